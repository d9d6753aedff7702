#!/usr/bin/env python3
"""The Poisson oracle of the robot's view (issue 20), beside sepmem's own run.

Usage: poisson_oracle.py BAG [--sepmem PATH] [--depth 8] [--crop 0.02]
                             [--samples 10000] [--tau 0.01] [--frames N]

BAG is a sequence written by `sepmem synth` (its clouds and its
`/synth/ground_truth`). For every frame k of every stream, the oracle:

1. takes every view j <= k since the stream's mesh last changed (a swap
   starts the fusion over), estimates each view's normals in its own camera
   frame (30 nearest neighbours) and orients them towards that camera;
2. moves the view into frame k with the **true** poses
   (p_k = pose_k * pose_j^-1 * p_j; the poses are the object's in the cloud
   frame), so tracking is perfect;
3. runs Open3D's screened Poisson reconstruction (octree depth --depth) on
   the fused points and drops the vertices whose density is in the lowest
   --crop quantile (Poisson has no closure of its own: it closes the unseen
   side by its smoothness, the crop trims what no point supports);
4. scores the mesh with sepmem's protocol (`metrics::evaluate`): both
   surfaces normalised by the posed true mesh's bounding box (longest edge
   1), --samples area-uniform samples on each, F-score at --tau.

It prints one line per frame and, per stream, the mean F over the first and
the last third of the frames. With --sepmem, it also runs `sepmem replay BAG
-q` on the same bag and prints sepmem's first- and last-third F beside the
oracle's (the issue asks for both in the same run).

The types come from the bag's own message definitions (rosbags AnyReader):
this is an independent reading of what `sepmem synth` wrote. Needs rosbags,
numpy and open3d (tests/python/requirements-oracle.txt).
"""

import argparse
import collections
import pathlib
import re
import subprocess
import sys

import numpy as np
import open3d as o3d
from rosbags.highlevel import AnyReader

TRUTH = 'sepmem_msgs/msg/GroundTruth'
CLOUD = 'sensor_msgs/msg/PointCloud2'


def isometry(p):
    """4x4 matrix of a geometry_msgs/Pose."""
    q = np.array([p.orientation.w, p.orientation.x, p.orientation.y, p.orientation.z])
    q = q / np.linalg.norm(q)
    w, x, y, z = q
    r = np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])
    m = np.eye(4)
    m[:3, :3] = r
    m[:3, 3] = [p.position.x, p.position.y, p.position.z]
    return m


def xyz(cloud):
    """The finite x, y, z of a PointCloud2 as an (n, 3) float64 array."""
    fields = {f.name: f for f in cloud.fields}
    dtype = {7: '<f4', 8: '<f8'}
    cols = []
    n = cloud.width * cloud.height
    raw = np.frombuffer(bytes(cloud.data), dtype=np.uint8).reshape(n, cloud.point_step)
    for name in 'xyz':
        f = fields[name]
        size = 4 if f.datatype == 7 else 8
        col = raw[:, f.offset:f.offset + size].copy().view(dtype[f.datatype]).reshape(n)
        cols.append(col.astype(np.float64))
    pts = np.stack(cols, axis=1)
    return pts[np.isfinite(pts).all(axis=1)]


def stamp(header):
    return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec


Frame = collections.namedtuple('Frame', 'stamp points pose mesh_id')


def read(bag):
    """Per stream: its frames (points, true pose, mesh id) and its meshes."""
    truths, meshes, clouds = {}, {}, collections.defaultdict(list)
    with AnyReader([bag]) as reader:
        for conn, _t, raw in reader.messages():
            if conn.msgtype == TRUTH:
                m = reader.deserialize(raw, conn.msgtype)
                truths[(m.stream_id, stamp(m.header))] = (isometry(m.pose), m.mesh_id)
                if len(m.vertices):
                    v = np.array([[p.x, p.y, p.z] for p in m.vertices])
                    t = np.array([list(tr.vertex_indices) for tr in m.triangles])
                    meshes[(m.stream_id, m.mesh_id)] = (v, t)
            elif conn.msgtype == CLOUD:
                m = reader.deserialize(raw, conn.msgtype)
                clouds[conn.topic].append((stamp(m.header), xyz(m)))
    streams = {}
    for topic, frames in clouds.items():
        seq = []
        for s, pts in frames:
            if (topic, s) in truths:
                pose, mesh_id = truths[(topic, s)]
                seq.append(Frame(s, pts, pose, mesh_id))
        if seq:
            streams[topic] = seq
    return streams, meshes


