#!/usr/bin/env python3
"""Write rosbag2 bags of real mOSD tabletop objects with an independent tool (rosbags).

Source: ../shared/datasets/mosd_tabletop_segmentation/extracted_objects/*.pcd
(binary PCD, fields x y z rgba, one file per segmented object; PCL data,
BSD licence, see tests/data/README.md). Run from the repository root:

    python3 tests/python/make_mosd_bag.py [DATASETS_DIR]

Writes (committed):
  tests/data/bags/mosd_rosbags/        MCAP bag directory (metadata.yaml + .mcap)
  tests/data/bags/mosd_rosbags_db3/    sqlite3 bag directory (metadata.yaml + .db3)

Layout. One topic per mOSD scene, /mosd/<scene>/points (test31 holds two
objects), each cloud a sensor_msgs/PointCloud2 with fields
x y z (FLOAT32), rgba (UINT32, 0xAARRGGBB as in the PCD) and label
(UINT32, the mOSD segment label), point_step 20, little-endian, unorganised.
Frame k (k = 0..FRAMES-1) of a scene holds, for every object of the scene,
the source points with index i % STRIDE == k, translated by
(k * STEP_M, 0, 0) metres (a slow slide along x), stamped
T0 + k * 100 ms. The db3 bag holds frames 0 and 1 of scene test31 with
stride DB3_STRIDE. tests/bag_mosd.rs re-reads the PCDs and checks every
count and coordinate.
"""

import pathlib
import re
import shutil
import sys

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

ROOT = pathlib.Path(__file__).resolve().parents[2]
FRAMES = 3
STRIDE = 4
DB3_STRIDE = 8
STEP_M = 0.005
T0 = 1_700_000_000_000_000_000

ts = get_typestore(Stores.ROS2_JAZZY)
PC2 = ts.types['sensor_msgs/msg/PointCloud2']
PF = ts.types['sensor_msgs/msg/PointField']
Header = ts.types['std_msgs/msg/Header']
Time = ts.types['builtin_interfaces/msg/Time']


def read_pcd(path):
    raw = path.read_bytes()
    end = raw.index(b'DATA binary\n') + len(b'DATA binary\n')
    head = raw[:end].decode()
    fields = re.search(r'^FIELDS (.*)$', head, re.M).group(1).split()
    assert fields == ['x', 'y', 'z', 'rgba'], fields
    n = int(re.search(r'^POINTS (\d+)$', head, re.M).group(1))
    rec = np.frombuffer(raw[end:end + 16 * n], dtype=[('x', '<f4'), ('y', '<f4'), ('z', '<f4'),
                                                      ('rgba', '<u4')])
    assert len(rec) == n
    return rec


def scenes(datasets):
    objs = {}
    for p in sorted((datasets / 'mosd_tabletop_segmentation' / 'extracted_objects').glob('*.pcd')):
        m = re.match(r'(test\d+)_label(\d+)_', p.name)
        objs.setdefault(m.group(1), []).append((int(m.group(2)), read_pcd(p)))
    return objs


def cloud(objects, frame, stride, stamp_ns):
    dt = np.dtype([('x', '<f4'), ('y', '<f4'), ('z', '<f4'), ('rgba', '<u4'), ('label', '<u4')])
    parts = []
    for label, rec in objects:
        sel = rec[frame::stride]
        out = np.zeros(len(sel), dtype=dt)
        out['x'] = sel['x'] + np.float32(frame * STEP_M)
        out['y'] = sel['y']
        out['z'] = sel['z']
        out['rgba'] = sel['rgba']
        out['label'] = label
        parts.append(out)
    pts = np.concatenate(parts)
    fields = [PF(name='x', offset=0, datatype=7, count=1), PF(name='y', offset=4, datatype=7, count=1),
              PF(name='z', offset=8, datatype=7, count=1), PF(name='rgba', offset=12, datatype=6, count=1),
              PF(name='label', offset=16, datatype=6, count=1)]
    return PC2(header=Header(stamp=Time(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9),
                             frame_id='camera_rgb_optical_frame'),
               height=1, width=len(pts), fields=fields, is_bigendian=False, point_step=20,
               row_step=20 * len(pts), data=np.frombuffer(pts.tobytes(), dtype=np.uint8),
               is_dense=True)


def write(bag_dir, plugin, objs, frames, stride):
    if bag_dir.exists():
        shutil.rmtree(bag_dir)
    with Writer(bag_dir, version=9, storage_plugin=plugin) as w:
        conns = {s: w.add_connection(f'/mosd/{s}/points', PC2.__msgtype__, typestore=ts) for s in objs}
        for k in range(frames):
            stamp = T0 + k * 100_000_000
            for s, objects in objs.items():
                msg = cloud(objects, k, stride, stamp)
                w.write(conns[s], stamp, ts.serialize_cdr(msg, PC2.__msgtype__))
    size = sum(p.stat().st_size for p in bag_dir.iterdir())
    print(f'{bag_dir.relative_to(ROOT)}: {len(objs)} topics x {frames} frames, {size} bytes')


def main():
    datasets = pathlib.Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT / '..' / 'shared' / 'datasets'
    objs = scenes(datasets)
    out = ROOT / 'tests' / 'data' / 'bags'
    out.mkdir(parents=True, exist_ok=True)
    write(out / 'mosd_rosbags', StoragePlugin.MCAP, objs, FRAMES, STRIDE)
    write(out / 'mosd_rosbags_db3', StoragePlugin.SQLITE3, {'test31': objs['test31']}, 2, DB3_STRIDE)


if __name__ == '__main__':
    main()
