#!/usr/bin/env python3
"""Independent client of the sepmem node, written without any sepmem code.

It talks to a running `sepmem node` the way an rmw_zenoh (ROS 2 Jazzy) node
would, using only `eclipse-zenoh` and `rosbags`:

* publishes `sensor_msgs/msg/PointCloud2` (serialized by rosbags) on the
  rmw_zenoh key `<domain>/<topic>/sensor_msgs::msg::dds_::PointCloud2_/RIHS01_…`
  with the 33-byte attachment (int64 sequence, int64 source timestamp,
  LEB128 length 16, 16-byte GID) and declares the node (NN) and publisher (MP)
  liveliness tokens;
* subscribes to the node's `visualization_msgs/msg/MarkerArray` and
  `diagnostic_msgs/msg/DiagnosticArray` outputs (type hash wildcarded) and
  decodes them with rosbags;
* checks what it received: TRIANGLE_LIST markers after a DELETEALL, a
  `/diagnostics` status for its stream with η_g, frames and latency values,
  and a valid attachment on every output sample.

Usage (against `sepmem node --set 'node.transport.zenoh.listen=["tcp/127.0.0.1:7450"]'
--set 'node.topics=["/pyclient/**"]'`):

    python3 tests/python/zenoh_client.py --connect tcp/127.0.0.1:7450

Prints one JSON line with the figures and exits 0 when every check passed
(1 otherwise). Requirements: tests/python/requirements.txt.
"""

import argparse
import json
import os
import struct
import sys
import threading
import time

import numpy as np
import zenoh
from rosbags.typesys import Stores, get_typestore

PC2_HASH = "RIHS01_9198cabf7da3796ae6fe19c4cb3bdd3525492988c70522628af5daa124bae2b5"
PC2_DDS = "sensor_msgs::msg::dds_::PointCloud2_"
MARKERS_DDS = "visualization_msgs::msg::dds_::MarkerArray_"
DIAG_DDS = "diagnostic_msgs::msg::dds_::DiagnosticArray_"
SENSOR_QOS = "2::,5:,:,:,,"  # best effort, volatile, keep last 5 (rmw_zenoh encoding)
TRIANGLE_LIST, DELETEALL = 11, 3


def attachment(seq: int, gid: bytes) -> bytes:
    """rmw_zenoh AttachmentData: i64 seq, i64 source ns, LEB128(16), 16 bytes."""
    return struct.pack("<qq", seq, time.time_ns()) + bytes([16]) + gid


def parse_attachment(b: bytes):
    if b is None or len(b) != 33 or b[16] != 16:
        return None
    seq, ts = struct.unpack("<qq", b[:16])
    return seq, ts


