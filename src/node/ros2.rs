//! The node on a native ROS 2 stack through r2r (cargo feature `ros2`).
//!
//! The zenoh runtime ([`super::runtime`]) speaks rmw_zenoh's wire protocol
//! itself; this runner instead joins whatever RMW the sourced ROS 2 uses
//! (Fast DDS, Cyclone DDS, rmw_zenoh …) through `rcl`. It hosts the same
//! [`Backend`] and reuses the same CDR codecs: inputs arrive as serialized
//! messages from `Node::subscribe_raw`, outputs leave through
//! `PublisherUntyped::publish_raw`.
//!
//! ROS has no wildcard subscriptions, so the topic patterns of `node.topics`
//! are matched ([`super::topic_matches`]) against the graph every
//! `diagnostics_period_ms`, and matching PointCloud2 topics are subscribed.
//! Each stream has a keep-latest [`LatestSlot`]; frames are processed on the
//! rayon pool (one frame in flight per stream, streams in parallel) and the
//! outputs are published from there. `/diagnostics` carries one status per
//! stream. Sharding, eviction and the per-frame deadline behave as in the
//! zenoh runtime.
//!
//! Build: source a ROS 2 installation (`source /opt/ros/jazzy/setup.bash`),
//! then `cargo build --release --features ros2`. CI only type-checks this
//! module (`--features ros2,r2r/doc-only`, no ROS needed).

use super::backend::{Backend, Frame, Output, OutputKind, StatusEntry, TopicProcessor};
use super::clock::mono_ns;
use super::slot::LatestSlot;
use super::stats::{LatencyWindow, Level};
use super::{topic_matches, NodeConfig, NodeError};
use crate::transport::attachment::now_ns;
use crate::transport::keys::expand_topic_template;
use futures::executor::LocalPool;
use futures::task::LocalSpawnExt;
use futures::StreamExt;
use std::collections::{BTreeMap, HashMap};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    match m.lock() {
        Ok(g) => g,
        Err(p) => p.into_inner(),
    }
}

fn ros_err(e: r2r::Error) -> NodeError {
    NodeError::Ros(e.to_string())
}

#[derive(Default)]
struct Counters {
    frames: u64,
    errors: u64,
    late: u64,
    latency: LatencyWindow,
    last: Option<(String, f64, u32, bool, Level, String)>,
    last_error: Option<String>,
}

struct Stream {
    slot: LatestSlot<Frame>,
    busy: AtomicBool,
    processor: Mutex<Box<dyn TopicProcessor>>,
    counters: Mutex<Counters>,
    /// Outputs go back to the spinning thread (r2r publishers are not `Send`).
    outputs: crossbeam_channel::Sender<(String, Vec<Output>)>,
}

type Publishers = HashMap<String, BTreeMap<OutputKind, r2r::PublisherUntyped>>;

fn publish_outputs(pubs: &Publishers, topic: &str, outputs: &[Output]) {
    let Some(p) = pubs.get(topic) else { return };
    for out in outputs {
        if let Some(publ) = p.get(&out.kind) {
            if let Err(e) = publ.publish_raw(&out.payload) {
                tracing::warn!(%topic, error = %e, "publish failed");
            }
        }
    }
}

/// The diagnostics publisher's QoS: [`NodeConfig::output_qos`] as an r2r
/// profile.
fn output_qos(cfg: &NodeConfig) -> r2r::QosProfile {
    if cfg.output_qos().keep_last.is_none() {
        r2r::QosProfile::default().keep_all()
    } else {
        r2r::QosProfile::default()
    }
}

/// One output kind's QoS ([`NodeConfig::output_qos_of`]) as an r2r
/// profile. A transient-local output keeps KEEP_LAST of its cache depth
/// even with `outputs_keep_all`: the rmw sizes its cache by the history,
/// and a KEEP_ALL cache would grow without bound.
fn output_qos_of(cfg: &NodeConfig, kind: OutputKind) -> r2r::QosProfile {
    match cfg.output_cache_of(kind) {
        Some(depth) => r2r::QosProfile::default()
            .keep_last(usize::try_from(depth).unwrap_or(1))
            .transient_local(),
        None => output_qos(cfg),
    }
}

