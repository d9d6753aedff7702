#!/usr/bin/env python3
"""The Poisson oracle of the robot's view (issue 20), beside sepmem's own run.

Usage: poisson_oracle.py BAG [--sepmem PATH] [--depth 8] [--crop 0.02]
                             [--samples 10000] [--tau 0.01] [--frames N]
                             [--seen]

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
the last third of the frames. With --seen it also measures the seen side
as `sepmem replay` does (`synth::view_metrics`): over the camera's pixel
rays that hit the posed true mesh, the share whose first hit on the mesh
lies within tau (times the truth's longest edge) of the true depth, and the
same on the silhouette's rim alone (a true hit with one of its 8
neighbours missing). It does so for the fused oracle and for Poisson on the
frame's own view alone (the issue's "as exact as a Poisson reconstruction
of that frame"), and prints their medians over the frames. With --sepmem, it also runs `sepmem replay BAG
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


Frame = collections.namedtuple('Frame', 'stamp points pose mesh_id camera')

# The pinhole camera of a frame: (fx, fy, cx, cy, width, height).
Camera = collections.namedtuple('Camera', 'fx fy cx cy width height')


def read(bag):
    """Per stream: its frames (points, true pose, mesh id) and its meshes."""
    truths, meshes, clouds = {}, {}, collections.defaultdict(list)
    with AnyReader([bag]) as reader:
        for conn, _t, raw in reader.messages():
            if conn.msgtype == TRUTH:
                m = reader.deserialize(raw, conn.msgtype)
                camera = Camera(m.fx, m.fy, m.cx, m.cy, m.width, m.height)
                truths[(m.stream_id, stamp(m.header))] = (isometry(m.pose), m.mesh_id, camera)
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
                pose, mesh_id, camera = truths[(topic, s)]
                seq.append(Frame(s, pts, pose, mesh_id, camera))
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


# The camera's depth range (synth::Camera's default), as `replay` casts.
MIN_DEPTH, MAX_DEPTH = 0.3, 8.0


def first_hits(mesh, cam, rect):
    """Depth of the first hit of each pixel ray of `rect` on `mesh` (NaN for
    none within the depth range); the rays are (x, y, 1), so t is depth."""
    i0, i1, j0, j1 = rect
    ii, jj = np.meshgrid(np.arange(i0, i1 + 1), np.arange(j0, j1 + 1))
    d = np.stack([(ii + 0.5 - cam.cx) / cam.fx, (jj + 0.5 - cam.cy) / cam.fy,
                  np.ones_like(ii, dtype=float)], axis=-1)
    rays = np.concatenate([np.zeros_like(d), d], axis=-1).astype(np.float32)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(mesh))
    t = scene.cast_rays(o3d.core.Tensor(rays))['t_hit'].numpy()
    return np.where((t >= MIN_DEPTH) & (t <= MAX_DEPTH), t, np.nan)


def seen_side(truth, mesh, cam, tau):
    """(seen side, seen side on the rim) of `mesh` against `truth` (module
    docs); NaN where the camera does not see the object."""
    v = np.asarray(truth.vertices)
    front = v[v[:, 2] > 0]
    if len(front) == 0 or len(mesh.triangles) == 0:
        return float('nan'), float('nan')
    u = cam.fx * front[:, 0] / front[:, 2] + cam.cx
    w = cam.fy * front[:, 1] / front[:, 2] + cam.cy
    rect = (max(int(u.min()) - 2, 0), min(int(u.max()) + 2, cam.width - 1),
            max(int(w.min()) - 2, 0), min(int(w.max()) + 2, cam.height - 1))
    true_t = first_hits(truth, cam, rect)
    mesh_t = first_hits(mesh, cam, rect)
    hit = ~np.isnan(true_t)
    if not hit.any():
        return float('nan'), float('nan')
    tau_m = tau * (v.max(axis=0) - v.min(axis=0)).max()
    within = hit & (np.abs(np.nan_to_num(mesh_t, nan=np.inf) - true_t) <= tau_m)
    padded = np.pad(hit, 1, constant_values=False)
    rows, cols = hit.shape
    all_neighbours = np.ones_like(hit)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            all_neighbours &= padded[1 + dy:1 + dy + rows, 1 + dx:1 + dx + cols]
    rim = hit & ~all_neighbours
    share = within[hit].mean()
    return float(share), float(within[rim].mean()) if rim.any() else float('nan')


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
    ap.add_argument('--seen', action='store_true',
                    help="also the seen side (and on the rim) of the oracle and of Poisson on "
                         "each frame's own view")
    args = ap.parse_args()

    streams, meshes = read(args.bag)
    if not streams:
        raise SystemExit(f'{args.bag}: no PointCloud2 frames with ground truth')
    ours = sepmem_thirds(args.sepmem, args.bag) if args.sepmem else {}
    for topic, frames in streams.items():
        if args.frames:
            frames = frames[:args.frames]
        views = [view_cloud(f.points) for f in frames]
        scores, seen = [], []
        for k, frame in enumerate(frames):
            mesh = poisson(fused(frames, k, views), args.depth, args.crop)
            truth = posed_truth(meshes, topic, frame)
            scores.append(f_score(mesh, truth, args.samples, args.tau))
            line = f'{topic} frame {k} points {len(frame.points)} oracle F {scores[-1]:.3f}'
            if args.seen:
                single = poisson(views[k], args.depth, args.crop)
                seen.append(seen_side(truth, mesh, frame.camera, args.tau)
                            + seen_side(truth, single, frame.camera, args.tau))
                line += ' seen side {:.3f} rim {:.3f}; one view: seen side {:.3f} rim {:.3f}'.format(
                    *seen[-1])
            print(line, flush=True)
        first, last = thirds(scores)
        line = f'oracle {topic}: {len(scores)} frames; first third F {first:.3f}; last third F {last:.3f}'
        if seen:
            med = np.nanmedian(np.array(seen), axis=0)
            line += ('; seen side median {:.3f} (rim {:.3f}); Poisson of each frame alone: '
                     'seen side median {:.3f} (rim {:.3f})').format(*med)
        if topic in ours:
            line += f'; sepmem first third F {ours[topic][0]:.3f}; last third F {ours[topic][1]:.3f}'
        print(line, flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
