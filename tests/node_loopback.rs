//! The node's scheduling on real zenoh sessions over loopback, with a test
//! backend whose "compute" is a known sleep: keep-latest slots and drop
//! counting under overload, isolation of a malformed stream, sharding,
//! liveliness tokens and clean shutdown. (The end-to-end test with the real
//! membrane and wire codecs is in `node_e2e.rs`.)
#![allow(clippy::unwrap_used)]

use sepmem::config::Config;
use sepmem::node::clock::mono_ns;
use sepmem::node::runtime::{run, NodeSummary};
use sepmem::node::{
    Backend, Frame, FrameResult, Level, NodeConfig, ObjectReport, Output, OutputKind, OutputSink,
    Shard, StatusEntry, TopicProcessor,
};
use sepmem::transport::liveliness::{EntityKind, Qos, Token};
use sepmem::transport::{free_loopback_port, Participant, Received, RosType, TransportConfig};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// Test payload: CDR header, u64 frame index, u32 compute milliseconds.
fn payload(index: u64, busy_ms: u32) -> Vec<u8> {
    let mut v = vec![0, 1, 0, 0];
    v.extend_from_slice(&index.to_le_bytes());
    v.extend_from_slice(&busy_ms.to_le_bytes());
    v
}

struct TestProc {
    topic: String,
    seen: Arc<Mutex<Vec<(String, u64)>>>,
    receipts: Arc<Mutex<Vec<i64>>>,
    /// When set: after the mesh, the frame's later output (a diagnostics
    /// message with the same bytes) takes this long to make.
    tail: Option<Duration>,
}

impl TopicProcessor for TestProc {
    fn process(&mut self, frame: &Frame, sink: &mut OutputSink<'_>) -> FrameResult {
        if frame.payload.len() != 16 || frame.payload[..4] != [0, 1, 0, 0] {
            return FrameResult {
                error: Some(format!("malformed sample of {} bytes", frame.payload.len())),
                ..FrameResult::default()
            };
        }
        self.receipts.lock().unwrap().push(frame.received_ns);
        let index = u64::from_le_bytes(frame.payload[4..12].try_into().unwrap());
        let busy = u32::from_le_bytes(frame.payload[12..16].try_into().unwrap());
        std::thread::sleep(Duration::from_millis(u64::from(busy)));
        self.seen.lock().unwrap().push((self.topic.clone(), index));
        let mut out = vec![0, 1, 0, 0];
        out.extend_from_slice(&index.to_le_bytes());
        out.extend_from_slice(self.topic.as_bytes());
        sink(Output {
            kind: OutputKind::Mesh,
            payload: out.clone(),
        });
        if let Some(tail) = self.tail {
            std::thread::sleep(tail);
            sink(Output {
                kind: OutputKind::FrameDiagnostics,
                payload: out,
            });
        }
        FrameResult {
            objects: vec![ObjectReport {
                stream: self.topic.clone(),
                eta_g: 0.9,
                iterations: 3,
                warm: index > 0,
                level: Level::Ok,
                message: "ok".into(),
                quality: None,
                model_bytes: None,
            }],
            ..FrameResult::default()
        }
    }

    fn on_evict(&mut self) -> Vec<Output> {
        vec![Output {
            kind: OutputKind::Markers,
            payload: b"DELETEALL".to_vec(),
        }]
    }
}

#[derive(Default)]
struct TestBackend {
    seen: Arc<Mutex<Vec<(String, u64)>>>,
    receipts: Arc<Mutex<Vec<i64>>>,
    tail: Option<Duration>,
}