/// Process frames of `s` on the rayon pool until its slot is empty.
fn drain(s: &Arc<Stream>, pool: &Arc<rayon::ThreadPool>) {
    if s.busy.swap(true, Ordering::AcqRel) {
        return; // the running job will pick the newest frame up
    }
    let s = s.clone();
    let p = pool.clone();
    pool.spawn(move || {
        while let Some(frame) = s.slot.take() {
            let span = tracing::info_span!("frame", topic = %frame.topic, seq = ?frame.sequence);
            let _enter = span.enter();
            // Each output goes to the spinning thread as soon as it is made.
            let result = lock(&s.processor).process(&frame, &mut |out| {
                let _ = s.outputs.send((frame.topic.clone(), vec![out]));
            });
            let now = mono_ns();
            s.slot.touch(now);
            let mut c = lock(&s.counters);
            c.frames += 1;
            c.latency.push((now - frame.received_ns) as f64 * 1e-9);
            if Instant::now() > frame.deadline {
                c.late += 1;
            }
            if let Some(e) = result.error {
                c.errors += 1;
                c.last_error = Some(e);
            }
            if let Some(o) = result.objects.last() {
                c.last = Some((
                    o.stream.clone(),
                    o.eta_g,
                    o.iterations,
                    o.warm,
                    o.level,
                    o.message.clone(),
                ));
            }
        }
        s.busy.store(false, Ordering::Release);
        // A frame put between the last take and the store above.
        if s.slot.has_pending() {
            drain(&s, &p);
        }
    });
}

fn statuses(cfg: &NodeConfig, streams: &BTreeMap<String, Arc<Stream>>) -> Vec<StatusEntry> {
    let node = &cfg.transport.node_name;
    let ms = |v: Option<f64>| v.map_or_else(|| "nan".to_string(), |s| format!("{:.3}", s * 1e3));
    streams
        .iter()
        .map(|(topic, s)| {
            let c = lock(&s.counters);
            let (level, message, mut values) = match &c.last {
                Some((_, eta, it, warm, level, msg)) => (
                    *level,
                    msg.clone(),
                    vec![
                        ("eta_g".to_string(), format!("{eta:.4}")),
                        ("iterations".to_string(), it.to_string()),
                        ("warm".to_string(), warm.to_string()),
                    ],
                ),
                None => (
                    Level::Ok,
                    c.last_error
                        .clone()
                        .unwrap_or_else(|| "no object yet".into()),
                    Vec::new(),
                ),
            };
            values.extend([
                ("topic".to_string(), topic.clone()),
                ("frames".to_string(), c.frames.to_string()),
                ("drops".to_string(), s.slot.dropped().to_string()),
                ("errors".to_string(), c.errors.to_string()),
                ("late".to_string(), c.late.to_string()),
                ("p50_ms".to_string(), ms(c.latency.quantile(0.5))),
                ("p95_ms".to_string(), ms(c.latency.quantile(0.95))),
            ]);
            StatusEntry {
                name: format!("{node}: {topic}"),
                level,
                message,
                hardware_id: node.clone(),
                values,
            }
        })
        .collect()
}

