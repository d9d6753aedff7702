//! The node's task structure on tokio and rayon.
//!
//! * zenoh subscriber callbacks (zenoh's threads) map each sample's key to
//!   its topic, drop samples of other shards, and put a [`Frame`] into the
//!   topic's [`LatestSlot`] (creating the slot, and asking the manager for a
//!   stream task, for a new topic).
//! * One tokio task per stream waits on its slot, hands the newest frame and
//!   the stream's [`TopicProcessor`] to the rayon pool, publishes each
//!   output as the processor hands it over (an object's mesh leaves before
//!   the frame's later outputs are made), and awaits the result on a
//!   oneshot channel (tokio workers never block). Streams therefore compute
//!   in parallel, up to the pool size.
//! * The manager task spawns stream tasks, publishes `/diagnostics` every
//!   `diagnostics_period_ms`, and evicts streams silent for
//!   `evict_after_ms` (their state is freed and they are reported STALE).
//! * Each stream's frames are charged to its compute share
//!   ([`super::budget`]): a stream in debt gets no compute until it earned it
//!   back (its frames are counted `over_budget`), and a frame in compute
//!   for longer than the cold budget plus `stall_after_ms` is reported
//!   stalled. What a frame refused is counted per reason
//!   ([`super::reasons`]); `/diagnostics` holds at most one status per
//!   tracked object (bounded by `pipeline.objects.max_tracked`) with
//!   messages cut to [`MAX_MESSAGE`] bytes.
//! * On shutdown the slots are closed, in-flight frames get
//!   `shutdown_timeout_ms` to finish (then are abandoned), processors emit
//!   their final outputs (DELETEALL markers), a final `/diagnostics` is
//!   published, and all liveliness tokens are undeclared before the session
//!   closes.

use super::backend::{
    Backend, Frame, ObjectReport, Output, OutputKind, StatusEntry, TopicProcessor,
};
use super::budget::ShareMeter;
use super::clock::mono_ns;
use super::reasons;
use super::slot::LatestSlot;
use super::stats::{LatencyWindow, Level};
use super::{NodeConfig, NodeError};
use crate::transport::attachment::now_ns;
use crate::transport::keys::expand_topic_template;
use crate::transport::liveliness::{EntityKind, Qos};
use crate::transport::session::EntityToken;
use crate::transport::{Outlet, Participant, Received, RosPublisher};
use std::collections::{BTreeMap, HashMap};
use std::future::Future;
use std::num::NonZeroUsize;
use std::sync::atomic::{AtomicBool, AtomicI64, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};
use tokio::sync::{mpsc, oneshot, watch};
use tokio::task::JoinSet;

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    match m.lock() {
        Ok(g) => g,
        Err(p) => p.into_inner(),
    }
}

/// Longest status message in `/diagnostics` (bytes); longer ones are cut.
pub const MAX_MESSAGE: usize = 240;

/// `s` cut to at most [`MAX_MESSAGE`] bytes at a character boundary.
fn bounded(mut s: String) -> String {
    if s.len() > MAX_MESSAGE {
        let mut end = MAX_MESSAGE - 3;
        while !s.is_char_boundary(end) {
            end -= 1;
        }
        s.truncate(end);
        s.push_str("...");
    }
    s
}

/// Per-object counters.
#[derive(Debug, Clone)]
struct ObjectStats {
    last: ObjectReport,
    warm: u64,
    cold: u64,
}

/// Per-stream counters shared by the stream task and the manager.
#[derive(Debug, Default)]
struct StreamStats {
    frames: u64,
    errors: u64,
    late: u64,
    latency: LatencyWindow,
    e2e: LatencyWindow,
    last_error: Option<String>,
    last_failed: bool,
    objects: BTreeMap<String, ObjectStats>,
    stale_since_ns: Option<i64>,
    drops: u64,
    received: u64,
    reported_drops: u64,
    reported_late: u64,
    reported_frames: u64,
    /// What the stream's frames refused or discarded, by reason.
    reasons: BTreeMap<&'static str, u64>,
    reported_over_budget: u64,
    /// When this stream last logged a failed frame (ns), and the failures
    /// left unlogged since: a hostile stream fails every frame, and the log
    /// says so once per [`WARN_EVERY_NS`], not 30 times a second.
    last_warn_ns: Option<i64>,
    unlogged: u64,
    /// Output messages handed to zenoh. Each output carries the rmw_zenoh
    /// attachment's sequence number, so a subscriber counts what the
    /// transport dropped under load as the gaps (`bench-node` does).
    published: u64,
}

/// Least time between two "frame failed" warnings of one stream.
const WARN_EVERY_NS: i64 = 5_000_000_000;

impl StreamStats {
    fn count(&self, reason: &str) -> u64 {
        self.reasons.get(reason).copied().unwrap_or(0)
    }
}