impl Backend for TestBackend {
    fn input_type(&self) -> RosType {
        RosType::new("sensor_msgs/msg/PointCloud2", "RIHS01_in")
    }
    fn output_type(&self, kind: OutputKind) -> RosType {
        match kind {
            OutputKind::Markers => RosType::new("visualization_msgs/msg/MarkerArray", "RIHS01_m"),
            OutputKind::Mesh => RosType::new("sepmem_msgs/msg/SurfaceMesh", "RIHS01_s"),
            OutputKind::FrameDiagnostics => {
                RosType::new("sepmem_msgs/msg/FrameDiagnostics", "RIHS01_f")
            }
            OutputKind::CollisionObjects => {
                RosType::new("moveit_msgs/msg/CollisionObject", "RIHS01_c")
            }
            OutputKind::Model => RosType::new("sensor_msgs/msg/PointCloud2", "RIHS01_in"),
        }
    }
    fn diagnostics_type(&self) -> RosType {
        RosType::new("diagnostic_msgs/msg/DiagnosticArray", "RIHS01_d")
    }
    // Like the pipeline backend without `pipeline.model`: the node must not
    // declare a publisher for it (the token count below).
    fn publishes(&self, kind: OutputKind) -> bool {
        kind != OutputKind::Model
    }
    fn processor(&self, topic: &str) -> Box<dyn TopicProcessor> {
        Box::new(TestProc {
            topic: topic.to_string(),
            seen: self.seen.clone(),
            receipts: self.receipts.clone(),
            tail: self.tail,
        })
    }
    fn encode_diagnostics(&self, _stamp: i64, _frame: &str, status: &[StatusEntry]) -> Vec<u8> {
        // Test encoding: one line per status, `name|level|k=v,k=v`.
        let mut s = String::new();
        for st in status {
            let kv: Vec<String> = st.values.iter().map(|(k, v)| format!("{k}={v}")).collect();
            s.push_str(&format!(
                "{}|{}|{}\n",
                st.name,
                st.level.byte(),
                kv.join(",")
            ));
        }
        s.into_bytes()
    }
}

fn pc2() -> RosType {
    RosType::new("sensor_msgs/msg/PointCloud2", "RIHS01_in")
}

/// A harness participant listening on an ephemeral port, and a node config
/// connecting to it.
async fn harness(name: &str) -> (Participant, NodeConfig) {
    let port = free_loopback_port().unwrap();
    let h = Participant::open(&TransportConfig::loopback(
        &format!("{name}_harness"),
        Some(port),
        &[],
    ))
    .await
    .unwrap();
    let mut cfg = Config::defaults().unwrap().node;
    cfg.topics = vec![format!("/{name}/**")];
    cfg.transport = TransportConfig::loopback(name, None, &[port]);
    cfg.diagnostics_period_ms = 200;
    cfg.compute_threads = 2;
    cfg.shutdown_timeout_ms = 5000;
    (h, cfg)
}

type Inbox = Arc<Mutex<Vec<Received>>>;

async fn collect(
    h: &Participant,
    pattern: &str,
    ty: &RosType,
) -> (zenoh::pubsub::Subscriber<()>, Inbox) {
    let inbox: Inbox = Arc::default();
    let i = inbox.clone();
    let sub = h
        .subscribe(pattern, ty, move |r| i.lock().unwrap().push(r))
        .await
        .unwrap();
    (sub, inbox)
}

async fn wait_for<F: Fn() -> bool>(f: F, what: &str) {
    for _ in 0..800 {
        if f() {
            return;
        }
        tokio::time::sleep(Duration::from_millis(25)).await;
    }
    panic!("timed out waiting for {what}");
}

/// Run a node on a tokio task until the returned sender fires.
fn spawn_node(
    cfg: NodeConfig,
    backend: Arc<TestBackend>,
) -> (
    tokio::sync::oneshot::Sender<()>,
    tokio::task::JoinHandle<NodeSummary>,
) {
    let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
    let node = tokio::spawn(async move {
        run(&cfg, backend, async {
            let _ = stop_rx.await;
        })
        .await
        .unwrap()
    });
    (stop_tx, node)
}

/// A node with the test backend, an observer of its markers under
/// `/{name}/**`, and a publisher on `/{name}/points`.
struct Rig {
    seen: Arc<Mutex<Vec<(String, u64)>>>,
    /// The receipt time of every frame a processor saw.
    receipts: Arc<Mutex<Vec<i64>>>,
    stop_tx: tokio::sync::oneshot::Sender<()>,
    node: tokio::task::JoinHandle<NodeSummary>,
    markers: Inbox,
    points: sepmem::transport::RosPublisher,
    _markers_sub: zenoh::pubsub::Subscriber<()>,
}