def transform(m, pts):
    return pts @ m[:3, :3].T + m[:3, 3]


def view_cloud(pts):
    """One view with its normals, oriented to its camera (the origin)."""
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    pc.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(30))
    pc.orient_normals_towards_camera_location(np.zeros(3))
    return pc


def fused(frames, k, views):
    """The views of frames[..=k] since the mesh last changed, moved into frame k."""
    start = k
    while start > 0 and frames[start - 1].mesh_id == frames[k].mesh_id:
        start -= 1
    pts, nrm = [], []
    for j in range(start, k + 1):
        m = frames[k].pose @ np.linalg.inv(frames[j].pose)
        pc = views[j]
        pts.append(transform(m, np.asarray(pc.points)))
        nrm.append(np.asarray(pc.normals) @ m[:3, :3].T)
    out = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.concatenate(pts)))
    out.normals = o3d.utility.Vector3dVector(np.concatenate(nrm))
    return out


def poisson(cloud, depth, crop):
    mesh, dens = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(cloud, depth=depth)
    dens = np.asarray(dens)
    mesh.remove_vertices_by_mask(dens < np.quantile(dens, crop))
    return mesh


def f_score(pred, truth, samples, tau):
    """sepmem's metrics::evaluate: normalised by the truth's box, F at tau."""
    tv = np.asarray(truth.vertices)
    lo, hi = tv.min(axis=0), tv.max(axis=0)
    centre, scale = (lo + hi) / 2, (hi - lo).max()
    if len(pred.triangles) == 0:
        return 0.0

    def sample(mesh):
        s = mesh.sample_points_uniformly(number_of_points=samples)
        return o3d.geometry.PointCloud(
            o3d.utility.Vector3dVector((np.asarray(s.points) - centre) / scale))

    p, g = sample(pred), sample(truth)
    precision = float((np.asarray(p.compute_point_cloud_distance(g)) <= tau).mean())
    recall = float((np.asarray(g.compute_point_cloud_distance(p)) <= tau).mean())
    return 0.0 if precision + recall == 0 else 2 * precision * recall / (precision + recall)


def posed_truth(meshes, topic, frame):
    v, t = meshes[(topic, frame.mesh_id)]
    return o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(transform(frame.pose, v)),
                                     o3d.utility.Vector3iVector(t))


def thirds(scores):
    n = len(scores) // 3
    if n == 0:
        return float('nan'), float('nan')
    return float(np.mean(scores[:n])), float(np.mean(scores[-n:]))


def sepmem_thirds(sepmem, bag):
    """sepmem's own first- and last-third F per stream, from `replay -q`."""
    out = subprocess.run([sepmem, 'replay', str(bag), '-q'], check=True,
                         capture_output=True, text=True).stdout
    pat = re.compile(r'^view (\S+): .*?first third \(\d+\): F ([\d.]+).*?'
                     r'last third \(\d+\): F ([\d.]+)', re.M)
    return {m.group(1): (float(m.group(2)), float(m.group(3))) for m in pat.finditer(out)}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('bag', type=pathlib.Path)
    ap.add_argument('--sepmem', help='sepmem binary: also run `sepmem replay BAG -q`')
    ap.add_argument('--depth', type=int, default=8)
    ap.add_argument('--crop', type=float, default=0.02)
    ap.add_argument('--samples', type=int, default=10000)
    ap.add_argument('--tau', type=float, default=0.01)
    ap.add_argument('--frames', type=int, default=0, help='score only the first N frames (0: all)')
    args = ap.parse_args()

    streams, meshes = read(args.bag)
    if not streams:
        raise SystemExit(f'{args.bag}: no PointCloud2 frames with ground truth')
    ours = sepmem_thirds(args.sepmem, args.bag) if args.sepmem else {}
    for topic, frames in streams.items():
        if args.frames:
            frames = frames[:args.frames]
        views = [view_cloud(f.points) for f in frames]
        scores = []
        for k, frame in enumerate(frames):
            mesh = poisson(fused(frames, k, views), args.depth, args.crop)
            scores.append(f_score(mesh, posed_truth(meshes, topic, frame), args.samples, args.tau))
            print(f'{topic} frame {k} points {len(frame.points)} oracle F {scores[-1]:.3f}', flush=True)
        first, last = thirds(scores)
        line = f'oracle {topic}: {len(scores)} frames; first third F {first:.3f}; last third F {last:.3f}'
        if topic in ours:
            line += f'; sepmem first third F {ours[topic][0]:.3f}; last third F {ours[topic][1]:.3f}'
        print(line, flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