struct Stream {
    slot: Arc<LatestSlot<Frame>>,
    stats: Arc<Mutex<StreamStats>>,
    /// A frame of this stream is being processed (never evicted then).
    busy: AtomicBool,
    /// When the frame now in compute started computing (ns; 0 = none).
    computing_since_ns: AtomicI64,
}

/// Counters of samples that never reached a stream.
#[derive(Debug, Default)]
struct Ignored {
    foreign_keys: AtomicU64,
    own_outputs: AtomicU64,
    other_shard: AtomicU64,
    over_capacity: AtomicU64,
    bad_attachments: AtomicU64,
}

struct Shared {
    streams: Mutex<HashMap<String, Arc<Stream>>>,
    new_tx: mpsc::Sender<String>,
    ignored: Ignored,
    cfg: NodeConfig,
    /// A frame in compute longer than this (ns) is stalled.
    stall_ns: i64,
    /// Reason counts of streams that were forgotten (so node totals keep them).
    retired: Mutex<BTreeMap<&'static str, u64>>,
}

/// Final figures of one stream.
#[derive(Debug, Clone, PartialEq)]
pub struct StreamSummary {
    /// Input topic.
    pub topic: String,
    /// Frames received (processed + dropped + pending at the end).
    pub received: u64,
    /// Frames processed.
    pub frames: u64,
    /// Frames replaced in the slot before processing.
    pub drops: u64,
    /// Frames that failed (malformed input …).
    pub errors: u64,
    /// Frames finished after their deadline.
    pub late: u64,
    /// Warm-started object frames.
    pub warm: u64,
    /// Cold-started object frames.
    pub cold: u64,
    /// Median receipt→publish latency, seconds.
    pub p50_s: Option<f64>,
    /// 95th percentile receipt→publish latency, seconds.
    pub p95_s: Option<f64>,
    /// Whether the stream was evicted (STALE) at the end.
    pub stale: bool,
    /// What the stream's frames refused or discarded, by reason.
    pub reasons: BTreeMap<String, u64>,
}

/// What the node did, returned when it stops.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct NodeSummary {
    /// Per-stream figures, sorted by topic.
    pub streams: Vec<StreamSummary>,
    /// Samples whose key was not a topic of the key mode.
    pub foreign_keys: u64,
    /// Samples on a topic that is an output of this node's templates
    /// ([`super::OutputTopics::is_output`]).
    pub own_outputs: u64,
    /// Samples of streams owned by another shard.
    pub other_shard: u64,
    /// Samples refused because `max_streams` streams existed.
    pub over_capacity: u64,
    /// Samples with a malformed rmw_zenoh attachment (still processed).
    pub bad_attachments: u64,
    /// Whether every in-flight frame finished within the shutdown bound.
    pub clean_shutdown: bool,
    /// Reason counts over all streams, forgotten ones included.
    pub reasons: BTreeMap<String, u64>,
}