async fn rig(h: &Participant, name: &str, cfg: NodeConfig) -> Rig {
    rig_with(h, name, cfg, TestBackend::default()).await
}

/// [`rig`] with the given backend.
async fn rig_with(h: &Participant, name: &str, cfg: NodeConfig, backend: TestBackend) -> Rig {
    let backend = Arc::new(backend);
    let (seen, receipts) = (backend.seen.clone(), backend.receipts.clone());
    let (stop_tx, node) = spawn_node(cfg, backend);
    let (_markers_sub, markers) = collect(
        h,
        &format!("/{name}/**"),
        &any_type("visualization_msgs/msg/MarkerArray"),
    )
    .await;
    let points = h
        .publisher(&format!("/{name}/points"), &pc2(), Qos::SENSOR_DATA)
        .await
        .unwrap();
    Rig {
        seen,
        receipts,
        stop_tx,
        node,
        markers,
        points,
        _markers_sub,
    }
}

/// Publish `next()` every 25 ms until `done()` (the node's subscription is
/// matched and the frames came through); at most 20 s.
async fn probe(
    p: &sepmem::transport::RosPublisher,
    done: impl Fn() -> bool,
    mut next: impl FnMut() -> Vec<u8>,
) {
    for k in 0.. {
        if done() {
            return;
        }
        assert!(k < 800, "probe frames not processed");
        p.put(next()).await.unwrap();
        tokio::time::sleep(Duration::from_millis(25)).await;
    }
}

/// Stop a node started by [`spawn_node`]; its summary (within 30 s).
async fn stop(
    stop_tx: tokio::sync::oneshot::Sender<()>,
    node: tokio::task::JoinHandle<NodeSummary>,
) -> NodeSummary {
    stop_tx.send(()).unwrap();
    tokio::time::timeout(Duration::from_secs(30), node)
        .await
        .unwrap()
        .unwrap()
}

/// The summary of one stream of a stopped node.
fn stream_of(summary: &NodeSummary, topic: &str) -> sepmem::node::runtime::StreamSummary {
    summary
        .streams
        .iter()
        .find(|s| s.topic == topic)
        .unwrap()
        .clone()
}

