"""Add a detached group of points to a bag's PointCloud2 messages.

Models a segmentation mask that bled onto the background: in every frame, a
10 cm square patch of N points facing the camera, D metres behind the
object's centroid along the camera ray, is appended to the object's cloud on
the same topic (its other fields copied from the cloud's first point). The
first F frames are kept; every other message is copied unchanged. Written
with the Python `rosbags` package (an MCAP rosbag2 bag), independently of
sepmem.

Made tests/data/bags/robot_view/turn_capsule_detached.mcap:

    python3 tests/python/add_detached.py \
        tests/data/bags/robot_view/turn_capsule.mcap /tmp/out 0.6 300 10
    cp /tmp/out/out.mcap tests/data/bags/robot_view/turn_capsule_detached.mcap
"""

import sys
from pathlib import Path

import numpy as np
from rosbags.rosbag2 import Reader, Writer
from rosbags.rosbag2.enums import StoragePlugin
from rosbags.typesys import Stores, get_typestore, get_types_from_msg

CLOUD = "sensor_msgs/msg/PointCloud2"


def with_patch(msg, distance, count, rng):
    """`msg` (a deserialized PointCloud2, float32 x, y, z) with the patch."""
    step = msg.point_step
    data = np.frombuffer(bytes(msg.data), dtype=np.uint8).reshape(-1, step)
    offset = {f.name: f.offset for f in msg.fields}
    xyz = np.stack(
        [data[:, offset[k]:offset[k] + 4].copy().view("<f4")[:, 0] for k in "xyz"], 1
    )
    centroid = xyz[np.isfinite(xyz).all(1)].mean(0)
    ray = centroid / np.linalg.norm(centroid)
    across = np.cross(ray, [0.0, 1.0, 0.0])
    across /= np.linalg.norm(across)
    up = np.cross(ray, across)
    uv = rng.uniform(-0.05, 0.05, (count, 2))
    patch = centroid + ray * distance + uv[:, :1] * across + uv[:, 1:] * up
    extra = np.repeat(data[:1], count, 0).copy()
    for i, k in enumerate("xyz"):
        column = patch[:, i].astype("<f4").view(np.uint8).reshape(count, 4)
        extra[:, offset[k]:offset[k] + 4] = column
    joined = np.concatenate([data, extra])
    msg.height, msg.width = 1, joined.shape[0]
    msg.row_step = step * msg.width
    msg.data = joined.reshape(-1)
    return msg


def main(src, out, distance, count, frames):
    store = get_typestore(Stores.ROS2_HUMBLE)
    rng = np.random.default_rng(3)
    seen = {}
    with Reader(src) as reader, Writer(
        Path(out), version=9, storage_plugin=StoragePlugin.MCAP
    ) as writer:
        conns = {}
        for c in reader.connections:
            if c.msgtype not in store.fielddefs:
                store.register(get_types_from_msg(c.msgdef.data, c.msgtype))
            conns[c.id] = writer.add_connection(
                c.topic,
                c.msgtype,
                typestore=store,
                serialization_format=c.ext.serialization_format,
                offered_qos_profiles=c.ext.offered_qos_profiles,
            )
        for c, stamp, raw in reader.messages():
            if c.msgtype == CLOUD:
                seen[c.topic] = seen.get(c.topic, 0) + 1
                if seen[c.topic] > frames:
                    continue
                msg = with_patch(store.deserialize_cdr(raw, CLOUD), distance, count, rng)
                raw = store.serialize_cdr(msg, CLOUD)
            writer.write(conns[c.id], stamp, raw)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], float(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5]))
