//! The node's task structure on tokio and rayon.
//!
//! * zenoh subscriber callbacks (zenoh's threads) map each sample's key to
//!   its topic, drop samples of other shards, and put a [`Frame`] into the
//!   topic's [`LatestSlot`] (creating the slot, and asking the manager for a
//!   stream task, for a new topic).
//! * One tokio task per stream waits on its slot, hands the newest frame and
//!   the stream's [`TopicProcessor`] to the rayon pool, awaits the result on
//!   a oneshot channel (tokio workers never block), and publishes the
//!   outputs. Streams therefore compute in parallel, up to the pool size.
//! * The manager task spawns stream tasks, publishes `/diagnostics` every
//!   `diagnostics_period_ms`, and evicts streams silent for
//!   `evict_after_ms` (their state is freed and they are reported STALE).
//! * On shutdown the slots are closed, in-flight frames get
//!   `shutdown_timeout_ms` to finish (then are abandoned), processors emit
//!   their final outputs (DELETEALL markers), a final `/diagnostics` is
//!   published, and all liveliness tokens are undeclared before the session
//!   closes.

use super::backend::{Backend, Frame, ObjectReport, OutputKind, StatusEntry, TopicProcessor};
use super::slot::LatestSlot;
use super::stats::{LatencyWindow, Level};
use super::{NodeConfig, NodeError};
use crate::transport::attachment::now_ns;
use crate::transport::keys::expand_topic_template;
use crate::transport::liveliness::{EntityKind, Qos};
use crate::transport::{Participant, Received, RosPublisher};
use std::collections::{BTreeMap, HashMap};
use std::future::Future;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
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
}

struct Stream {
    slot: Arc<LatestSlot<Frame>>,
    stats: Arc<Mutex<StreamStats>>,
    /// A frame of this stream is being processed (never evicted then).
    busy: AtomicBool,
}

/// Counters of samples that never reached a stream.
#[derive(Debug, Default)]
struct Ignored {
    foreign_keys: AtomicU64,
    other_shard: AtomicU64,
    over_capacity: AtomicU64,
    bad_attachments: AtomicU64,
}

struct Shared {
    streams: Mutex<HashMap<String, Arc<Stream>>>,
    new_tx: mpsc::Sender<String>,
    ignored: Ignored,
    cfg: NodeConfig,
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
}

/// What the node did, returned when it stops.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct NodeSummary {
    /// Per-stream figures, sorted by topic.
    pub streams: Vec<StreamSummary>,
    /// Samples whose key was not a topic of the key mode.
    pub foreign_keys: u64,
    /// Samples of streams owned by another shard.
    pub other_shard: u64,
    /// Samples refused because `max_streams` streams existed.
    pub over_capacity: u64,
    /// Samples with a malformed rmw_zenoh attachment (still processed).
    pub bad_attachments: u64,
    /// Whether every in-flight frame finished within the shutdown bound.
    pub clean_shutdown: bool,
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
    let participant = Arc::new(Participant::open(&cfg.transport).await?);
    tracing::info!(zid = participant.zid(), node = %cfg.transport.node_name, "node started");
    let (new_tx, mut new_rx) = mpsc::channel::<String>(cfg.max_streams.max(16));
    let shared = Arc::new(Shared {
        streams: Mutex::new(HashMap::new()),
        new_tx,
        ignored: Ignored::default(),
        cfg: cfg.clone(),
    });
    // No deadline: a day is as good as none, and keeps `Frame::deadline` an Instant.
    let deadline = backend
        .frame_deadline()
        .unwrap_or(Duration::from_secs(86_400));

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
    let frame = Frame {
        topic: topic.clone(),
        payload: r.payload,
        received_ns: r.received_ns,
        source_ns,
        sequence,
        deadline: Instant::now() + deadline,
    };
    // The map stays locked until the frame is in the slot: `evict` must
    // never see a new stream before its first frame (it would read "silent
    // since the epoch" and close the slot under the frame).
    let mut map = lock(&shared.streams);
    if let Some(s) = map.get(&topic) {
        s.slot.put(frame, r.received_ns);
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
    });
    if shared.new_tx.try_send(topic.clone()).is_err() {
        shared.ignored.over_capacity.fetch_add(1, Ordering::Relaxed);
        return;
    }
    s.slot.put(frame, r.received_ns);
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
    result: super::backend::FrameResult,
}

/// What a compute job hands back: the processor, and what it took (`None`
/// when the slot was empty by the time the job ran).
type Done = (Box<dyn TopicProcessor>, Option<Taken>);