/// Run the node on ROS 2 through r2r until `stop` is set (e.g. by a signal
/// handler). Returns the number of frames processed.
///
/// # Errors
/// [`NodeError`] for an invalid configuration or an rcl failure at start-up.
pub fn run(
    cfg: &NodeConfig,
    backend: Arc<dyn Backend>,
    stop: &AtomicBool,
) -> Result<u64, NodeError> {
    cfg.validate()?;
    let pool = cfg.compute_pool()?;
    let ctx = r2r::Context::create().map_err(ros_err)?;
    let namespace = if cfg.transport.namespace == "/" {
        ""
    } else {
        cfg.transport.namespace.as_str()
    };
    let mut node = r2r::Node::create(ctx, &cfg.transport.node_name, namespace).map_err(ros_err)?;
    let input_type = backend.input_type().name;
    let diag_pub = node
        .create_publisher_untyped(
            &expand_topic_template(&cfg.outputs.diagnostics, "/"),
            &backend.diagnostics_type().name,
            output_qos(cfg),
        )
        .map_err(ros_err)?;
    let deadline = backend
        .frame_deadline()
        .unwrap_or(Duration::from_secs(86_400));
    let period = Duration::from_millis(cfg.diagnostics_period_ms);
    let evict_after = i64::try_from(cfg.evict_after_ms).unwrap_or(i64::MAX / 2_000_000) * 1_000_000;
    let mut pool_local = LocalPool::new();
    let spawner = pool_local.spawner();
    let streams: Arc<Mutex<BTreeMap<String, Arc<Stream>>>> = Arc::default();
    let mut subscribed: HashMap<String, ()> = HashMap::new();
    let mut publishers: Publishers = HashMap::new();
    let (out_tx, out_rx) = crossbeam_channel::unbounded::<(String, Vec<Output>)>();
    let mut next_tick = Instant::now();
    while !stop.load(Ordering::Relaxed) {
        node.spin_once(Duration::from_millis(10));
        pool_local.run_until_stalled();
        while let Ok((topic, outs)) = out_rx.try_recv() {
            publish_outputs(&publishers, &topic, &outs);
        }
        if Instant::now() < next_tick {
            continue;
        }
        next_tick = Instant::now() + period;
        // Discover matching topics.
        let graph = node.get_topic_names_and_types().map_err(ros_err)?;
        for (topic, types) in graph {
            if subscribed.contains_key(&topic)
                || !types.contains(&input_type)
                || !cfg.topics.iter().any(|p| topic_matches(p, &topic))
                || cfg.outputs.is_output(&topic, &cfg.topics)
                || !cfg.shard.owns(&topic)
                || lock(&streams).len() >= cfg.max_streams
            {
                continue;
            }
            let mut pubs = BTreeMap::new();
            for kind in OutputKind::ALL {
                let Some(template) = cfg.outputs.template(kind) else {
                    continue;
                };
                if !backend.publishes(kind) {
                    continue;
                }
                let out = expand_topic_template(template, &topic);
                let p = node
                    .create_publisher_untyped(
                        &out,
                        &backend.output_type(kind).name,
                        output_qos_of(cfg, kind),
                    )
                    .map_err(ros_err)?;
                pubs.insert(kind, p);
            }
            publishers.insert(topic.clone(), pubs);
            let mut sub = node
                .subscribe_raw(&topic, &input_type, r2r::QosProfile::sensor_data())
                .map_err(ros_err)?;
            let stream = Arc::new(Stream {
                slot: LatestSlot::new(),
                busy: AtomicBool::new(false),
                processor: Mutex::new(backend.processor(&topic)),
                counters: Mutex::new(Counters::default()),
                outputs: out_tx.clone(),
            });
            lock(&streams).insert(topic.clone(), stream.clone());
            subscribed.insert(topic.clone(), ());
            tracing::info!(%topic, "subscribed");
            let pool = pool.clone();
            let t = topic.clone();
            spawner
                .spawn_local(async move {
                    while let Some(bytes) = sub.next().await {
                        let received_ns = mono_ns();
                        let frame = Frame {
                            topic: t.clone(),
                            payload: bytes,
                            received_ns,
                            source_ns: None,
                            sequence: None,
                            deadline: Instant::now() + deadline,
                        };
                        if !stream.slot.put(frame, received_ns) {
                            break;
                        }
                        drain(&stream, &pool);
                    }
                })
                .map_err(|e| NodeError::Ros(e.to_string()))?;
        }
        // Evict silent streams (their subscription task ends with the slot).
        let now = mono_ns();
        let mut map = lock(&streams);
        map.retain(|topic, s| {
            let silent = s.slot.received() > 0
                && !s.busy.load(Ordering::Acquire)
                && now - s.slot.last_seen_ns() > evict_after;
            if silent {
                tracing::info!(%topic, "evicting silent stream");
                s.slot.close();
                let outs = lock(&s.processor).on_evict();
                publish_outputs(&publishers, topic, &outs);
            }
            !silent
        });
        let status = statuses(cfg, &map);
        drop(map);
        let bytes = backend.encode_diagnostics(now, "", &status);
        if let Err(e) = diag_pub.publish_raw(&bytes) {
            tracing::warn!(error = %e, "publishing /diagnostics");
        }
    }
    // Shutdown: close the slots, let in-flight frames finish within the bound.
    let map = std::mem::take(&mut *lock(&streams));
    for s in map.values() {
        s.slot.close();
    }
    let until = Instant::now() + Duration::from_millis(cfg.shutdown_timeout_ms);
    while map.values().any(|s| s.busy.load(Ordering::Acquire)) && Instant::now() < until {
        std::thread::sleep(Duration::from_millis(10));
    }
    while let Ok((topic, outs)) = out_rx.try_recv() {
        publish_outputs(&publishers, &topic, &outs);
    }
    let mut frames = 0;
    for (topic, s) in &map {
        let outs = lock(&s.processor).on_evict();
        publish_outputs(&publishers, topic, &outs);
        frames += lock(&s.counters).frames;
    }
    let status = statuses(cfg, &map);
    let _ = diag_pub.publish_raw(&backend.encode_diagnostics(now_ns(), "", &status));
    node.spin_once(Duration::from_millis(10));
    Ok(frames)
}
