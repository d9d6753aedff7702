#!/usr/bin/env python3
"""Independent ROS 2 conformance client of the sepmem node (no sepmem code).

It behaves as an rmw_zenoh (ROS 2 Jazzy) participant would, with only
`eclipse-zenoh` and `rosbags`:

* Graph: it reads every liveliness token under `@ros2_lv/<domain>/**` with a
  parser that follows rmw_zenoh's grammar (`liveliness_utils.cpp`): at least
  9 parts and none empty, entity kinds NN/MP/MS/SS/SC, `%` mangling, 13 parts
  for topic entities, and the QoS string with defaults left empty
  (`qos.cpp`: RELIABLE, VOLATILE, KEEP_LAST 42, infinite durations).
* Data: it subscribes on the *exact* keys an rmw_zenoh subscription would use,
  `<domain>/<topic>/<pkg>::msg::dds_::<Name>_/<RIHS01>`, with the hashes that
  rosbags computes from the message definitions (sepmem's .msg files and the
  MoveIt definitions under msg/third_party are registered on the Jazzy
  typestore), and decodes every sample with rosbags.
* Every sample must carry rmw_zenoh's attachment: i64 sequence number
  (1, 2, 3 … per publisher), i64 source timestamp in ns, LEB128 length 0x10
  and the 16-byte GID.

Scenario (the Rust test `tests/python_client.rs` drives it):
1. connect, and check that the node (NN) and its subscriptions (MS) of the
   exact input topics are in the graph before any data flows;
2. print `READY` (the test then starts `sepmem play` on --played-topic);
3. publish a scripted stream on --scripted-topic: the same ellipsoid cloud,
   shifted rigidly by 1 cm per frame, in lock step with the node's meshes;
4. check the graph: node list, every endpoint's topic, type, hash and QoS
   (mesh, markers and collision objects TRANSIENT_LOCAL);
5. after the last frame, open a *new* session and subscribe as a
   TRANSIENT_LOCAL rmw_zenoh subscription does (AdvancedSubscriber detecting
   late publishers): it must get the last mesh of every stream (the one with
   the stamp of the last mesh seen live) within 1 s;
6. wait for the streams' eviction: the collision objects of the scripted
   stream must read ADD, MOVE …, then REMOVE, in that order;
7. every output carries the input's frame_id and stamp.

Prints one JSON line with the figures and `failures`; exits 0 when there are
none. Requirements: tests/python/requirements.txt.
"""

import argparse
import json
import os
import pathlib
import queue
import struct
import sys
import threading
import time

import numpy as np
import zenoh
import zenoh.ext
from rosbags.typesys import Stores, get_typestore, get_types_from_msg

ROOT = pathlib.Path(__file__).resolve().parents[2]
KINDS = {"NN", "MP", "MS", "SS", "SC"}
# rmw_zenoh's QoS defaults (qos.cpp): left empty in the token.
DEFAULT_DEPTH = 42
ADD, REMOVE, MOVE = 0, 1, 3
SENSOR_QOS = "2::,5:,:,:,,"


def typestore():
    ts = get_typestore(Stores.ROS2_JAZZY)
    types = {}
    for name in ("SurfaceMesh", "FrameDiagnostics"):
        types.update(get_types_from_msg((ROOT / "msg/msg" / f"{name}.msg").read_text(), f"sepmem_msgs/msg/{name}"))
    for full in ("moveit_msgs/msg/CollisionObject", "object_recognition_msgs/msg/ObjectType"):
        pkg, _, ty = full.split("/")
        types.update(get_types_from_msg((ROOT / "msg/third_party" / pkg / "msg" / f"{ty}.msg").read_text(), full))
    ts.register(types)
    return ts


def dds(type_name):
    pkg, _, name = type_name.split("/")
    return f"{pkg}::msg::dds_::{name}_"


def data_key(domain, topic, type_name, ts):
    return f"{domain}/{topic.strip('/')}/{dds(type_name)}/{ts.hash_rihs01(type_name)}"