/// Run the node until `shutdown` resolves.
///
/// # Errors
/// [`NodeError`] when the configuration is invalid or the transport fails to
/// start; failures after start-up are logged and counted, not returned.
pub async fn run<S>(
    cfg: &NodeConfig,
    backend: Arc<dyn Backend>,
    shutdown: S,
) -> Result<NodeSummary, NodeError>
where
    S: Future<Output = ()>,
{
    cfg.validate()?;
    let pool = cfg.compute_pool()?;
    // zenoh drops a message above the backend's limit while reassembling
    // it, so `wire.max_bytes` bounds what is ever held of one message.
    let mut transport = cfg.transport.clone();
    transport.zenoh.max_message_bytes = backend.max_message_bytes();
    let participant = Arc::new(Participant::open(&transport).await?);
    tracing::info!(zid = participant.zid(), node = %cfg.transport.node_name, "node started");
    let (new_tx, mut new_rx) = mpsc::channel::<String>(cfg.max_streams.max(16));
    // No deadline: a day is as good as none, and keeps `Frame::deadline` an Instant.
    let deadline = backend
        .frame_deadline()
        .unwrap_or(Duration::from_secs(86_400));
    let stall = backend.frame_budget().unwrap_or(Duration::ZERO)
        + Duration::from_millis(cfg.stall_after_ms);
    let shared = Arc::new(Shared {
        streams: Mutex::new(HashMap::new()),
        new_tx,
        ignored: Ignored::default(),
        cfg: cfg.clone(),
        stall_ns: i64::try_from(stall.as_nanos()).unwrap_or(i64::MAX),
        retired: Mutex::new(BTreeMap::new()),
    });

    let input_type = cfg.transport.advertised(&backend.input_type());
    let mut subscribers = Vec::new();
    for pattern in &cfg.topics {
        let sh = shared.clone();
        let sub = participant
            .subscribe(pattern, &input_type, move |r| on_sample(&sh, r, deadline))
            .await?;
        subscribers.push(sub);
    }
    let early_tokens = declare_exact_subscriptions(&participant, cfg, &input_type).await;
    let diag_topic = expand_topic_template(&cfg.outputs.diagnostics, "/");
    let diag_pub = participant
        .publisher(
            &diag_topic,
            &cfg.transport.advertised(&backend.diagnostics_type()),
            cfg.output_qos(),
        )
        .await?;

    let (stop_tx, stop_rx) = watch::channel(false);
    let mut tasks = JoinSet::new();
    let mut ticker = tokio::time::interval(Duration::from_millis(cfg.diagnostics_period_ms));
    ticker.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut all_stats: BTreeMap<String, Arc<Mutex<StreamStats>>> = BTreeMap::new();
    let mut clean = true;
    tokio::pin!(shutdown);
    loop {
        tokio::select! {
            () = &mut shutdown => break,
            Some(topic) = new_rx.recv() => {
                let stream = lock(&shared.streams).get(&topic).cloned();
                if let Some(stream) = stream {
                    all_stats.insert(topic.clone(), stream.stats.clone());
                    let ctx = StreamCtx {
                        topic,
                        stream,
                        participant: participant.clone(),
                        backend: backend.clone(),
                        pool: pool.clone(),
                        cfg: shared.cfg.clone(),
                        stop: stop_rx.clone(),
                    };
                    tasks.spawn(stream_task(ctx));
                }
            }
            Some(joined) = tasks.join_next(), if !tasks.is_empty() => {
                if let Ok(false) = joined {
                    clean = false;
                }
            }
            _ = ticker.tick() => {
                evict(&shared, &mut all_stats);
                publish_diagnostics(&diag_pub, backend.as_ref(), &shared, &all_stats, false).await;
            }
        }
    }

    tracing::info!("shutting down");
    let _ = stop_tx.send(true);
    for s in lock(&shared.streams).values() {
        s.slot.close();
    }
    drop(subscribers);
    let bound = Duration::from_millis(cfg.shutdown_timeout_ms) + Duration::from_secs(1);
    let joined = tokio::time::timeout(bound, async {
        let mut ok = true;
        while let Some(r) = tasks.join_next().await {
            ok &= r.unwrap_or(false);
        }
        ok
    })
    .await;
    match joined {
        Ok(ok) => clean &= ok,
        Err(_) => {
            clean = false;
            tasks.abort_all();
        }
    }
    publish_diagnostics(&diag_pub, backend.as_ref(), &shared, &all_stats, true).await;
    let summary = summarize(&shared, &all_stats, clean);
    if let Err(e) = diag_pub.undeclare().await {
        tracing::warn!(error = %e, "undeclaring /diagnostics publisher");
    }
    for t in early_tokens {
        if let Err(e) = t.undeclare().await {
            tracing::warn!(error = %e, "undeclaring subscription token");
        }
    }
    participant.close().await?;
    Ok(summary)
}

/// `MS` tokens for the configured topics without wildcards, declared at
/// start so that the graph (`ros2 topic info`) shows the subscription before
/// any sample arrives; streams of these topics then declare none of their own.
async fn declare_exact_subscriptions(
    participant: &Participant,
    cfg: &NodeConfig,
    input_type: &crate::transport::RosType,
) -> Vec<crate::transport::EntityToken> {
    let mut tokens = Vec::new();
    for topic in cfg.exact_topics() {
        match participant
            .declare_entity(
                EntityKind::Subscription,
                &topic,
                input_type,
                Qos::SENSOR_DATA,
            )
            .await
        {
            Ok(t) => tokens.push(t),
            Err(e) => tracing::warn!(%topic, error = %e, "cannot declare subscription token"),
        }
    }
    tokens
}

fn on_sample(shared: &Shared, r: Received, deadline: Duration) {
    let topic = match r.topic {
        Ok(t) => t,
        Err(e) => {
            shared.ignored.foreign_keys.fetch_add(1, Ordering::Relaxed);
            tracing::debug!(error = %e, "ignoring sample");
            return;
        }
    };
    if shared.cfg.outputs.is_output(&topic, &shared.cfg.topics) {
        shared.ignored.own_outputs.fetch_add(1, Ordering::Relaxed);
        return;
    }
    if !shared.cfg.shard.owns(&topic) {
        shared.ignored.other_shard.fetch_add(1, Ordering::Relaxed);
        return;
    }
    let (source_ns, sequence) = match &r.attachment {
        Some(Ok(a)) => (Some(a.timestamp_ns), Some(a.sequence)),
        Some(Err(_)) => {
            shared
                .ignored
                .bad_attachments
                .fetch_add(1, Ordering::Relaxed);
            (None, None)
        }
        None => (None, None),
    };
    // On the node's monotonic clock (`clock`), not the wall time zenoh's
    // callback read: silence and latency must not jump with the wall clock.
    let received_ns = mono_ns();
    let frame = Frame {
        topic: topic.clone(),
        payload: r.payload,
        received_ns,
        source_ns,
        sequence,
        deadline: Instant::now() + deadline,
    };
    // The map stays locked until the frame is in the slot: `evict` must
    // never see a new stream before its first frame (it would read "silent
    // since the epoch" and close the slot under the frame).
    let mut map = lock(&shared.streams);
    if let Some(s) = map.get(&topic) {
        s.slot.put(frame, received_ns);
        return;
    }
    if map.len() >= shared.cfg.max_streams {
        shared.ignored.over_capacity.fetch_add(1, Ordering::Relaxed);
        return;
    }
    let s = Arc::new(Stream {
        slot: Arc::new(LatestSlot::new()),
        stats: Arc::new(Mutex::new(StreamStats::default())),
        busy: AtomicBool::new(false),
        computing_since_ns: AtomicI64::new(0),
    });
    if shared.new_tx.try_send(topic.clone()).is_err() {
        shared.ignored.over_capacity.fetch_add(1, Ordering::Relaxed);
        return;
    }
    s.slot.put(frame, received_ns);
    map.insert(topic, s);
}

