#!/usr/bin/env python3
"""Regenerate the derived PLY fixtures from cube.ply (PCL test/cube.ply).

cube_be.ply: the same cube as binary big-endian, double x y z, plus per
vertex uchar red green blue = (10*i, 255-10*i, 7) and float quality = i/2,
and the faces as list uchar int. Written with Python's struct module,
independently of sepmem's reader and writer.
"""
import struct, pathlib

here = pathlib.Path(__file__).parent
data = (here / "cube.ply").read_bytes()
head_end = data.index(b"end_header\n") + len(b"end_header\n")
body = data[head_end:]
nv, nf = 24, 12
verts = [struct.unpack_from("<3f", body, 12 * i) for i in range(nv)]
off = 12 * nv
faces = []
for _ in range(nf):
    n = body[off]
    faces.append(struct.unpack_from("<%di" % n, body, off + 1))
    off += 1 + 4 * n
out = bytearray(
    b"ply\nformat binary_big_endian 1.0\ncomment big-endian copy of PCL test/cube.ply\n"
    b"element vertex 24\nproperty double x\nproperty double y\nproperty double z\n"
    b"property uchar red\nproperty uchar green\nproperty uchar blue\nproperty float quality\n"
    b"element face 12\nproperty list uchar int vertex_indices\nend_header\n"
)
for i, v in enumerate(verts):
    out += struct.pack(">3d", *v)
    out += bytes([10 * i, 255 - 10 * i, 7])
    out += struct.pack(">f", i / 2)
for f in faces:
    out += bytes([len(f)]) + struct.pack(">%di" % len(f), *f)
(here / "cube_be.ply").write_bytes(out)
print("vertices", verts[:3], "faces", faces[:2])