def parse_qos(s):
    """rmw_zenoh keyexpr_to_qos: 6+ ':' parts with 2/2/2/3 comma sub-parts."""
    parts = s.split(":")
    if len(parts) < 6:
        raise ValueError(f"QoS {s!r}: {len(parts)} parts")
    sub = [p.split(",") for p in parts[2:6]]
    if [len(x) for x in sub] != [2, 2, 2, 3]:
        raise ValueError(f"QoS {s!r}: sub-parts {[len(x) for x in sub]}")
    rel = {"": "reliable", "1": "reliable", "2": "best_effort"}[parts[0]]
    dur = {"": "volatile", "2": "volatile", "1": "transient_local"}[parts[1]]
    hist = {"": "keep_last", "1": "keep_last", "2": "keep_all"}[sub[0][0]]
    depth = int(sub[0][1]) if sub[0][1] else DEFAULT_DEPTH
    for x in sub[1:]:
        for v in x:
            if v and not v.isdigit():
                raise ValueError(f"QoS {s!r}: {v!r}")
    return {"reliability": rel, "durability": dur, "history": hist, "depth": depth}


def parse_token(key):
    """rmw_zenoh's Entity::make: None for a key that is not a valid token."""
    parts = key.split("/")
    if len(parts) < 9 or parts[0] != "@ros2_lv" or any(p == "" for p in parts):
        raise ValueError(f"token {key!r}: {len(parts)} parts or an empty one")
    kind = parts[5]
    if kind not in KINDS:
        raise ValueError(f"token {key!r}: kind {kind}")
    tok = {
        "domain": int(parts[1]), "zid": parts[2], "nid": int(parts[3]), "id": int(parts[4]), "kind": kind,
        "enclave": parts[6].replace("%", "/"), "namespace": parts[7].replace("%", "/"), "node": parts[8],
    }
    if kind != "NN":
        if len(parts) < 13:
            raise ValueError(f"token {key!r}: topic entity with {len(parts)} parts")
        tok.update(topic=parts[9].replace("%", "/"), type=parts[10], hash=parts[11], qos=parse_qos(parts[12]))
    return tok


def attachment(seq, gid):
    return struct.pack("<qq", seq, time.time_ns()) + bytes([16]) + gid


class Attachments:
    """Checks rmw_zenoh's attachment of every sample, per publisher GID.

    Sequence numbers start at 1 and increase by one per publish. The node's
    outputs are RELIABLE + KEEP_LAST, which rmw_zenoh (and sepmem) map to
    zenoh's "drop" congestion control: a burst the link cannot take at once
    (a cold frame's mesh, markers and collision object together) may lose a
    sample, seen here as a gap. Gaps are counted in `lost` (a missing first
    sample counts as a gap from 0); a repeated or decreasing number, or one
    below 1, is a failure."""

    def __init__(self):
        self.last = {}
        self.first = {}
        self.bad = []
        self.count = 0
        self.lost = {}

    def check(self, key, b, fresh):
        self.count += 1
        if len(b) != 33 or b[16] != 0x10:
            self.bad.append(f"{key}: attachment {b.hex()}")
            return
        seq, ts_ns = struct.unpack("<qq", b[:16])
        gid = b[17:]
        if abs(ts_ns - time.time_ns()) > 60e9:
            self.bad.append(f"{key}: source timestamp {ts_ns} far from now")
        prev = self.last.get(gid)
        if prev is None:
            self.first[gid] = (key, seq)
            if seq < 1:
                self.bad.append(f"{key}: first sequence number {seq}, expected >= 1")
            elif fresh and seq > 1:
                self.lost[key] = self.lost.get(key, 0) + seq - 1
        elif seq <= prev:
            self.bad.append(f"{key}: sequence {seq} after {prev}")
        elif seq > prev + 1:
            self.lost[key] = self.lost.get(key, 0) + seq - prev - 1
        self.last[gid] = seq