struct StreamCtx {
    topic: String,
    stream: Arc<Stream>,
    participant: Arc<Participant>,
    backend: Arc<dyn Backend>,
    pool: Arc<rayon::ThreadPool>,
    cfg: NodeConfig,
    stop: watch::Receiver<bool>,
}

/// The frame a compute job took (what the stream task needs of it once the
/// payload is gone) and its result.
struct Taken {
    received_ns: i64,
    source_ns: Option<i64>,
    deadline: Instant,
    /// Wall time the frame spent in compute.
    busy: Duration,
    result: super::backend::FrameResult,
}

/// What a compute job hands back: the processor, and what it took (`None`
/// when the slot was empty by the time the job ran).
type Done = (Box<dyn TopicProcessor>, Option<Taken>);

/// How a compute job ended, seen from the stream task.
enum Computed {
    /// The frame was abandoned at shutdown (the processor with it).
    Abandoned,
    /// The slot was empty when the job ran.
    Empty(Box<dyn TopicProcessor>),
    /// The frame was processed, and its outputs published.
    Done(Box<dyn TopicProcessor>, Taken, Sent),
}

type Publishers = BTreeMap<OutputKind, RosPublisher>;

/// One stream's worker; returns whether it stopped cleanly (no abandoned frame).
async fn stream_task(mut ctx: StreamCtx) -> bool {
    let (token, pubs) = declare_stream(&ctx).await;
    let mut processor: Option<Box<dyn TopicProcessor>> = Some(ctx.backend.processor(&ctx.topic));
    let mut meter = ctx
        .cfg
        .compute_share
        .as_ref()
        .map(|c| ShareMeter::new(c, Instant::now()));
    let mut clean = true;
    loop {
        if ctx.stream.slot.has_pending() {
            if let Some(debt) = meter.as_mut().and_then(|m| m.debt(Instant::now())) {
                if !sit_out(&ctx, debt).await {
                    break;
                }
                continue;
            }
            let Some(p) = processor.take() else { break };
            match compute(&ctx, &pubs, p).await {
                Computed::Abandoned => {
                    tracing::warn!(topic = %ctx.topic, "in-flight frame abandoned at shutdown");
                    clean = false;
                    break;
                }
                Computed::Empty(p) => processor = Some(p),
                Computed::Done(p, taken, sent) => {
                    processor = Some(p);
                    if let Some(m) = meter.as_mut() {
                        m.charge(taken.busy, Instant::now());
                    }
                    record(&ctx, taken, sent);
                }
            }
            continue;
        }
        if ctx.stream.slot.is_closed() || *ctx.stop.borrow() {
            break;
        }
        tokio::select! {
            () = ctx.stream.slot.wait() => {}
            _ = ctx.stop.changed() => {}
        }
    }
    // Final outputs (e.g. DELETEALL markers), then withdraw everything.
    if let Some(mut p) = processor {
        publish_outputs(&pubs, &ctx.topic, p.on_evict()).await;
    }
    for (_, p) in pubs {
        if let Err(e) = p.undeclare().await {
            tracing::warn!(topic = %ctx.topic, error = %e, "undeclaring publisher");
        }
    }
    if let Some(t) = token {
        if let Err(e) = t.undeclare().await {
            tracing::warn!(topic = %ctx.topic, error = %e, "undeclaring subscription token");
        }
    }
    tracing::info!(topic = %ctx.topic, "stream stopped");
    clean
}

async fn declare_stream_subscription(
    ctx: &StreamCtx,
    topic: &str,
) -> Option<crate::transport::EntityToken> {
    let ty = ctx.cfg.transport.advertised(&ctx.backend.input_type());
    match ctx
        .participant
        .declare_entity(EntityKind::Subscription, topic, &ty, Qos::SENSOR_DATA)
        .await
    {
        Ok(t) => Some(t),
        Err(e) => {
            tracing::warn!(%topic, error = %e, "cannot declare subscription token");
            None
        }
    }
}