/// One stream's worker; returns whether it stopped cleanly (no abandoned frame).
async fn stream_task(mut ctx: StreamCtx) -> bool {
    let topic = ctx.topic.clone();
    let tr = &ctx.cfg.transport;
    // Exact topics have had their MS token since start (see `run`).
    let token = if ctx.cfg.exact_topics().contains(&topic) {
        None
    } else {
        declare_stream_subscription(&ctx, &topic).await
    };
    let mut pubs: BTreeMap<OutputKind, RosPublisher> = BTreeMap::new();
    for kind in OutputKind::ALL {
        let Some(template) = ctx.cfg.outputs.template(kind) else {
            continue;
        };
        let out = expand_topic_template(template, &topic);
        let ty = tr.advertised(&ctx.backend.output_type(kind));
        match ctx
            .participant
            .publisher(&out, &ty, ctx.cfg.output_qos_of(kind))
            .await
        {
            Ok(p) => {
                pubs.insert(kind, p);
            }
            Err(e) => tracing::warn!(%topic, output = %out, error = %e, "cannot declare publisher"),
        }
    }
    let mut processor: Option<Box<dyn TopicProcessor>> = Some(ctx.backend.processor(&topic));
    let shutdown_bound = Duration::from_millis(ctx.cfg.shutdown_timeout_ms);
    let mut clean = true;
    loop {
        if ctx.stream.slot.has_pending() {
            let Some(mut p) = processor.take() else { break };
            ctx.stream.busy.store(true, Ordering::Release);
            let (tx, mut rx) = oneshot::channel::<Done>();
            // Late binding: the job takes the newest frame when a compute
            // thread is free, so a frame never ages in the pool's queue while
            // a newer one waits in the slot (that older one is then counted
            // as dropped, and the deadline is not spent waiting).
            let slot = ctx.stream.slot.clone();
            ctx.pool.spawn(move || {
                let Some(frame) = slot.take() else {
                    let _ = tx.send((p, None));
                    return;
                };
                let span = tracing::info_span!("frame", topic = %frame.topic, seq = ?frame.sequence);
                let _enter = span.enter();
                let result = p.process(&frame);
                tracing::debug!(objects = result.objects.len(), error = ?result.error, "frame done");
                let taken = Taken {
                    received_ns: frame.received_ns,
                    source_ns: frame.source_ns,
                    deadline: frame.deadline,
                    result,
                };
                let _ = tx.send((p, Some(taken)));
            });
            let stop = ctx.stop.clone();
            let done = tokio::select! {
                r = &mut rx => r.ok(),
                () = wait_stop(stop) => tokio::time::timeout(shutdown_bound, &mut rx).await.ok().and_then(Result::ok),
            };
            let Some((p, taken)) = done else {
                tracing::warn!(%topic, "in-flight frame abandoned at shutdown");
                clean = false;
                break;
            };
            processor = Some(p);
            let Some(Taken {
                received_ns,
                source_ns,
                deadline,
                result,
            }) = taken
            else {
                ctx.stream.busy.store(false, Ordering::Release);
                continue;
            };
            for out in result.outputs {
                if let Some(publ) = pubs.get(&out.kind) {
                    if let Err(e) = publ.put(out.payload).await {
                        tracing::warn!(%topic, error = %e, "publish failed");
                    }
                }
            }
            let now = now_ns();
            ctx.stream.slot.touch(now);
            ctx.stream.busy.store(false, Ordering::Release);
            let late = Instant::now() > deadline;
            let mut st = lock(&ctx.stream.stats);
            st.frames += 1;
            st.drops = ctx.stream.slot.dropped();
            st.received = ctx.stream.slot.received();
            st.latency.push((now - received_ns) as f64 * 1e-9);
            if let Some(s) = source_ns {
                st.e2e.push((now - s) as f64 * 1e-9);
            }
            if late {
                st.late += 1;
            }
            st.last_failed = result.error.is_some();
            if let Some(e) = result.error {
                tracing::warn!(%topic, error = %e, "frame failed");
                st.errors += 1;
                st.last_error = Some(e);
            }
            for o in result.objects {
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
        for out in p.on_evict() {
            if let Some(publ) = pubs.get(&out.kind) {
                let _ = publ.put(out.payload).await;
            }
        }
    }
    for (_, p) in pubs {
        if let Err(e) = p.undeclare().await {
            tracing::warn!(%topic, error = %e, "undeclaring publisher");
        }
    }
    if let Some(t) = token {
        if let Err(e) = t.undeclare().await {
            tracing::warn!(%topic, error = %e, "undeclaring subscription token");
        }
    }
    tracing::info!(%topic, "stream stopped");
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

async fn wait_stop(mut stop: watch::Receiver<bool>) {
    let _ = stop.wait_for(|v| *v).await;
}

fn evict(shared: &Shared, all: &mut BTreeMap<String, Arc<Mutex<StreamStats>>>) {
    let now = now_ns();
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
    // Forget streams that have been reported STALE for another period.
    all.retain(|_, st| lock(st).stale_since_ns.is_none_or(|t| now - t <= after));
}

fn statuses(
    shared: &Shared,
    all: &BTreeMap<String, Arc<Mutex<StreamStats>>>,
    last: bool,
) -> Vec<StatusEntry> {
    let node = &shared.cfg.transport.node_name;
    let hw = node.clone();
    let ms = |v: Option<f64>| v.map_or_else(|| "nan".to_string(), |s| format!("{:.3}", s * 1e3));
    let mut out = Vec::new();
    let live = lock(&shared.streams).len();
    let ig = &shared.ignored;
    out.push(StatusEntry {
        name: format!("{node}: node"),
        level: Level::Ok,
        message: if last {
            "shutting down".into()
        } else {
            "running".into()
        },
        hardware_id: hw.clone(),
        values: vec![
            ("streams".into(), live.to_string()),
            (
                "shard".into(),
                format!("{}/{}", shared.cfg.shard.index, shared.cfg.shard.count),
            ),
            (
                "foreign_keys".into(),
                ig.foreign_keys.load(Ordering::Relaxed).to_string(),
            ),
            (
                "other_shard".into(),
                ig.other_shard.load(Ordering::Relaxed).to_string(),
            ),
            (
                "over_capacity".into(),
                ig.over_capacity.load(Ordering::Relaxed).to_string(),
            ),
            (
                "bad_attachments".into(),
                ig.bad_attachments.load(Ordering::Relaxed).to_string(),
            ),
        ],
    });
    for (topic, st) in all {
        let mut st = lock(st);
        let new_drops = st.drops > st.reported_drops;
        let new_late = st.late > st.reported_late;
        st.reported_drops = st.drops;
        st.reported_late = st.late;
        let base_level = if st.stale_since_ns.is_some() {
            Level::Stale
        } else if st.last_failed {
            Level::Error
        } else if new_drops || new_late {
            Level::Warn
        } else {
            Level::Ok
        };
        let common = |v: &mut Vec<(String, String)>, st: &StreamStats| {
            v.push(("topic".into(), topic.clone()));
            v.push(("frames".into(), st.frames.to_string()));
            v.push(("drops".into(), st.drops.to_string()));
            v.push(("errors".into(), st.errors.to_string()));
            v.push(("late".into(), st.late.to_string()));
            v.push(("p50_ms".into(), ms(st.latency.quantile(0.5))));
            v.push(("p95_ms".into(), ms(st.latency.quantile(0.95))));
            v.push(("e2e_p95_ms".into(), ms(st.e2e.quantile(0.95))));
        };
        let stale_msg = "stream silent: evicted";
        if st.objects.is_empty() {
            let mut values = Vec::new();
            common(&mut values, &st);
            out.push(StatusEntry {
                name: format!("{node}: {topic}"),
                level: base_level,
                message: if base_level == Level::Stale {
                    stale_msg.into()
                } else {
                    st.last_error
                        .clone()
                        .unwrap_or_else(|| "no object yet".into())
                },
                hardware_id: hw.clone(),
                values,
            });
            continue;
        }
        for (name, o) in &st.objects {
            let mut values = vec![
                ("eta_g".into(), format!("{:.4}", o.last.eta_g)),
                ("iterations".into(), o.last.iterations.to_string()),
                ("warm".into(), o.warm.to_string()),
                ("cold".into(), o.cold.to_string()),
            ];
            common(&mut values, &st);
            let level = if base_level == Level::Stale {
                Level::Stale
            } else {
                base_level.max(o.last.level)
            };
            let message = match level {
                Level::Stale => stale_msg.to_string(),
                Level::Error => st.last_error.clone().unwrap_or_default(),
                _ if new_drops => format!("{}; dropping frames", o.last.message),
                _ => o.last.message.clone(),
            };
            out.push(StatusEntry {
                name: format!("{node}: {name}"),
                level,
                message,
                hardware_id: hw.clone(),
                values,
            });
        }
    }
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
            }
        })
        .collect();
    let ig = &shared.ignored;
    NodeSummary {
        streams,
        foreign_keys: ig.foreign_keys.load(Ordering::Relaxed),
        other_shard: ig.other_shard.load(Ordering::Relaxed),
        over_capacity: ig.over_capacity.load(Ordering::Relaxed),
        bad_attachments: ig.bad_attachments.load(Ordering::Relaxed),
        clean_shutdown: clean,
    }
}