def ellipsoid(ts, k, stamp_ns, frame_id, shift):
    rng = np.random.default_rng(7)  # the same points every frame: a rigid motion
    d = rng.normal(size=(2500, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    pts = (d * np.array([0.10, 0.07, 0.05]) + np.array([shift, 0.0, 1.0])).astype("<f4")
    T = ts.types
    fields = [T["sensor_msgs/msg/PointField"](name=c, offset=4 * i, datatype=7, count=1) for i, c in enumerate("xyz")]
    stamp = T["builtin_interfaces/msg/Time"](sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9)
    msg = T["sensor_msgs/msg/PointCloud2"](
        header=T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame_id), height=1, width=len(pts),
        fields=fields, is_bigendian=False, point_step=12, row_step=12 * len(pts),
        data=np.frombuffer(pts.tobytes(), dtype=np.uint8), is_dense=True)
    return bytes(ts.serialize_cdr(msg, "sensor_msgs/msg/PointCloud2"))


def open_session(endpoint):
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("timestamping/enabled", "true")
    return zenoh.open(conf)


def stamp_of(header):
    return (header.stamp.sec * 10**9 + header.stamp.nanosec, header.frame_id)


class Outputs:
    """The node's outputs of one input topic, on their exact keys."""

    TYPES = {
        "mesh": "sepmem_msgs/msg/SurfaceMesh",
        "mesh_markers": "visualization_msgs/msg/MarkerArray",
        "membrane_diagnostics": "sepmem_msgs/msg/FrameDiagnostics",
    }

    def __init__(self, args, ts, topic):
        self.topic = topic
        self.keys = {s: data_key(args.domain, f"{topic}/{s}", t, ts) for s, t in self.TYPES.items()}
        self.types = {f"{topic}/{s}": t for s, t in self.TYPES.items()}


def expected_endpoints(args, streams):
    """(kind, topic) -> (type, durability, depth) that the sepmem node must advertise."""
    want = {("MP", "/diagnostics"): ("diagnostic_msgs/msg/DiagnosticArray", "volatile", 10),
            ("MP", "/collision_object"): ("moveit_msgs/msg/CollisionObject", "transient_local", 10)}
    for o in streams:
        want[("MS", o.topic)] = ("sensor_msgs/msg/PointCloud2", "volatile", 5)
        for s, t in Outputs.TYPES.items():
            dur = "volatile" if s == "membrane_diagnostics" else "transient_local"
            # A MarkerArray holds every object of its frame: the node keeps
            # only the last one for late joiners (KEEP_LAST 1).
            want[("MP", f"{o.topic}/{s}")] = (t, dur, 1 if s == "mesh_markers" else 10)
    return want


def parse_all(tokens, failures):
    parsed = []
    for key in sorted(tokens):
        try:
            parsed.append(parse_token(key))
        except ValueError as e:
            failures.append(str(e))
    return parsed


def check_graph(tokens, player_tokens, args, ts, streams, failures):
    """The node's endpoints (all streams alive) and the player's (while it plays)."""
    parsed = parse_all(tokens, failures)
    nodes = sorted({t["node"] for t in parsed if t["kind"] == "NN"})
    if args.node_name not in nodes:
        failures.append(f"node {args.node_name} not in the node list {nodes}")
    players = parse_all(player_tokens, failures)
    if not any(t["kind"] == "NN" and t["node"] == args.player_name for t in players):
        failures.append(f"node {args.player_name} not in the node list while it played")
    ours = [t for t in parsed if t["node"] == args.node_name and t["kind"] != "NN"]
    seen = {}
    for t in ours:
        seen.setdefault((t["kind"], t["topic"]), []).append(t)
    for (kind, topic), (ty, dur, depth) in expected_endpoints(args, streams).items():
        found = seen.get((kind, topic))
        if not found:
            failures.append(f"no {kind} endpoint for {topic}")
            continue
        for t in found:
            if t["type"] != dds(ty) or t["hash"] != ts.hash_rihs01(ty):
                failures.append(f"{kind} {topic}: type {t['type']} {t['hash']}, rosbags says {dds(ty)} {ts.hash_rihs01(ty)}")
            q = t["qos"]
            if q["durability"] != dur or q["depth"] != depth or q["history"] != "keep_last":
                failures.append(f"{kind} {topic}: QoS {q}, expected {dur} keep_last {depth}")
            want_rel = "best_effort" if kind == "MS" else "reliable"
            if q["reliability"] != want_rel:
                failures.append(f"{kind} {topic}: reliability {q['reliability']}")
    player = [t for t in players if t["node"] == args.player_name and t["kind"] == "MP"]
    pc2 = ts.hash_rihs01("sensor_msgs/msg/PointCloud2")
    if not any(t["topic"] == args.played_topic and t["hash"] == pc2 for t in player):
        failures.append(f"player has no MP token for {args.played_topic} with hash {pc2}")
    return {"nodes": sorted(set(nodes) | {t["node"] for t in players if t["kind"] == "NN"}),
            "endpoints": len(ours), "tokens": len(parsed)}


def late_join(args, ts, streams, last):
    """A new session subscribing like an rmw_zenoh TRANSIENT_LOCAL subscription.

    `last` maps each stream to the (stamp, frame_id) of the last mesh the live
    subscription received; returns, per stream, the seconds from the join
    (opening the session) until that very mesh arrived (streams that never
    got it are left out). Samples are only timed in the callback and decoded
    outside it, so that decoding does not delay the later arrivals."""
    t0 = time.monotonic()
    s2 = open_session(args.connect)
    arrived = []  # (topic, seconds since t0, payload), appended by the callbacks
    got = {}
    subs = []
    for o in streams:
        def cb(sample, topic=o.topic):
            arrived.append((topic, time.monotonic() - t0, bytes(sample.payload.to_bytes())))
        subs.append(zenoh.ext.declare_advanced_subscriber(
            s2, o.keys["mesh"], cb,
            history=zenoh.ext.HistoryConfig(detect_late_publishers=True), subscriber_detection=True))
    done = 0
    while time.monotonic() - t0 < 3.0 and len(got) < len(streams):
        while done < len(arrived):
            topic, t, payload = arrived[done]
            done += 1
            m = ts.deserialize_cdr(payload, Outputs.TYPES["mesh"])
            if stamp_of(m.header) == last.get(topic):
                got.setdefault(topic, t)
        time.sleep(0.01)
    for s in subs:
        s.undeclare()
    s2.close()
    return got


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--connect", required=True, help="zenoh endpoint of the node, e.g. tcp/127.0.0.1:7450")
    ap.add_argument("--domain", type=int, default=int(os.environ.get("ROS_DOMAIN_ID", "0")))
    ap.add_argument("--node-name", default="sepmem")
    ap.add_argument("--player-name", default="sepmem_player")
    ap.add_argument("--played-topic", default="/synth/ellipsoid/points")
    ap.add_argument("--played-frames", type=int, default=12)
    ap.add_argument("--scripted-topic", default="/conformance/points")
    ap.add_argument("--frames", type=int, default=4, help="frames of the scripted stream")
    ap.add_argument("--max-triangles", type=int, default=500)
    ap.add_argument("--timeout", type=float, default=120.0)
    args = ap.parse_args()

    ts = typestore()
    session = open_session(args.connect)
    zid = str(session.info.zid())
    lock = threading.Lock()
    tokens = set()
    ever = set()  # every token seen alive, also after it left (the player exits)
    failures = []
    att = Attachments()
    t_start = time.monotonic()

    def on_token(sample):
        with lock:
            if sample.kind == zenoh.SampleKind.PUT:
                tokens.add(str(sample.key_expr))
                ever.add(str(sample.key_expr))
            else:
                tokens.discard(str(sample.key_expr))

    lv_sub = session.liveliness().declare_subscriber(f"@ros2_lv/{args.domain}/**", on_token, history=True)

    def has_token(pred):
        with lock:
            keys = list(tokens)
        for k in keys:
            try:
                t = parse_token(k)
            except ValueError:
                continue
            if pred(t):
                return True
        return False

    # 1. The node and its exact subscriptions are visible before any data.
    exact = [args.scripted_topic, args.played_topic]
    while time.monotonic() - t_start < 30 and not all(
            has_token(lambda t, x=x: t["node"] == args.node_name and t["kind"] == "MS" and t["topic"] == x)
            for x in exact):
        time.sleep(0.05)
    early = {x: has_token(lambda t, x=x: t["node"] == args.node_name and t["kind"] == "MS" and t["topic"] == x
                          and t.get("qos", {}).get("reliability") == "best_effort") for x in exact}
    for x, ok in early.items():
        if not ok:
            failures.append(f"no MS token (best effort) for {x} before any data")

    streams = [Outputs(args, ts, args.scripted_topic), Outputs(args, ts, args.played_topic)]
    inputs = {args.scripted_topic: set(), args.played_topic: set()}
    received = {}  # output topic -> list of decoded messages
    collision = []

    # The callbacks only copy each sample into a queue; a worker decodes and
    # checks them in arrival order. Decoding large meshes with rosbags inside
    # zenoh's callback held up its receive path, and the node's outputs
    # (zenoh "drop" congestion control) then lost samples to the back pressure.
    pending = queue.Queue()

    def subscriber(key, type_name, topic, sink):
        def cb(sample):
            raw = sample.attachment
            pending.put((type_name, topic, sink, bytes(sample.payload.to_bytes()),
                         bytes(raw.to_bytes()) if raw is not None else b""))
        return session.declare_subscriber(key, cb)

    def work():
        while (item := pending.get()) is not None:
            type_name, topic, sink, payload, raw = item
            try:
                msg = ts.deserialize_cdr(payload, type_name)
                with lock:
                    att.check(topic, raw, fresh=topic != "/diagnostics")
                    sink(msg)
            except Exception as e:  # noqa: BLE001 - any decode failure is a finding
                with lock:
                    failures.append(f"{topic}: {e}")

    worker = threading.Thread(target=work, daemon=True)
    worker.start()

    subs = []
    for o in streams:
        for suffix, key in o.keys.items():
            topic = f"{o.topic}/{suffix}"
            subs.append(subscriber(key, Outputs.TYPES[suffix], topic,
                                   lambda m, topic=topic: received.setdefault(topic, []).append(m)))
    subs.append(subscriber(data_key(args.domain, "/collision_object", "moveit_msgs/msg/CollisionObject", ts),
                           "moveit_msgs/msg/CollisionObject", "/collision_object", collision.append))
    subs.append(subscriber(data_key(args.domain, "/diagnostics", "diagnostic_msgs/msg/DiagnosticArray", ts),
                           "diagnostic_msgs/msg/DiagnosticArray", "/diagnostics",
                           lambda m: received.setdefault("/diagnostics", []).append(m)))
    # The player's clouds, on the key an rmw_zenoh subscription uses (checks `sepmem play`).
    subs.append(subscriber(data_key(args.domain, args.played_topic, "sensor_msgs/msg/PointCloud2", ts),
                           "sensor_msgs/msg/PointCloud2", args.played_topic,
                           lambda m: inputs[args.played_topic].add(stamp_of(m.header))))

    # Our own publisher, as an rmw_zenoh node: NN + MP tokens, attachments.
    name = "conformance_client"
    mangled = "%" + args.scripted_topic.strip("/").replace("/", "%")
    pc2 = "sensor_msgs/msg/PointCloud2"
    own = [session.liveliness().declare_token(f"@ros2_lv/{args.domain}/{zid}/0/0/NN/%/%/{name}"),
           session.liveliness().declare_token(
               f"@ros2_lv/{args.domain}/{zid}/0/1/MP/%/%/{name}/{mangled}/{dds(pc2)}/{ts.hash_rihs01(pc2)}/{SENSOR_QOS}")]
    pub = session.declare_publisher(data_key(args.domain, args.scripted_topic, pc2, ts))
    print("READY", flush=True)

    # 3. The scripted stream, in lock step with the node's meshes.
    mesh_topic = f"{args.scripted_topic}/mesh"
    gid = bytes(range(16))
    for k in range(args.frames):
        stamp = time.time_ns()
        inputs[args.scripted_topic].add((stamp, "conformance_cam"))
        with lock:
            before = len(received.get(mesh_topic, []))
        pub.put(ellipsoid(ts, k, stamp, "conformance_cam", 0.01 * k), attachment=attachment(k + 1, gid))
        t0 = time.monotonic()
        while time.monotonic() - t0 < 60:
            with lock:
                if len(received.get(mesh_topic, [])) > before:
                    break
            time.sleep(0.02)
        else:
            failures.append(f"no mesh for scripted frame {k}")
    # Wait for the played stream's meshes (the test plays the bag meanwhile).
    played_mesh = f"{args.played_topic}/mesh"
    while time.monotonic() - t_start < args.timeout:
        with lock:
            n_in = len(inputs[args.played_topic])
            n_out = len(received.get(played_mesh, []))
            last = max((stamp_of(m.header) for m in received.get(played_mesh, [])), default=None)
        if n_in >= args.played_frames and n_out > 0 and last == max(inputs[args.played_topic]):
            break
        time.sleep(0.05)
    else:
        failures.append(f"played stream: {n_in} clouds seen, {n_out} meshes")

    # 4. The graph while every stream is alive.
    with lock:
        snapshot = set(tokens)
        played_tokens = set(ever)
    graph = check_graph(snapshot, played_tokens, args, ts, streams, failures)

    # 5. A late joiner gets the last mesh of every stream within 1 s.
    with lock:
        last_mesh = {o.topic: max((stamp_of(m.header) for m in received.get(f"{o.topic}/mesh", [])), default=None)
                     for o in streams}
    late = late_join(args, ts, streams, last_mesh)
    for o in streams:
        if late.get(o.topic) is None or late[o.topic] > 1.0:
            failures.append(f"late joiner: last mesh of {o.topic} after {late.get(o.topic)} s")

    # 6. Eviction: REMOVE of the scripted stream's collision object.
    sid = None
    while time.monotonic() - t_start < args.timeout:
        with lock:
            ops = [(c.id, c.operation) for c in collision]
        if any(op == REMOVE and i.endswith(args.scripted_topic) for i, op in ops):
            break
        time.sleep(0.1)
    for s in subs:
        s.undeclare()
    subs = []
    pending.put(None)
    worker.join(timeout=30)
    with lock:
        objs = list(collision)
        outs = {k: list(v) for k, v in received.items()}
    sequence = [c.operation for c in objs if c.id.endswith(args.scripted_topic)]
    if objs:
        sid = next((c.id for c in objs if c.id.endswith(args.scripted_topic)), None)
    first_move = sequence.index(MOVE) if MOVE in sequence else -1
    if not (sequence and sequence[0] == ADD and first_move > 0 and sequence[-1] == REMOVE
            and REMOVE not in sequence[:-1]):
        failures.append(f"collision object {sid}: operations {sequence}, expected ADD, MOVE …, REMOVE")
    for c in objs:
        if c.operation == ADD and (len(c.meshes) != 1 or not 0 < len(c.meshes[0].triangles) <= args.max_triangles):
            failures.append(f"ADD {c.id}: {[len(m.triangles) for m in c.meshes]} triangles")
        if c.operation in (MOVE, REMOVE) and (c.meshes or c.primitives or c.planes):
            failures.append(f"{c.id}: operation {c.operation} with geometry")

    # 7. Frames and stamps: every output carries its input's header.
    headers = 0
    for o in streams:
        sent = inputs[o.topic]
        for suffix in Outputs.TYPES:
            for m in outs.get(f"{o.topic}/{suffix}", []):
                hs = [x.header for x in m.markers] if suffix == "mesh_markers" else [m.header]
                for h in hs:
                    headers += 1
                    if stamp_of(h) not in sent:
                        failures.append(f"{o.topic}/{suffix}: header {stamp_of(h)} is no input's")
    for c in objs:
        headers += 1
        stream = next((t for t in inputs if c.id.endswith(t)), None)
        sent = inputs.get(stream, set())
        if c.operation == REMOVE:
            # The REMOVE of an evicted stream carries its last input's header.
            if not sent or stamp_of(c.header) != max(sent):
                failures.append(f"REMOVE {c.id}: header {stamp_of(c.header)}, last input {max(sent, default=None)}")
        elif stamp_of(c.header) not in sent:
            failures.append(f"collision object {c.id}: header {stamp_of(c.header)} is no input's of its stream")
    with lock:
        failures.extend(att.bad)
        samples = att.count
        lost = dict(att.lost)

    print(json.dumps({
        "graph": graph, "early_subscriptions": early, "samples_checked": samples, "samples_lost": lost,
        "headers_checked": headers,
        "outputs": {k: len(v) for k, v in outs.items()}, "collision_operations": sequence,
        "collision_objects": len(objs), "late_join_s": late, "failures": failures}))
    for s in subs:
        s.undeclare()
    for t in own:
        t.undeclare()
    pub.undeclare()
    lv_sub.undeclare()
    session.close()
    return 0 if not failures else 1


if __name__ == "__main__":
    sys.exit(main())