/// The stream's subscription token (none for an exact topic: it has had
/// its token since start, see `run`) and output publishers.
async fn declare_stream(ctx: &StreamCtx) -> (Option<EntityToken>, Publishers) {
    let topic = &ctx.topic;
    let tr = &ctx.cfg.transport;
    let token = if ctx.cfg.exact_topics().contains(topic) {
        None
    } else {
        declare_stream_subscription(ctx, topic).await
    };
    let mut pubs = Publishers::new();
    for kind in OutputKind::ALL {
        let Some(template) = ctx.cfg.outputs.template(kind) else {
            continue;
        };
        if !ctx.backend.publishes(kind) {
            continue;
        }
        let out = expand_topic_template(template, topic);
        let ty = tr.advertised(&ctx.backend.output_type(kind));
        match ctx
            .participant
            .publisher_in(
                &out,
                &ty,
                ctx.cfg.output_qos_of(kind),
                outlet_of(&ctx.cfg, kind),
            )
            .await
        {
            Ok(p) => {
                pubs.insert(kind, p);
            }
            Err(e) => tracing::warn!(%topic, output = %out, error = %e, "cannot declare publisher"),
        }
    }
    (token, pubs)
}

/// The lane and cache depth of one output kind's publisher.
fn outlet_of(cfg: &NodeConfig, kind: OutputKind) -> Outlet {
    Outlet {
        lane: kind.lane(),
        cache: cfg
            .output_cache_of(kind)
            .and_then(|d| usize::try_from(d).ok())
            .and_then(NonZeroUsize::new),
    }
}

/// Hand the stream's newest frame and its processor to the compute pool,
/// publish each output as the processor hands it over, and wait for the
/// result (tokio workers never block).
async fn compute(ctx: &StreamCtx, pubs: &Publishers, mut p: Box<dyn TopicProcessor>) -> Computed {
    ctx.stream.busy.store(true, Ordering::Release);
    let (tx, mut rx) = oneshot::channel::<Done>();
    // Unbounded, but it holds at most one frame's outputs: a mesh and a
    // diagnostics message per object (at most pipeline.objects.max_per_frame)
    // and a few per frame.
    let (out_tx, mut out_rx) = mpsc::unbounded_channel::<Output>();
    // Late binding: the job takes the newest frame when a compute thread is
    // free, so a frame never ages in the pool's queue while a newer one
    // waits in the slot (that older one is then counted as dropped, and the
    // deadline is not spent waiting).
    let stream = ctx.stream.clone();
    ctx.pool.spawn(move || {
        let Some(frame) = stream.slot.take() else {
            let _ = tx.send((p, None));
            return;
        };
        let span = tracing::info_span!("frame", topic = %frame.topic, seq = ?frame.sequence);
        let _enter = span.enter();
        let start = Instant::now();
        stream
            .computing_since_ns
            .store(mono_ns(), Ordering::Release);
        let result = p.process(&frame, &mut |out| {
            let _ = out_tx.send(out);
        });
        stream.computing_since_ns.store(0, Ordering::Release);
        tracing::debug!(objects = result.objects.len(), error = ?result.error, "frame done");
        let taken = Taken {
            received_ns: frame.received_ns,
            source_ns: frame.source_ns,
            deadline: frame.deadline,
            busy: start.elapsed(),
            result,
        };
        let _ = tx.send((p, Some(taken)));
    });
    let shutdown_bound = Duration::from_millis(ctx.cfg.shutdown_timeout_ms);
    let mut sent = Sent::default();
    let stop = wait_stop(ctx.stop.clone());
    tokio::pin!(stop);
    let done = loop {
        tokio::select! {
            Some(out) = out_rx.recv() => sent.count(publish_output(pubs, &ctx.topic, out).await),
            r = &mut rx => break r.ok(),
            () = &mut stop => break tokio::time::timeout(shutdown_bound, &mut rx).await.ok().and_then(Result::ok),
        }
    };
    // The outputs handed over just before the result came.
    while let Ok(out) = out_rx.try_recv() {
        sent.count(publish_output(pubs, &ctx.topic, out).await);
    }
    match done {
        None => Computed::Abandoned,
        Some((p, None)) => {
            ctx.stream.busy.store(false, Ordering::Release);
            Computed::Empty(p)
        }
        Some((p, Some(taken))) => Computed::Done(p, taken, sent),
    }
}

/// The stream is `debt` over its compute share: its pending frame waits
/// until it has earned that back (frames arriving meanwhile replace it, as
/// in any keep-latest slot). The waiting frame and those replaced are
/// counted as `over_budget`. Returns `false` at shutdown.
async fn sit_out(ctx: &StreamCtx, debt: Duration) -> bool {
    let dropped = ctx.stream.slot.dropped();
    // A stream with a frame waiting is not silent: never evicted meanwhile.
    ctx.stream.busy.store(true, Ordering::Release);
    let running = tokio::select! {
        () = tokio::time::sleep(debt) => true,
        () = wait_stop(ctx.stop.clone()) => false,
    };
    ctx.stream.slot.touch(mono_ns());
    ctx.stream.busy.store(false, Ordering::Release);
    let n = ctx.stream.slot.dropped().saturating_sub(dropped) + 1;
    *lock(&ctx.stream.stats)
        .reasons
        .entry(reasons::OVER_BUDGET)
        .or_default() += n;
    running
}

