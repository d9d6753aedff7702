#!/usr/bin/env python3
"""Developer tool: plane slices of replayed meshes against the input points
and the ground truth of a `sepmem synth` bag (not run by the tests).

For each chosen frame it draws two slices through the centroid of the
stream's points, y = const and x = const, with depth (z, the camera axis
of a synth bag) vertical:
  * black: the input points within ±4 mm of the slice plane;
  * green: the ground-truth mesh (from /synth/ground_truth, posed per frame);
  * one colour per output bag: the TRIANGLE_LIST markers that
    `sepmem replay -o OUT.mcap` wrote for the stream.
Folds, loops and a collapsed or ballooned unseen back show at a glance.
The plots led to the session-3 fix of the occluded back beyond the
occupancy grid (src/membrane/view.rs, `outside_at`).

Example:
    sepmem synth -o s.mcap --shapes bottle --frames 20 --points 20000
    sepmem replay s.mcap -o warm.mcap
    sepmem replay s.mcap -o cold.mcap --set pipeline.warm_start=false
    python3 tests/python/slice_plot.py s.mcap --topic /synth/bottle/points \\
        --frames 0,10,19 --png slices.png warm.mcap cold.mcap

Needs numpy, rosbags and matplotlib (`pip install matplotlib`).
"""

import argparse
from pathlib import Path

import numpy as np
from rosbags.highlevel import AnyReader


def read(bag, topic):
    """Deserialised messages of `topic` in `bag`, in log order."""
    with AnyReader([Path(bag)]) as r:
        cons = [c for c in r.connections if c.topic == topic]
        return [r.deserialize(raw, c.msgtype) for c, _, raw in r.messages(connections=cons)]


def cloud_xyz(msg):
    """Finite xyz of a FLOAT32 PointCloud2."""
    a = np.frombuffer(bytes(msg.data), dtype=np.uint8).reshape(-1, msg.point_step)
    offs = {f.name: f.offset for f in msg.fields}
    xyz = np.stack([a[:, offs[k]:offs[k] + 4].copy().view('<f4')[:, 0] for k in 'xyz'], 1)
    return xyz[np.isfinite(xyz).all(1)].astype(float)


def rotation(q):
    """Rotation matrix of a geometry_msgs/Quaternion."""
    x, y, z, w = q.x, q.y, q.z, q.w
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def slice_segments(tris, axis, value):
    """Segments where the triangles (n×3×3) cross the plane coordinate[axis] = value."""
    segs = []
    d = tris[:, :, axis] - value
    for tri, dd in zip(tris, d):
        s = []
        for a, b in ((0, 1), (1, 2), (2, 0)):
            if (dd[a] > 0) != (dd[b] > 0):
                t = dd[a] / (dd[a] - dd[b])
                s.append(tri[a] + t * (tri[b] - tri[a]))
        if len(s) == 2:
            segs.append(s)
    return segs


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('bag', help='the synth input bag (points + /synth/ground_truth)')
    ap.add_argument('outputs', nargs='*', help='output bags of `sepmem replay -o`')
    ap.add_argument('--topic', default='/synth/ellipsoid/points', help='input PointCloud2 topic')
    ap.add_argument('--frames', default='0', help='comma-separated frame indices')
    ap.add_argument('--png', default='slices.png', help='output image')
    args = ap.parse_args()

    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    frames = [int(f) for f in args.frames.split(',')]
    clouds = read(args.bag, args.topic)
    truths = read(args.bag, '/synth/ground_truth')
    truths = [g for g in truths if g.stream_id in ('', args.topic)] or truths
    mesh_src = next(g for g in truths if len(g.vertices))
    gt_v = np.array([[p.x, p.y, p.z] for p in mesh_src.vertices])
    gt_f = np.array([list(t.vertex_indices) for t in mesh_src.triangles])
    outputs = [read(o, args.topic + '/mesh_markers') for o in args.outputs]
    colours = ['r', 'b', 'm', 'c', 'y']

    fig, axs = plt.subplots(len(frames), 2, figsize=(12, 5 * len(frames)), squeeze=False)
    for row, f in enumerate(frames):
        pts = cloud_xyz(clouds[f])
        c = pts.mean(0)
        g = truths[f]
        t = np.array([g.pose.position.x, g.pose.position.y, g.pose.position.z])
        gt_tris = (gt_v @ rotation(g.pose.orientation).T + t)[gt_f]
        layers = [('truth', 'g', gt_tris)]
        for k, (name, out) in enumerate(zip(args.outputs, outputs)):
            marker = out[f].markers[-1]
            v = np.array([[p.x, p.y, p.z] for p in marker.points]).reshape(-1, 3, 3)
            layers.append((Path(name).name, colours[k % len(colours)], v))
        for col, (axis, name) in enumerate(((1, 'y'), (0, 'x'))):
            ax = axs[row, col]
            other = 0 if axis == 1 else 1
            near = np.abs(pts[:, axis] - c[axis]) < 0.004
            ax.plot(pts[near, other], pts[near, 2], 'k.', ms=1)
            for label, colour, tris in layers:
                for i, s in enumerate(slice_segments(tris, axis, c[axis])):
                    ax.plot([s[0][other], s[1][other]], [s[0][2], s[1][2]], colour, lw=1,
                            label=label if i == 0 else None)
            ax.set_aspect('equal')
            ax.set_title(f'frame {f}: slice {name} = {c[axis]:.3f} (vertical: depth z)')
            ax.legend(loc='upper right', fontsize=7)
    plt.savefig(args.png, dpi=60)
    print(f'wrote {args.png}')


if __name__ == '__main__':
    main()
