#!/usr/bin/env python3
"""Decode the `sepmem_msgs/msg/GroundTruth` messages of a bag with Python rosbags.

Usage: ground_truth.py BAG

The types come from the bag's own message definitions (rosbags AnyReader), so
this is an independent reading of what `sepmem synth` wrote. Prints one JSON
object per GroundTruth message, in log order: stamp (ns), stream_id, mesh_id,
pose and camera_pose as [x, y, z, qx, qy, qz, qw], world_frame_id, the
intrinsics [width, height, fx, fy, cx, cy], visible_points and the vertex and
triangle counts of the mesh it carries.
"""

import json
import pathlib
import sys

from rosbags.highlevel import AnyReader

TYPE = 'sepmem_msgs/msg/GroundTruth'


def pose(p):
    return [p.position.x, p.position.y, p.position.z,
            p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w]


def main():
    bag = pathlib.Path(sys.argv[1])
    with AnyReader([bag]) as reader:
        conns = [c for c in reader.connections if c.msgtype == TYPE]
        if not conns:
            raise SystemExit(f'{bag}: no {TYPE} topic')
        for conn, _t, raw in reader.messages(connections=conns):
            m = reader.deserialize(raw, conn.msgtype)
            print(json.dumps({
                'stamp': m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec,
                'frame_id': m.header.frame_id,
                'stream_id': m.stream_id,
                'mesh_id': m.mesh_id,
                'pose': pose(m.pose),
                'world_frame_id': m.world_frame_id,
                'camera_pose': pose(m.camera_pose),
                'intrinsics': [m.width, m.height, m.fx, m.fy, m.cx, m.cy],
                'visible_points': m.visible_points,
                'vertices': len(m.vertices),
                'triangles': len(m.triangles),
            }))
    return 0


if __name__ == '__main__':
    sys.exit(main())