/// How many of a frame's outputs were handed to zenoh, and how many could
/// not be.
#[derive(Debug, Default, Clone, Copy)]
struct Sent {
    published: u64,
    failed: u64,
}

impl Sent {
    fn count(&mut self, published: bool) {
        if published {
            self.published += 1;
        } else {
            self.failed += 1;
        }
    }
}

/// Publish one output; whether zenoh took it.
async fn publish_output(pubs: &Publishers, topic: &str, out: Output) -> bool {
    let Some(publ) = pubs.get(&out.kind) else {
        return false;
    };
    match publ.put(out.payload).await {
        Ok(()) => true,
        Err(e) => {
            tracing::warn!(%topic, error = %e, "publish failed");
            false
        }
    }
}

/// Publish a stream's final outputs.
async fn publish_outputs(pubs: &Publishers, topic: &str, outputs: Vec<Output>) {
    for out in outputs {
        publish_output(pubs, topic, out).await;
    }
}

/// Add one processed frame to the stream's statistics.
fn record(ctx: &StreamCtx, taken: Taken, sent: Sent) {
    let now = mono_ns();
    ctx.stream.slot.touch(now);
    ctx.stream.busy.store(false, Ordering::Release);
    let late = Instant::now() > taken.deadline;
    let result = taken.result;
    let mut st = lock(&ctx.stream.stats);
    st.frames += 1;
    st.drops = ctx.stream.slot.dropped();
    st.received = ctx.stream.slot.received();
    st.latency.push((now - taken.received_ns) as f64 * 1e-9);
    if let Some(s) = taken.source_ns {
        // The source stamp is the publisher's wall clock.
        st.e2e.push((now_ns() - s) as f64 * 1e-9);
    }
    if late {
        st.late += 1;
    }
    for (reason, n) in result.counts {
        *st.reasons.entry(reason).or_default() += n;
    }
    st.published += sent.published;
    if sent.failed > 0 {
        *st.reasons.entry(reasons::OUTPUTS_FAILED).or_default() += sent.failed;
    }
    st.last_failed = result.error.is_some();
    if let Some(e) = result.error {
        if st.last_warn_ns.is_none_or(|t| now - t >= WARN_EVERY_NS) {
            let also = std::mem::take(&mut st.unlogged);
            tracing::warn!(topic = %ctx.topic, error = %e, unlogged_since = also, "frame failed");
            st.last_warn_ns = Some(now);
        } else {
            st.unlogged += 1;
        }
        st.errors += 1;
        st.last_error = Some(bounded(e));
    }
    for gone in &result.evicted {
        st.objects.remove(gone);
    }
    for mut o in result.objects {
        o.message = bounded(o.message);
        let e = st.objects.entry(o.stream.clone()).or_insert(ObjectStats {
            last: o.clone(),
            warm: 0,
            cold: 0,
        });
        if o.warm {
            e.warm += 1;
        } else {
            e.cold += 1;
        }
        e.last = o;
    }
}

async fn wait_stop(mut stop: watch::Receiver<bool>) {
    let _ = stop.wait_for(|v| *v).await;
}

fn evict(shared: &Shared, all: &mut BTreeMap<String, Arc<Mutex<StreamStats>>>) {
    let now = mono_ns();
    let after =
        i64::try_from(shared.cfg.evict_after_ms).unwrap_or(i64::MAX / 2_000_000) * 1_000_000;
    let mut map = lock(&shared.streams);
    let silent: Vec<(String, i64)> = map
        .iter()
        .filter(|(_, s)| !s.busy.load(Ordering::Acquire))
        .map(|(k, s)| (k.clone(), now - s.slot.last_seen_ns()))
        .filter(|(_, silent_ns)| *silent_ns > after)
        .collect();
    for (topic, silent_ns) in silent {
        if let Some(s) = map.remove(&topic) {
            tracing::info!(%topic, silent_ms = silent_ns / 1_000_000, "evicting silent stream");
            s.slot.close();
            lock(&s.stats).stale_since_ns = Some(now);
        }
    }
    drop(map);
    // Forget streams that have been reported STALE for another period; the
    // node's totals keep their counts.
    let mut retired = lock(&shared.retired);
    all.retain(|_, st| {
        let st = lock(st);
        let keep = st.stale_since_ns.is_none_or(|t| now - t <= after);
        if !keep {
            for (r, n) in &st.reasons {
                *retired.entry(*r).or_default() += n;
            }
        }
        keep
    });
}

