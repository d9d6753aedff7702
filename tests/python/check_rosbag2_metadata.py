#!/usr/bin/env python3
"""Read the `rosbag2` metadata record of an MCAP file as rosbag2 does, and
compare its structure, key for key, with a bag written by rosbag2 itself.

Usage: check_rosbag2_metadata.py BAG.mcap REFERENCE.mcap

rosbag2_storage_mcap's `read_metadata` loads the record's
`serialized_metadata` with yaml-cpp and decodes it as `BagMetadata`, starting
with `node["version"].as<int>()`: the root must be the bare map. This script
does the same with PyYAML (no sepmem code), checks the keys rosbag2 decodes,
then compares the nested key structure with the last record of REFERENCE
(a rosbag2-written fixture). `offered_qos_profiles` is a YAML string up to
version 8 and a YAML list from version 9; a string is parsed before the
comparison so that the profile keys are compared too. Prints one JSON line
and exits non-zero on any difference.
"""

import json
import sys

import yaml
from mcap.reader import make_reader

REQUIRED = ['version', 'storage_identifier', 'duration', 'starting_time', 'message_count',
            'topics_with_message_count', 'compression_format', 'compression_mode',
            'relative_file_paths', 'files', 'custom_data', 'ros_distro']


def record(path):
    with open(path, 'rb') as f:
        found = [m for m in make_reader(f).iter_metadata() if m.name == 'rosbag2']
    if not found:
        raise SystemExit(f'{path}: no rosbag2 metadata record')
    return yaml.safe_load(found[-1].metadata['serialized_metadata'])


def normalise(node):
    if isinstance(node, dict):
        out = {}
        for k, v in node.items():
            if k == 'offered_qos_profiles' and isinstance(v, str):
                v = yaml.safe_load(v)
            out[k] = normalise(v)
        return out
    if isinstance(node, list):
        return [normalise(v) for v in node]
    return node


def shape(node, path, out):
    """Every key path (lists: the union over their items) -> value kind."""
    if isinstance(node, dict):
        for k, v in node.items():
            out.setdefault(f'{path}/{k}', set()).add(type(v).__name__ if not isinstance(v, (dict, list)) else 'node')
            shape(v, f'{path}/{k}', out)
    elif isinstance(node, list):
        for v in node:
            shape(v, f'{path}[]', out)
    return out


def main():
    ours, ref = record(sys.argv[1]), record(sys.argv[2])
    failures = []
    if not isinstance(ours, dict):
        raise SystemExit(f'serialized_metadata is not a map: {type(ours).__name__}')
    try:
        version = int(ours['version'])  # node["version"].as<int>()
    except (KeyError, TypeError, ValueError) as e:
        failures.append(f'root has no integer version: {e!r}')
        version = None
    for key in REQUIRED:
        if key not in ours:
            failures.append(f'root lacks {key}')
    a = shape(normalise(ours), '', {})
    b = shape(normalise(ref), '', {})
    missing = sorted(set(b) - set(a))
    extra = sorted(set(a) - set(b))
    if missing:
        failures.append(f'keys of the rosbag2 fixture missing: {missing}')
    if extra:
        failures.append(f'keys the rosbag2 fixture does not have: {extra}')
    topics = {t['topic_metadata']['name']: t['message_count'] for t in ours.get('topics_with_message_count') or []}
    print(json.dumps({'version': version, 'root_keys': list(ours), 'key_paths': len(a),
                      'reference_key_paths': len(b), 'topics': topics, 'failures': failures}))
    return 1 if failures else 0


if __name__ == '__main__':
    sys.exit(main())