fn any_type(name: &str) -> RosType {
    RosType::new(name, "x")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn overload_keeps_newest_counts_drops_and_isolates_a_malformed_stream() {
    let (h, cfg) = harness("ovl").await;
    let seen: Arc<Mutex<Vec<(String, u64)>>> = Arc::default();
    let backend = Arc::new(TestBackend {
        seen: seen.clone(),
        ..TestBackend::default()
    });
    let (stop_tx, node) = spawn_node(cfg, backend);
    let (_msub, meshes) = collect(&h, "/ovl/**", &any_type("sepmem_msgs/msg/SurfaceMesh")).await;
    let (_dsub, diags) = collect(
        &h,
        "/diagnostics",
        &any_type("diagnostic_msgs/msg/DiagnosticArray"),
    )
    .await;
    let fast = h
        .publisher("/ovl/fast", &pc2(), Qos::SENSOR_DATA)
        .await
        .unwrap();
    let slow = h
        .publisher("/ovl/slow", &pc2(), Qos::SENSOR_DATA)
        .await
        .unwrap();
    let bad = h
        .publisher("/ovl/bad", &pc2(), Qos::SENSOR_DATA)
        .await
        .unwrap();
    // Wait until the node is subscribed: a probe frame on `fast` comes back.
    for k in 0.. {
        if !meshes.lock().unwrap().is_empty() {
            break;
        }
        assert!(k < 800, "no first mesh");
        fast.put(payload(0, 0)).await.unwrap();
        tokio::time::sleep(Duration::from_millis(25)).await;
    }
    // `slow`: 40 frames back to back, each taking 50 ms to compute: most are
    // replaced in the slot before the worker is free.
    for i in 1..=40u64 {
        slow.put(payload(i, 50)).await.unwrap();
        bad.put(vec![0, 1, 0, 0, 9, 9]).await.unwrap();
        fast.put(payload(i, 0)).await.unwrap();
        tokio::time::sleep(Duration::from_millis(2)).await;
    }
    // The newest `slow` frame (40) is always processed eventually.
    wait_for(
        || {
            seen.lock()
                .unwrap()
                .iter()
                .any(|(t, i)| t == "/ovl/slow" && *i == 40)
        },
        "last slow frame",
    )
    .await;
    wait_for(
        || {
            seen.lock()
                .unwrap()
                .iter()
                .any(|(t, i)| t == "/ovl/fast" && *i == 40)
        },
        "last fast frame",
    )
    .await;
    // Diagnostics report the malformed stream as ERROR and the others not.
    wait_for(
        || {
            diags.lock().unwrap().iter().any(|r| {
                let s = String::from_utf8_lossy(&r.payload);
                s.contains("ovl: /ovl/bad|2|") && s.contains("ovl: /ovl/fast|")
            })
        },
        "diagnostics with the bad stream",
    )
    .await;
    let summary = stop(stop_tx, node).await;
    let get = |t: &str| stream_of(&summary, t);
    let slow_s = get("/ovl/slow");
    let slow_seen: Vec<u64> = seen
        .lock()
        .unwrap()
        .iter()
        .filter(|(t, _)| t == "/ovl/slow")
        .map(|(_, i)| *i)
        .collect();
    // Every frame was either processed or counted as dropped, and under 20x
    // overload most were dropped.
    assert!(slow_s.received <= 40 && slow_s.received >= 30, "{slow_s:?}");
    assert_eq!(slow_s.frames + slow_s.drops, slow_s.received, "{slow_s:?}");
    assert_eq!(slow_s.frames as usize, slow_seen.len());
    assert!(slow_s.drops >= 10, "{slow_s:?}");
    // Processed frames are in increasing order (newest wins, never an old one).
    assert!(slow_seen.windows(2).all(|w| w[0] < w[1]), "{slow_seen:?}");
    let bad_s = get("/ovl/bad");
    assert_eq!(bad_s.errors, bad_s.frames);
    assert!(bad_s.frames >= 1);
    let fast_s = get("/ovl/fast");
    assert_eq!(fast_s.errors, 0);
    assert!(summary.clean_shutdown);
    // Meshes arrived for the good streams only, each naming its topic.
    let meshes = meshes.lock().unwrap();
    assert!(meshes.iter().all(|r| !r.key.contains("/ovl/bad/")));
    assert!(meshes
        .iter()
        .any(|r| r.topic.as_deref() == Ok("/ovl/slow/mesh")));
    for r in meshes.iter() {
        let a = r.attachment.clone().unwrap().unwrap();
        assert!(a.sequence >= 1);
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn two_shards_split_streams_without_overlap_or_gap() {
    let (h, cfg) = harness("shd").await;
    let seen: Arc<Mutex<Vec<(String, u64)>>> = Arc::default();
    let mut nodes = Vec::new();
    let mut stops = Vec::new();
    for index in 0..2u32 {
        let mut c = cfg.clone();
        c.shard = Shard { index, count: 2 };
        c.transport.node_name = format!("shd{index}");
        let backend = Arc::new(TestBackend {
            seen: seen.clone(),
            ..TestBackend::default()
        });
        let (tx, node) = spawn_node(c, backend);
        stops.push(tx);
        nodes.push(node);
    }
    let (_msub, meshes) = collect(&h, "/shd/**", &any_type("sepmem_msgs/msg/SurfaceMesh")).await;
    let topics: Vec<String> = (0..8).map(|i| format!("/shd/obj{i}")).collect();
    let mut pubs = Vec::new();
    for t in &topics {
        pubs.push(h.publisher(t, &pc2(), Qos::SENSOR_DATA).await.unwrap());
    }
    // Publish until every topic has produced at least one mesh.
    let mut i = 0u64;
    loop {
        let done = topics.iter().all(|t| {
            meshes
                .lock()
                .unwrap()
                .iter()
                .any(|r| r.topic.as_deref() == Ok(format!("{t}/mesh").as_str()))
        });
        if done {
            break;
        }
        assert!(i < 400, "not every topic produced a mesh");
        for p in &pubs {
            p.put(payload(i, 0)).await.unwrap();
        }
        i += 1;
        tokio::time::sleep(Duration::from_millis(25)).await;
    }
    for s in stops {
        s.send(()).unwrap();
    }
    let mut owned: Vec<Vec<String>> = Vec::new();
    for n in nodes {
        let s = tokio::time::timeout(Duration::from_secs(30), n)
            .await
            .unwrap()
            .unwrap();
        assert!(s.clean_shutdown);
        assert!(s.other_shard > 0, "each shard saw the other's samples");
        owned.push(s.streams.iter().map(|s| s.topic.clone()).collect());
    }
    // No overlap, no gap, and the split follows the documented hash.
    for t in &topics {
        let owners: Vec<usize> = (0..2).filter(|k| owned[*k].contains(t)).collect();
        assert_eq!(owners.len(), 1, "{t} owned by {owners:?}");
        assert_eq!(owners[0] as u32, Shard::of(t, 2));
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tokens_are_declared_and_withdrawn_on_clean_shutdown() {
    let (h, cfg) = harness("tok").await;
    let r = rig(&h, "tok", cfg).await;
    let (seen, markers, p) = (&r.seen, &r.markers, &r.points);
    let mut i = 0;
    probe(
        p,
        || seen.lock().unwrap().len() >= 2,
        || {
            i += 1;
            payload(i - 1, 0)
        },
    )
    .await;
    let tokens = liveliness(&h).await;
    let mine: Vec<&Token> = tokens.iter().filter(|t| t.node == "tok").collect();
    let kinds = |k: EntityKind| mine.iter().filter(|t| t.kind == k).count();
    assert_eq!(kinds(EntityKind::Node), 1);
    assert_eq!(kinds(EntityKind::Subscription), 1);
    // /diagnostics + markers + mesh + frame diagnostics + /collision_object.
    assert_eq!(kinds(EntityKind::Publisher), 5);
    let sub = mine
        .iter()
        .find(|t| t.kind == EntityKind::Subscription)
        .unwrap();
    assert_eq!(sub.topic.as_ref().unwrap().topic, "/tok/points");
    let topics: Vec<String> = mine
        .iter()
        .filter_map(|t| t.topic.as_ref().map(|x| x.topic.clone()))
        .collect();
    for want in [
        "/diagnostics",
        "/tok/points/mesh",
        "/tok/points/mesh_markers",
        "/tok/points/membrane_diagnostics",
    ] {
        assert!(topics.iter().any(|t| t == want), "{want} in {topics:?}");
    }
    let summary = stop(r.stop_tx, r.node).await;
    assert!(summary.clean_shutdown);
    // The final DELETEALL markers were published and all tokens withdrawn.
    wait_for(
        || {
            markers
                .lock()
                .unwrap()
                .iter()
                .any(|r| r.payload == b"DELETEALL")
        },
        "final DELETEALL",
    )
    .await;
    let mut left = usize::MAX;
    for _ in 0..100 {
        left = liveliness(&h)
            .await
            .iter()
            .filter(|t| t.node == "tok")
            .count();
        if left == 0 {
            break;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    assert_eq!(left, 0, "tokens left after shutdown");
}

async fn liveliness(h: &Participant) -> Vec<Token> {
    let replies = h.session().liveliness().get("@ros2_lv/**").await.unwrap();
    let mut out = Vec::new();
    while let Ok(Ok(reply)) =
        tokio::time::timeout(Duration::from_secs(3), replies.recv_async()).await
    {
        if let Ok(s) = reply.result() {
            out.push(Token::parse(s.key_expr().as_str()).unwrap());
        }
    }
    out
}

/// A stream is evicted only after `evict_after_ms` of real silence: never
/// while one of its frames is being processed, and silence counts from the
/// end of the last processing (a publisher that waits for each result, as a
/// lock-step player does, is not silent). Eviction is seen as the
/// processor's DELETEALL markers.
/// Silence, stalls and latencies are measured on the node's monotonic
/// clock: the receipt time a processor sees lies between two readings of
/// `clock::mono_ns` around the frame, not on the wall clock, which a robot's
/// chrony may step by hours (a forward step would evict every stream and
/// forget every label at once, a backward one keep silent ones for hours).
/// The frame index of a [`TestProc`] output.
fn index_of(r: &Received) -> u64 {
    u64::from_le_bytes(r.payload[4..12].try_into().unwrap())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_mesh_leaves_before_the_frames_later_outputs_are_made() {
    let (h, cfg) = harness("early").await;
    let tail = Duration::from_millis(400);
    let backend = TestBackend {
        tail: Some(tail),
        ..TestBackend::default()
    };
    let r = rig_with(&h, "early", cfg, backend).await;
    let mesh = any_type("sepmem_msgs/msg/SurfaceMesh");
    let (_msub, meshes) = collect(&h, "/early/**", &mesh).await;
    let diag = any_type("sepmem_msgs/msg/FrameDiagnostics");
    let (_dsub, diags) = collect(&h, "/early/**", &diag).await;
    let mut k = 0;
    probe(
        &r.points,
        || diags.lock().unwrap().len() >= 3,
        || {
            k += 1;
            payload(k, 0)
        },
    )
    .await;
    // Every frame's mesh arrived at least most of the tail before the
    // frame's diagnostics: it was published before they were made.
    let meshes = meshes.lock().unwrap().clone();
    let diags = diags.lock().unwrap().clone();
    for d in &diags {
        let i = index_of(d);
        let m = meshes.iter().find(|m| index_of(m) == i);
        let m = m.unwrap_or_else(|| panic!("frame {i}: diagnostics without its mesh"));
        let ahead = Duration::from_nanos((d.received_ns - m.received_ns).max(0) as u64);
        assert!(
            ahead >= tail * 3 / 4,
            "frame {i}: the mesh arrived only {ahead:?} before the diagnostics (tail {tail:?})"
        );
    }
    let summary = stop(r.stop_tx, r.node).await;
    assert!(summary.clean_shutdown);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn receipt_times_are_on_the_monotonic_clock() {
    let (h, cfg) = harness("mono").await;
    let r = rig(&h, "mono", cfg).await;
    let before = mono_ns();
    let got = || !r.receipts.lock().unwrap().is_empty();
    probe(&r.points, got, || payload(0, 0)).await;
    let after = mono_ns();
    let receipts = r.receipts.lock().unwrap().clone();
    assert!(
        receipts.iter().all(|t| (before..=after).contains(t)),
        "receipts {receipts:?} outside [{before}, {after}]"
    );
    let summary = stop(r.stop_tx, r.node).await;
    assert!(summary.clean_shutdown);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_busy_stream_is_not_evicted_and_a_silent_one_is() {
    let (h, mut cfg) = harness("evb").await;
    cfg.evict_after_ms = 1000;
    cfg.diagnostics_period_ms = 50;
    let r = rig(&h, "evb", cfg).await;
    let (seen, markers, p) = (&r.seen, &r.markers, &r.points);
    let processed = |i: u64| seen.lock().unwrap().iter().any(|(_, k)| *k == i);
    // Probe until the node is subscribed (frame 0).
    probe(p, || processed(0), || payload(0, 0)).await;
    // Frame 1 computes for 2.5 × the eviction time; frame 2 follows as soon
    // as frame 1 is done.
    p.put(payload(1, 2500)).await.unwrap();
    wait_for(|| processed(1), "slow frame").await;
    p.put(payload(2, 0)).await.unwrap();
    wait_for(|| processed(2), "frame after the slow one").await;
    tokio::time::sleep(Duration::from_millis(200)).await;
    assert!(
        markers.lock().unwrap().is_empty(),
        "evicted while busy or right after a frame"
    );
    // Now silence: the stream is evicted (its DELETEALL markers arrive).
    wait_for(
        || !markers.lock().unwrap().is_empty(),
        "eviction of the silent stream",
    )
    .await;
    let summary = stop(r.stop_tx, r.node).await;
    assert!(summary.clean_shutdown);
    let s = summary
        .streams
        .iter()
        .find(|s| s.topic == "/evb/points")
        .unwrap();
    assert!(s.stale, "{s:?}");
    assert!(s.frames >= 3, "one processor saw every frame: {s:?}");
}

/// The stall guard and the compute share (issue 22): a stream whose one
/// frame holds a compute thread for 2.5 s is reported ERROR while it does
/// (and the node WARN); a stream whose frames cost 60 ms every 20 ms (three
/// times a thread) is held to its 0.2-core share, its waiting frames counted
/// as `over_budget` and reported WARN; a light stream keeps being processed.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stalled_or_greedy_stream_is_reported_and_the_others_keep_running() {
    let (h, mut cfg) = harness("grd").await;
    cfg.stall_after_ms = 300;
    cfg.compute_share = Some(sepmem::node::budget::ComputeShareConfig {
        cores: 0.2,
        burst_ms: 100.0,
    });
    let seen: Arc<Mutex<Vec<(String, u64)>>> = Arc::default();
    let backend = Arc::new(TestBackend {
        seen: seen.clone(),
        ..TestBackend::default()
    });
    let (stop_tx, node) = spawn_node(cfg, backend);
    let (_dsub, diags) = collect(
        &h,
        "/diagnostics",
        &any_type("diagnostic_msgs/msg/DiagnosticArray"),
    )
    .await;
    let publ = |t: &'static str| {
        let h = &h;
        async move { h.publisher(t, &pc2(), Qos::SENSOR_DATA).await.unwrap() }
    };
    let (stuck, greedy, light) = (
        publ("/grd/stuck").await,
        publ("/grd/greedy").await,
        publ("/grd/light").await,
    );
    let count = |t: &str| seen.lock().unwrap().iter().filter(|(s, _)| s == t).count();
    probe(&light, || count("/grd/light") > 0, || payload(0, 0)).await;
    stuck.put(payload(1, 2500)).await.unwrap();
    let mut sent_light = 0;
    for i in 1..=100u64 {
        greedy.put(payload(i, 60)).await.unwrap();
        light.put(payload(i, 0)).await.unwrap();
        sent_light += 1;
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let has = |needle: &str| {
        diags
            .lock()
            .unwrap()
            .iter()
            .any(|r| String::from_utf8_lossy(&r.payload).contains(needle))
    };
    assert!(
        has("grd: /grd/stuck|2|"),
        "the stuck stream was not reported ERROR"
    );
    assert!(has("grd: node|1|"), "the node was not reported WARN");
    wait_for(
        || has("grd: /grd/greedy|1|"),
        "the greedy stream reported WARN",
    )
    .await;
    let processed_light = count("/grd/light") - 1;
    let summary = stop(stop_tx, node).await;
    let get = |t: &str| stream_of(&summary, t);
    let greedy_s = get("/grd/greedy");
    let over = greedy_s.reasons.get("over_budget").copied().unwrap_or(0);
    // 100 frames of 60 ms in 2 s at 0.2 core: at most about 0.4 s + the
    // 0.1 s burst of compute, i.e. 9 frames, plus the one running at the end.
    assert!(greedy_s.frames <= 12, "{greedy_s:?}");
    assert!(over >= 5, "{greedy_s:?}");
    assert_eq!(summary.reasons.get("over_budget").copied(), Some(over));
    // The light stream kept its rate (keep-latest may merge a few frames).
    assert!(
        processed_light * 10 >= sent_light * 8,
        "{processed_light} of {sent_light}"
    );
    assert!(get("/grd/stuck").frames == 1);
}