/// How a stream's compute stands at `now_ns`: stalled (a frame in compute
/// for longer than the stall bound), over its share since the last report,
/// or fine.
fn compute_state(
    shared: &Shared,
    since: i64,
    st: &mut StreamStats,
    now_ns: i64,
) -> Option<(Level, String)> {
    let over = st.count(reasons::OVER_BUDGET);
    let new_over = over - st.reported_over_budget.min(over);
    st.reported_over_budget = over;
    if since > 0 && now_ns - since > shared.stall_ns {
        let ms = (now_ns - since) / 1_000_000;
        return Some((
            Level::Error,
            format!("stalled: one frame has held a compute thread for {ms} ms"),
        ));
    }
    (new_over > 0).then(|| {
        (
            Level::Warn,
            format!("over its compute share: {new_over} frames skipped"),
        )
    })
}

/// The `/diagnostics` values every status of a stream carries.
fn stream_values(topic: &str, st: &StreamStats) -> Vec<(String, String)> {
    let ms = |v: Option<f64>| v.map_or_else(|| "nan".to_string(), |s| format!("{:.3}", s * 1e3));
    let mut v = vec![
        ("topic".into(), topic.to_string()),
        ("frames".into(), st.frames.to_string()),
        ("drops".into(), st.drops.to_string()),
        ("published".into(), st.published.to_string()),
        ("errors".into(), st.errors.to_string()),
        ("late".into(), st.late.to_string()),
        ("p50_ms".into(), ms(st.latency.quantile(0.5))),
        ("p95_ms".into(), ms(st.latency.quantile(0.95))),
        ("e2e_p95_ms".into(), ms(st.e2e.quantile(0.95))),
    ];
    v.extend(
        reasons::ALL
            .iter()
            .map(|r| ((*r).to_string(), st.count(r).to_string())),
    );
    v
}

/// The node's own status: counts of samples that reached no stream, and
/// each reason summed over all streams (forgotten ones included).
fn node_status(
    shared: &Shared,
    all: &BTreeMap<String, Arc<Mutex<StreamStats>>>,
    last: bool,
    troubled: usize,
) -> StatusEntry {
    let node = &shared.cfg.transport.node_name;
    let ig = &shared.ignored;
    let live = lock(&shared.streams).len();
    let mut values: Vec<(String, String)> = vec![
        ("streams".into(), live.to_string()),
        (
            "shard".into(),
            format!("{}/{}", shared.cfg.shard.index, shared.cfg.shard.count),
        ),
    ];
    let ignored = [
        ("foreign_keys", &ig.foreign_keys),
        ("own_outputs", &ig.own_outputs),
        ("other_shard", &ig.other_shard),
        ("over_capacity", &ig.over_capacity),
        ("bad_attachments", &ig.bad_attachments),
    ];
    values.extend(
        ignored
            .iter()
            .map(|(k, v)| ((*k).to_string(), v.load(Ordering::Relaxed).to_string())),
    );
    values.extend(
        totals(shared, all)
            .into_iter()
            .map(|(k, v)| (k, v.to_string())),
    );
    let (level, message) = match (last, troubled) {
        (true, _) => (Level::Ok, "shutting down".to_string()),
        (false, 0) => (Level::Ok, "running".to_string()),
        (false, n) => (
            Level::Warn,
            format!("running; {n} streams stalled or over their compute share"),
        ),
    };
    StatusEntry {
        name: format!("{node}: node"),
        level,
        message,
        hardware_id: node.clone(),
        values,
    }
}

/// Every reason summed over all streams, forgotten ones included.
fn totals(
    shared: &Shared,
    all: &BTreeMap<String, Arc<Mutex<StreamStats>>>,
) -> BTreeMap<String, u64> {
    let mut t: BTreeMap<String, u64> = reasons::ALL.iter().map(|r| ((*r).to_string(), 0)).collect();
    let mut add = |r: &str, n: u64| *t.entry(r.to_string()).or_default() += n;
    for (r, n) in lock(&shared.retired).iter() {
        add(r, *n);
    }
    for st in all.values() {
        for (r, n) in &lock(st).reasons {
            add(r, *n);
        }
    }
    t
}

/// Share of a stream's frames since its last `/diagnostics` status above
/// which the frames that finished after their deadline make it WARN. A
/// frame may end past its deadline by the iteration it must run
/// (`pipeline.warm_min_iterations`) and by a wrong guess of the last
/// iteration's time: on an idle machine a healthy 6 k-point stream at the
/// default deadline finished 42 of 151 frames after it (`sepmem bench-node
/// --streams 1 --rate 10 --points 6000`), which WARNed nearly every
/// period. A stream whose frames mostly miss it needs a longer deadline or
/// fewer points.
const LATE_WARN_SHARE: f64 = 0.5;

/// Whether `late` of `frames` is more than [`LATE_WARN_SHARE`].
fn mostly_late(late: u64, frames: u64) -> bool {
    late as f64 > LATE_WARN_SHARE * frames as f64
}

