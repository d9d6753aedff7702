#!/usr/bin/env python3
"""Independent check of a rosbag2 bag with Python `rosbags` and `mcap`.

Usage: check_bag.py BAG [--expect TOPIC=COUNT ...] [--type TOPIC=TYPE ...]

BAG is a bag directory (metadata.yaml + storage files) or a single .mcap file.
Every message is decoded twice, by rosbags (AnyReader, types taken from the
bag's own message definitions) and, for MCAP storage, by mcap +
mcap-ros2-support (from the ros2msg schema). Prints one line per topic
(`topic type count`) and exits non-zero on any failure or mismatch.
"""

import argparse
import pathlib
import sys

from rosbags.highlevel import AnyReader


def mcap_files(bag: pathlib.Path):
    if bag.is_file():
        return [bag] if bag.suffix == '.mcap' else []
    return sorted(bag.glob('*.mcap'))


def check_with_mcap(files, counts, types):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    seen = {}
    for path in files:
        with open(path, 'rb') as f:
            reader = make_reader(f, decoder_factories=[DecoderFactory()])
            header = reader.get_header()
            if header.profile != 'ros2':
                raise SystemExit(f'{path}: MCAP profile {header.profile!r}, expected ros2')
            for schema, channel, message, decoded in reader.iter_decoded_messages():
                if schema.encoding != 'ros2msg' or channel.message_encoding != 'cdr':
                    raise SystemExit(f'{channel.topic}: schema {schema.encoding}, '
                                     f'message encoding {channel.message_encoding}')
                if 'offered_qos_profiles' not in channel.metadata:
                    raise SystemExit(f'{channel.topic}: no offered_qos_profiles in channel metadata')
                if types.get(channel.topic, schema.name) != schema.name:
                    raise SystemExit(f'{channel.topic}: mcap schema {schema.name}, '
                                     f'rosbags type {types[channel.topic]}')
                if decoded is None:
                    raise SystemExit(f'{channel.topic}: mcap could not decode a message')
                seen[channel.topic] = seen.get(channel.topic, 0) + 1
    if seen != counts:
        raise SystemExit(f'mcap counts {seen} differ from rosbags counts {counts}')


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('bag', type=pathlib.Path)
    ap.add_argument('--expect', action='append', default=[], metavar='TOPIC=COUNT')
    ap.add_argument('--type', action='append', default=[], metavar='TOPIC=TYPE')
    args = ap.parse_args()

    counts, types = {}, {}
    with AnyReader([args.bag]) as reader:
        for conn in reader.connections:
            types[conn.topic] = conn.msgtype
        for conn, _timestamp, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            if msg is None:
                raise SystemExit(f'{conn.topic}: rosbags could not decode a message')
            counts[conn.topic] = counts.get(conn.topic, 0) + 1

    files = mcap_files(args.bag)
    if files:
        check_with_mcap(files, counts, types)
        readers = 'rosbags+mcap'
    else:
        readers = 'rosbags'

    for topic in sorted(types):
        print(f'{topic} {types[topic]} {counts.get(topic, 0)}')
    ok = True
    for item in args.expect:
        topic, n = item.rsplit('=', 1)
        if counts.get(topic, 0) != int(n):
            print(f'MISMATCH {topic}: {counts.get(topic, 0)} messages, expected {n}')
            ok = False
    for item in args.type:
        topic, t = item.rsplit('=', 1)
        if types.get(topic) != t:
            print(f'MISMATCH {topic}: type {types.get(topic)}, expected {t}')
            ok = False
    total = sum(counts.values())
    print(f'OK {readers}: {len(types)} topics, {total} messages decoded' if ok else 'FAILED')
    return 0 if ok else 1


if __name__ == '__main__':
    sys.exit(main())
