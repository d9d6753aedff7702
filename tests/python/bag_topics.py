#!/usr/bin/env python3
"""List the topics of rosbag2 bags as two independent readers see them.

Usage: bag_topics.py BAG [BAG ...]

For each BAG (an .mcap file or a bag directory) it prints one JSON line
`{"bag": BAG, "rosbags": [[topic, type, count], ...], "mcap": [...]}`:
`rosbags` is Python rosbags' rosbag2 Reader (its connections and their
message counts, from the bag's metadata), `mcap` is the mcap package's
reader (channels, their schema names, and the messages counted one by one).
Both lists are sorted by topic. No sepmem code.
"""

import json
import pathlib
import sys

from mcap.reader import make_reader
from rosbags.rosbag2 import Reader


def with_rosbags(bag):
    with Reader(bag) as r:
        return sorted([c.topic, c.msgtype, c.msgcount] for c in r.connections)


def with_mcap(bag):
    files = [bag] if bag.is_file() else sorted(bag.glob('*.mcap'))
    topics = {}
    for path in files:
        with open(path, 'rb') as f:
            reader = make_reader(f)
            summary = reader.get_summary()
            for channel in summary.channels.values():
                schema = summary.schemas.get(channel.schema_id)
                topics.setdefault(channel.topic, [channel.topic, schema.name if schema else '', 0])
            for _, channel, _ in reader.iter_messages():
                topics[channel.topic][2] += 1
    return sorted(topics.values())


def main():
    for arg in sys.argv[1:]:
        bag = pathlib.Path(arg)
        print(json.dumps({'bag': arg, 'rosbags': with_rosbags(bag), 'mcap': with_mcap(bag)}))


if __name__ == '__main__':
    main()