fn statuses(
    shared: &Shared,
    all: &BTreeMap<String, Arc<Mutex<StreamStats>>>,
    last: bool,
) -> Vec<StatusEntry> {
    let node = &shared.cfg.transport.node_name;
    let now = mono_ns();
    let mut out = Vec::new();
    let mut troubled = 0;
    for (topic, st) in all {
        let since = lock(&shared.streams)
            .get(topic)
            .map_or(0, |s| s.computing_since_ns.load(Ordering::Acquire));
        let mut st = lock(st);
        let new_drops = st.drops > st.reported_drops;
        let new_late = mostly_late(st.late - st.reported_late, st.frames - st.reported_frames);
        st.reported_drops = st.drops;
        st.reported_late = st.late;
        st.reported_frames = st.frames;
        let compute = compute_state(shared, since, &mut st, now);
        troubled += usize::from(compute.is_some());
        let base_level = if st.stale_since_ns.is_some() {
            Level::Stale
        } else if st.last_failed {
            Level::Error
        } else if new_drops || new_late {
            Level::Warn
        } else {
            Level::Ok
        };
        let base_level = compute
            .as_ref()
            .map_or(base_level, |(l, _)| base_level.max(*l));
        let stale_msg = "stream silent: evicted";
        let entry = |name: &str, level: Level, message: String, values| StatusEntry {
            name: format!("{node}: {name}"),
            level,
            message: match (&compute, level) {
                (_, Level::Stale) => stale_msg.into(),
                (Some((_, why)), _) => format!("{why}; {message}"),
                (None, _) => message,
            },
            hardware_id: node.clone(),
            values,
        };
        if st.objects.is_empty() {
            let message = st
                .last_error
                .clone()
                .unwrap_or_else(|| "no object yet".into());
            out.push(entry(topic, base_level, message, stream_values(topic, &st)));
            continue;
        }
        for (name, o) in &st.objects {
            let mut values = vec![
                ("eta_g".into(), format!("{:.4}", o.last.eta_g)),
                ("iterations".into(), o.last.iterations.to_string()),
                ("warm".into(), o.warm.to_string()),
                ("cold".into(), o.cold.to_string()),
                ("quality".into(), o.last.quality.unwrap_or("").to_string()),
            ];
            if let Some(b) = o.last.model_bytes {
                values.push(("model_bytes".into(), b.to_string()));
            }
            values.extend(stream_values(topic, &st));
            let level = if base_level == Level::Stale {
                Level::Stale
            } else {
                base_level.max(o.last.level)
            };
            let message = match level {
                Level::Error if st.last_failed => st.last_error.clone().unwrap_or_default(),
                _ if new_drops => format!("{}; dropping frames", o.last.message),
                _ if new_late => format!(
                    "{}; most frames finished after their deadline (raise pipeline.deadline_ms or thin the cloud: pipeline.max_frame_points)",
                    o.last.message
                ),
                _ => o.last.message.clone(),
            };
            out.push(entry(name, level, message, values));
        }
    }
    out.insert(0, node_status(shared, all, last, troubled));
    out
}

async fn publish_diagnostics(
    publ: &RosPublisher,
    backend: &dyn Backend,
    shared: &Shared,
    all: &BTreeMap<String, Arc<Mutex<StreamStats>>>,
    last: bool,
) {
    let status = statuses(shared, all, last);
    let bytes = backend.encode_diagnostics(now_ns(), "", &status);
    if let Err(e) = publ.put(bytes).await {
        tracing::warn!(error = %e, "publishing /diagnostics");
    }
}

fn summarize(
    shared: &Shared,
    all: &BTreeMap<String, Arc<Mutex<StreamStats>>>,
    clean: bool,
) -> NodeSummary {
    let streams = all
        .iter()
        .map(|(topic, st)| {
            let st = lock(st);
            StreamSummary {
                topic: topic.clone(),
                received: st.received,
                frames: st.frames,
                drops: st.drops,
                errors: st.errors,
                late: st.late,
                warm: st.objects.values().map(|o| o.warm).sum(),
                cold: st.objects.values().map(|o| o.cold).sum(),
                p50_s: st.latency.quantile(0.5),
                p95_s: st.latency.quantile(0.95),
                stale: st.stale_since_ns.is_some(),
                reasons: st
                    .reasons
                    .iter()
                    .map(|(r, n)| ((*r).to_string(), *n))
                    .collect(),
            }
        })
        .collect();
    let ig = &shared.ignored;
    NodeSummary {
        streams,
        foreign_keys: ig.foreign_keys.load(Ordering::Relaxed),
        own_outputs: ig.own_outputs.load(Ordering::Relaxed),
        other_shard: ig.other_shard.load(Ordering::Relaxed),
        over_capacity: ig.over_capacity.load(Ordering::Relaxed),
        bad_attachments: ig.bad_attachments.load(Ordering::Relaxed),
        clean_shutdown: clean,
        reasons: totals(shared, all),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_stream_is_late_when_most_of_its_frames_since_the_last_status_were() {
        assert!(!mostly_late(0, 0));
        assert!(!mostly_late(4, 10));
        assert!(!mostly_late(5, 10));
        assert!(mostly_late(6, 10));
        assert!(mostly_late(1, 1));
    }
}