def ellipsoid_cloud(ts, n: int, k: int, stamp_ns: int):
    rng = np.random.default_rng(k)
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    pts = (d * np.array([0.12, 0.08, 0.06]) + np.array([0.01 * k, 0.0, 1.0])).astype("<f4")
    PointCloud2 = ts.types["sensor_msgs/msg/PointCloud2"]
    PointField = ts.types["sensor_msgs/msg/PointField"]
    Header = ts.types["std_msgs/msg/Header"]
    Time = ts.types["builtin_interfaces/msg/Time"]
    fields = [PointField(name=c, offset=4 * i, datatype=7, count=1) for i, c in enumerate("xyz")]
    msg = PointCloud2(
        header=Header(stamp=Time(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9), frame_id="camera"),
        height=1,
        width=n,
        fields=fields,
        is_bigendian=False,
        point_step=12,
        row_step=12 * n,
        data=np.frombuffer(pts.tobytes(), dtype=np.uint8),
        is_dense=True,
    )
    return ts.serialize_cdr(msg, "sensor_msgs/msg/PointCloud2")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--connect", required=True, help="zenoh endpoint of the node, e.g. tcp/127.0.0.1:7450")
    ap.add_argument("--domain", type=int, default=int(os.environ.get("ROS_DOMAIN_ID", "0")))
    ap.add_argument("--topic", default="/pyclient/points")
    ap.add_argument("--frames", type=int, default=3, help="marker arrays with triangles to wait for")
    ap.add_argument("--points", type=int, default=3000)
    ap.add_argument("--rate", type=float, default=5.0)
    ap.add_argument("--timeout", type=float, default=60.0)
    args = ap.parse_args()

    ts = get_typestore(Stores.ROS2_JAZZY)
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("connect/endpoints", json.dumps([args.connect]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    session = zenoh.open(conf)
    zid = str(session.info.zid())
    topic = args.topic.strip("/")
    mangled = "%" + topic.replace("/", "%")
    node = "pyclient"
    tokens = [
        session.liveliness().declare_token(f"@ros2_lv/{args.domain}/{zid}/0/0/NN/%/%/{node}"),
        session.liveliness().declare_token(
            f"@ros2_lv/{args.domain}/{zid}/0/1/MP/%/%/{node}/{mangled}/"
            f"sensor_msgs::msg::dds_::PointCloud2_/{PC2_HASH}/{SENSOR_QOS}"
        ),
    ]
    gid = bytes(range(16))

    lock = threading.Lock()
    got = {"markers": [], "diagnostics": [], "bad_attachments": 0, "errors": []}

    def on_markers(sample):
        try:
            att = parse_attachment(bytes(sample.attachment.to_bytes()) if sample.attachment else None)
            msg = ts.deserialize_cdr(bytes(sample.payload.to_bytes()), "visualization_msgs/msg/MarkerArray")
            with lock:
                if att is None:
                    got["bad_attachments"] += 1
                got["markers"].append(msg)
        except Exception as e:  # noqa: BLE001 - report any decode failure
            with lock:
                got["errors"].append(f"markers: {e}")

    def on_diag(sample):
        try:
            att = parse_attachment(bytes(sample.attachment.to_bytes()) if sample.attachment else None)
            msg = ts.deserialize_cdr(bytes(sample.payload.to_bytes()), "diagnostic_msgs/msg/DiagnosticArray")
            with lock:
                if att is None:
                    got["bad_attachments"] += 1
                got["diagnostics"].append(msg)
        except Exception as e:  # noqa: BLE001
            with lock:
                got["errors"].append(f"diagnostics: {e}")

    subs = [
        session.declare_subscriber(f"{args.domain}/{topic}/mesh_markers/{MARKERS_DDS}/*", on_markers),
        session.declare_subscriber(f"{args.domain}/diagnostics/{DIAG_DDS}/*", on_diag),
    ]
    pub = session.declare_publisher(f"{args.domain}/{topic}/{PC2_DDS}/{PC2_HASH}")
    t0 = time.time()
    seq = 0

    def done():
        with lock:
            tri = [m for m in got["markers"] if any(x.type == TRIANGLE_LIST for x in m.markers)]
            diag = [
                s
                for d in got["diagnostics"]
                for s in d.status
                if args.topic in s.name and any(kv.key == "eta_g" for kv in s.values)
            ]
        return len(tri) >= args.frames and diag

    while time.time() - t0 < args.timeout and not done():
        seq += 1
        payload = ellipsoid_cloud(ts, args.points, seq, time.time_ns())
        pub.put(bytes(payload), attachment=attachment(seq, gid))
        time.sleep(1.0 / args.rate)
    # One more diagnostics period, so that the last frames are counted.
    time.sleep(1.2)

    with lock:
        markers = list(got["markers"])
        diags = list(got["diagnostics"])
        bad = got["bad_attachments"]
        errors = list(got["errors"])
    failures = list(errors)
    tri_arrays = [m for m in markers if any(x.type == TRIANGLE_LIST for x in m.markers)]
    if len(tri_arrays) < args.frames:
        failures.append(f"only {len(tri_arrays)} marker arrays with triangles")
    triangles = 0
    for m in tri_arrays:
        if m.markers[0].action != DELETEALL:
            failures.append("marker array does not start with DELETEALL")
        for x in m.markers[1:]:
            if x.type != TRIANGLE_LIST or len(x.points) == 0 or len(x.points) % 3:
                failures.append(f"bad marker type {x.type} with {len(x.points)} points")
            triangles += len(x.points) // 3
    status = None
    for d in diags:
        for s in d.status:
            if args.topic in s.name and any(kv.key == "eta_g" for kv in s.values):
                status = s
    values = {}
    if status is None:
        failures.append(f"no /diagnostics status for {args.topic}")
    else:
        values = {kv.key: kv.value for kv in status.values}
        for key in ("eta_g", "iterations", "frames", "drops", "p50_ms", "p95_ms", "warm", "cold"):
            if key not in values:
                failures.append(f"status lacks {key}")
        if status.level not in (0, 1):
            failures.append(f"status level {status.level} ({status.message})")
        if not 0.0 < float(values.get("eta_g", "0")) <= 1.0:
            failures.append(f"eta_g {values.get('eta_g')}")
    if bad:
        failures.append(f"{bad} output samples without a valid rmw_zenoh attachment")
    print(
        json.dumps(
            {
                "published": seq,
                "marker_arrays": len(markers),
                "marker_arrays_with_triangles": len(tri_arrays),
                "triangles": triangles,
                "diagnostic_arrays": len(diags),
                "status": {"name": status.name, "level": int(status.level), "values": values} if status else None,
                "failures": failures,
            }
        )
    )
    for s in subs:
        s.undeclare()
    for t in tokens:
        t.undeclare()
    pub.undeclare()
    session.close()
    return 0 if not failures else 1


if __name__ == "__main__":
    sys.exit(main())
