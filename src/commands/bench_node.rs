//! `sepmem bench-node`: the live node under a synthetic load, in one process
//! over zenoh loopback. N object streams publish PointCloud2 at R Hz with P
//! points each (a moving, slightly noisy ellipsoid surface per stream, at a
//! different size per stream) for a duration; an observer receives the
//! meshes. It reports publish→mesh-receipt latency percentiles (the cloud's
//! header stamp is its publish time, same clock), frames, drops, the share
//! of each stream's frames meshed and the process's resident memory over
//! time.
//!
//! `--hostile` is the soak: the hostile streams of [`super::soak`]
//! (poisoned clouds, a label bomb, label churn, oversized payloads,
//! malformed CDR) publish next to the healthy ones, an observer watches
//! `/diagnostics`, and the run fails unless every hostile stream was
//! counted there under its own reason and the node stopped without a panic.
//! Resident memory is the whole process's: node, observer and publishers.

use super::soak;
use anyhow::{bail, Context, Result};
use clap::Args;
use hdrhistogram::Histogram;
use sepmem::cloud::PointCloud;
use sepmem::config::Config;
use sepmem::node::loopback::LoopbackNode;
use sepmem::node::runtime::NodeSummary;
use sepmem::node::Backend;
use sepmem::transport::attachment::now_ns;
use sepmem::transport::liveliness::Qos;
use sepmem::transport::RosType;
use sepmem::wire::msgs::{Header, PointCloud2, SurfaceMesh, Time};
use sepmem::wire::pointcloud2::encode_pointcloud2;
use sepmem::wire::{self, RosMessage};
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// Arguments of `sepmem bench-node`.
#[derive(Args, Debug)]
pub struct BenchNodeArgs {
    /// Concurrent object streams.
    #[arg(long, default_value_t = 4)]
    pub streams: usize,
    /// Publication rate per stream (Hz).
    #[arg(long, default_value_t = 30.0)]
    pub rate: f64,
    /// Points per cloud.
    #[arg(long, default_value_t = 20_000)]
    pub points: usize,
    /// Loop the clouds of this rosbag2 bag (its first PointCloud2 topic, e.g.
    /// a `sepmem synth` turning sequence) on every stream instead of the
    /// synthetic ellipsoids (`--points` is then ignored): a looped replay
    /// through the live node, for its memory over time.
    #[arg(long)]
    pub bag: Option<PathBuf>,
    /// Duration of the measurement (s).
    #[arg(long, default_value_t = 120.0)]
    pub duration: f64,
    /// Warm-up excluded from the latency figures (s).
    #[arg(long, default_value_t = 3.0)]
    pub warmup: f64,
    /// Resident-memory sampling period (s).
    #[arg(long, default_value_t = 10.0)]
    pub rss_every: f64,
    /// Publish the hostile streams too (the soak); `wire.max_bytes` is 8 MiB
    /// unless set.
    #[arg(long)]
    pub hostile: bool,
    /// Write the figures as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Configuration file (.json5 or .toml) holding the keys to change.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Override one parameter: section.key=value (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub set: Vec<String>,
}

/// Resident set size of this process in MiB (Linux; `None` elsewhere).
fn rss_mib() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmRSS:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}

/// Bytes the heap holds in live allocations and in all (MiB), from
/// glibc's `mallinfo2`: with the RSS they tell a leak (in use grows) from
/// fragmentation (only the RSS grows).
#[cfg(all(target_os = "linux", target_env = "gnu"))]
#[allow(unsafe_code)]
fn heap_mib() -> Option<(f64, f64)> {
    // SAFETY: mallinfo2 only reads the allocator's statistics.
    let m = unsafe { libc::mallinfo2() };
    let mib = |b: usize| b as f64 / (1024.0 * 1024.0);
    Some((mib(m.uordblks + m.hblkhd), mib(m.arena + m.hblkhd)))
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn heap_mib() -> Option<(f64, f64)> {
    None
}

/// The machine's CPU time and the part of it the hypervisor stole, in
/// jiffies (Linux `/proc/stat`; `None` elsewhere). On a shared VM the same
/// 30 s healthy-only run meshed 95-98 % of the frames at 5 % steal and
/// 70-75 % at 29 % (this machine, 2026-12-03): the steal share says which
/// run is which.
fn cpu_jiffies() -> Option<[u64; 2]> {
    let s = std::fs::read_to_string("/proc/stat").ok()?;
    let v: Vec<u64> = s
        .lines()
        .next()?
        .split_whitespace()
        .skip(1)
        .filter_map(|x| x.parse().ok())
        .collect();
    // user nice system idle iowait irq softirq steal
    Some([v.iter().take(8).sum(), *v.get(7)?])
}

/// The share (%) of the machine's CPU time stolen between two readings.
fn steal_percent(from: Option<[u64; 2]>, to: Option<[u64; 2]>) -> Option<f64> {
    let ([t0, s0], [t1, s1]) = (from?, to?);
    (t1 > t0).then(|| 100.0 * s1.saturating_sub(s0) as f64 / (t1 - t0) as f64)
}

/// Pre-encoded frames of one stream ([`sepmem::bench::clouds::moving_ellipsoid`]);
/// the stamp is patched at publish time.
fn stream_frames(index: usize, points: usize, frames: usize) -> Result<Vec<Vec<u8>>> {
    let header = Header {
        stamp: Time::from_nanos(0),
        frame_id: "bench".into(),
    };
    let encode = |c: &PointCloud| wire::encode(&encode_pointcloud2(c, header.clone()));
    let clouds = sepmem::bench::clouds::moving_ellipsoid(index, points, frames)?;
    Ok(clouds.iter().map(encode).collect::<Result<_, _>>()?)
}

/// The clouds of `bag`'s first PointCloud2 topic, in order.
fn bag_frames(bag: &std::path::Path) -> Result<Vec<Vec<u8>>> {
    let b =
        sepmem::bag::Bag::open(bag).with_context(|| format!("opening bag {}", bag.display()))?;
    let Some(topic) = b
        .topics
        .iter()
        .find(|t| t.type_name == PointCloud2::TYPE_NAME)
    else {
        bail!("no {} topic in {}", PointCloud2::TYPE_NAME, bag.display());
    };
    let frames: Vec<Vec<u8>> = b
        .read(&[topic.name.as_str()])?
        .into_iter()
        .map(|m| m.data)
        .collect();
    if frames.is_empty() {
        bail!("no clouds on {} in {}", topic.name, bag.display());
    }
    Ok(frames)
}

/// Each stream's looped clouds: the bag's (`--bag`), or 30 synthetic
/// ellipsoids of `--points` points per stream.
fn stream_payloads(args: &BenchNodeArgs) -> Result<Vec<Vec<Vec<u8>>>> {
    if let Some(bag) = &args.bag {
        let frames = bag_frames(bag)?;
        eprintln!(
            "looping {} clouds of {} on {} streams …",
            frames.len(),
            bag.display(),
            args.streams
        );
        return Ok(vec![frames; args.streams]);
    }
    let frames_per_stream = 30;
    eprintln!(
        "encoding {} × {frames_per_stream} clouds of {} points …",
        args.streams, args.points
    );
    (0..args.streams)
        .map(|s| stream_frames(s, args.points, frames_per_stream))
        .collect()
}

/// The stamp of a CDR message whose first field is a `std_msgs/Header`.
fn stamp_of(cdr: &[u8]) -> Option<i64> {
    let sec = i32::from_le_bytes(cdr.get(4..8)?.try_into().ok()?);
    let nsec = u32::from_le_bytes(cdr.get(8..12)?.try_into().ok()?);
    Some(i64::from(sec) * 1_000_000_000 + i64::from(nsec))
}

fn set_stamp(cdr: &mut [u8], ns: i64) {
    let t = Time::from_nanos(ns);
    cdr[4..8].copy_from_slice(&t.sec.to_le_bytes());
    cdr[8..12].copy_from_slice(&t.nanosec.to_le_bytes());
}

/// What the observer saw, in memory that does not grow with the run's
/// length (the soak's resident-memory figure is the whole process's, so a
/// per-mesh record here would read as a leak of the node).
#[derive(Clone)]
struct Receipts {
    /// The measurement window of the healthy streams' frames (stamp ns).
    window: (i64, i64),
    /// Healthy streams.
    streams: usize,
    /// Meshes received, all streams.
    total: u64,
    /// Per healthy stream: meshes of frames stamped in the window, and how
    /// many of them fitted.
    meshed: Vec<(u64, u64)>,
    /// Publish→receipt latency (µs) of the healthy streams' meshes
    /// received in the window.
    latency_us: Histogram<u64>,
    /// Meshes received in the window (all streams): count, membrane
    /// iterations summed, and how many had none.
    iterations: (u64, u64, u64),
    /// Per mesh topic, the attachment sequence numbers seen: the node
    /// numbers each publisher's samples from 1, so the gaps are the meshes
    /// the transport dropped (zenoh drops under congestion, silently).
    sequences: BTreeMap<String, Sequences>,
    /// Since the last memory sample, healthy meshes: count, control-grid
    /// cells (M·L) and vertices summed — surfaces that grow over the run
    /// hold more memory in the node's caches and outputs.
    sizes: (u64, u64, u64),
}

impl Receipts {
    fn new(streams: usize) -> Result<Self> {
        Ok(Self {
            window: (i64::MAX, i64::MAX),
            streams,
            total: 0,
            meshed: vec![(0, 0); streams],
            latency_us: Histogram::new_with_bounds(1, 3_600_000_000, 3)
                .context("latency histogram")?,
            iterations: (0, 0, 0),
            sequences: BTreeMap::new(),
            sizes: (0, 0, 0),
        })
    }

    /// One mesh of stream `idx` (usize::MAX: not a healthy stream).
    fn see(&mut self, received_ns: i64, stamp: i64, idx: usize, msg: Option<&SurfaceMesh>) {
        self.total += 1;
        let (from, end) = self.window;
        if received_ns >= from {
            if let Some(m) = msg {
                let it = &mut self.iterations;
                *it = (
                    it.0 + 1,
                    it.1 + u64::from(m.iterations),
                    it.2 + u64::from(m.iterations == 0),
                );
            }
            if let (Some(m), true) = (msg, idx < self.streams) {
                let z = &mut self.sizes;
                *z = (
                    z.0 + 1,
                    z.1 + u64::from(m.grid_m) * u64::from(m.grid_l),
                    z.2 + m.vertices.len() as u64,
                );
            }
            if idx < self.streams {
                let us = u64::try_from((received_ns - stamp) / 1000)
                    .unwrap_or(0)
                    .max(1);
                self.latency_us.saturating_record(us);
            }
        }
        if let Some(c) = self.meshed.get_mut(idx) {
            if stamp >= from && stamp < end {
                let fitted = msg.is_some_and(|m| m.quality == SurfaceMesh::FITTED);
                *c = (c.0 + 1, c.1 + u64::from(fitted));
            }
        }
    }

    /// A latency quantile in ms (NaN with no mesh).
    fn latency_ms(&self, q: f64) -> f64 {
        if self.latency_us.is_empty() {
            return f64::NAN;
        }
        self.latency_us.value_at_quantile(q) as f64 * 1e-3
    }
}

/// The sequence numbers received on one topic.
#[derive(Debug, Clone, Copy, Default)]
struct Sequences {
    first: i64,
    last: i64,
    received: u64,
}

impl Sequences {
    fn see(&mut self, seq: i64) {
        if self.received == 0 {
            (self.first, self.last) = (seq, seq);
        }
        self.first = self.first.min(seq);
        self.last = self.last.max(seq);
        self.received += 1;
    }

    /// Sequence numbers between the first and the last that never arrived.
    fn lost(&self) -> u64 {
        u64::try_from(self.last - self.first + 1)
            .unwrap_or(0)
            .saturating_sub(self.received)
    }
}

/// What the hostile streams are made from.
struct Setup {
    max_bytes: usize,
    limit: usize,
    healthy: Vec<u8>,
}

/// Run the benchmark.
pub fn run(args: &BenchNodeArgs) -> Result<()> {
    if args.streams == 0 || args.rate <= 0.0 || args.points < 100 || args.duration <= 0.0 {
        bail!("need --streams ≥ 1, --rate > 0, --points ≥ 100, --duration > 0");
    }
    let mut sets = args.set.clone();
    if args.hostile && !sets.iter().any(|s| s.starts_with("wire.max_bytes")) {
        sets.push("wire.max_bytes=8388608".into());
    }
    let cfg = Config::load(args.config.as_deref(), &sets)?;
    let mut node_cfg = cfg.node.clone();
    node_cfg.topics = vec!["/bench/**".into()];
    node_cfg.transport.node_name = "sepmem_bench".into();
    let payloads = stream_payloads(args)?;
    let backend = Arc::new(cfg.pipeline_backend()?);
    let hostile = args.hostile.then(|| Setup {
        max_bytes: cfg.wire.max_bytes,
        limit: backend.max_message_bytes().unwrap_or(cfg.wire.max_bytes),
        healthy: payloads[0][0].clone(),
    });
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("starting tokio")?;
    let args_rate = args.rate;
    rt.block_on(async move {
        let node = LoopbackNode::start(&node_cfg, backend).await?;
        let diag = soak::watch_diagnostics(&node, &node_cfg.outputs.diagnostics).await?;
        let receipts = Arc::new(Mutex::new(Receipts::new(args.streams)?));
        let r2 = receipts.clone();
        let _sub = node
            .harness
            .subscribe(
                "/bench/**",
                &RosType::new(SurfaceMesh::TYPE_NAME, SurfaceMesh::TYPE_HASH),
                move |s| {
                    let (Some(stamp), Ok(topic)) = (stamp_of(&s.payload), &s.topic) else {
                        return;
                    };
                    let idx = topic
                        .trim_start_matches("/bench/s")
                        .split('/')
                        .next()
                        .and_then(|n| n.parse::<usize>().ok())
                        .unwrap_or(usize::MAX);
                    let msg = wire::decode::<SurfaceMesh>(&s.payload).ok();
                    if let Ok(mut r) = r2.lock() {
                        if let Some(Ok(a)) = &s.attachment {
                            r.sequences.entry(topic.clone()).or_default().see(a.sequence);
                        }
                        r.see(s.received_ns, stamp, idx, msg.as_ref());
                    }
                },
            )
            .await?;
        if !node.wait_ready(Duration::from_secs(30)).await {
            bail!("the node did not come up on loopback");
        }
        let mut pubs = Vec::new();
        for s in 0..args.streams {
            pubs.push(
                node.harness
                    .publisher(
                        &format!("/bench/s{s}/points"),
                        &RosType::new(PointCloud2::TYPE_NAME, PointCloud2::TYPE_HASH),
                        Qos::SENSOR_DATA,
                    )
                    .await?,
            );
        }
        tokio::time::sleep(Duration::from_millis(300)).await;
        println!(
            "bench-node: {} streams × {} Hz × {} for {} s (warm-up {} s), deadline {} ms, compute threads {}",
            args.streams,
            args_rate,
            args.bag.as_ref().map_or_else(
                || format!("{} points", args.points),
                |b| format!("the clouds of {}", b.display())
            ),
            args.duration,
            args.warmup,
            cfg.pipeline.deadline_ms,
            if node_cfg.compute_threads == 0 {
                std::thread::available_parallelism().map_or(1, std::num::NonZero::get)
            } else {
                node_cfg.compute_threads
            }
        );
        let t0 = now_ns();
        let cpu0 = cpu_jiffies();
        let end = t0 + (args.duration * 1e9) as i64;
        let measure_from = t0 + (args.warmup * 1e9) as i64;
        let window = (measure_from, end);
        if let Ok(mut r) = receipts.lock() {
            r.window = window;
        }
        let published: Arc<Vec<AtomicU64>> =
            Arc::new((0..args.streams).map(|_| AtomicU64::new(0)).collect());
        let mut tasks = Vec::new();
        for (s, (p, frames)) in pubs.into_iter().zip(payloads).enumerate() {
            let published = published.clone();
            let n_streams = args.streams;
            tasks.push(tokio::spawn(async move {
                let period = Duration::from_secs_f64(1.0 / args_rate);
                // Stagger the streams over one period.
                tokio::time::sleep(period.mul_f64(s as f64 / n_streams as f64)).await;
                let mut tick = tokio::time::interval(period);
                tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
                let mut k = 0usize;
                while now_ns() < end {
                    tick.tick().await;
                    let mut bytes = frames[k % frames.len()].clone();
                    let stamp = now_ns();
                    set_stamp(&mut bytes, stamp);
                    if p.put(bytes).await.is_ok() && stamp >= measure_from {
                        published[s].fetch_add(1, Ordering::Relaxed);
                    }
                    k += 1;
                }
                p
            }));
        }
        let hostile_tasks = match &hostile {
            Some(h) => soak::spawn(&node, soak::streams(h.max_bytes, h.limit, h.healthy.clone())?, end).await?,
            None => Vec::new(),
        };
        let rss = sample_rss(t0, end, args.rss_every, &receipts, &diag.1).await;
        let steal = steal_percent(cpu0, cpu_jiffies());
        let mut pubs = Vec::new();
        for t in tasks {
            pubs.push(t.await?);
        }
        let mut sent = BTreeMap::new();
        for (name, t) in hostile_tasks {
            let (p, n) = t.await?;
            sent.insert(name, n);
            pubs.push(p);
        }
        tokio::time::sleep(Duration::from_millis(1500)).await;
        for p in pubs {
            p.undeclare().await?;
        }
        let summary = node.stop().await?;
        let seen = diag.1.lock().map(|d| d.clone()).unwrap_or_default();
        let r = receipts.lock().map_err(|_| anyhow::anyhow!("the observer panicked"))?.clone();
        let published: Vec<u64> = published.iter().map(|p| p.load(Ordering::Relaxed)).collect();
        let mut figures = report(args, &cfg, &summary, &r, &published, &rss);
        match steal {
            Some(p) => println!(
                "CPU stolen by the hypervisor during the run: {p:.1} % of the machine's time (compare runs only at similar steal)"
            ),
            None => println!("CPU steal: unknown (no /proc/stat)"),
        }
        figures["steal_percent"] = serde_json::json!(steal);
        figures["model_bytes_max"] = serde_json::json!(seen.model_bytes_max);
        let [ok, warn, error, stale] = seen.healthy_levels;
        println!(
            "/diagnostics statuses of the healthy streams' objects: OK {ok}, WARN {warn}, ERROR {error}, STALE {stale}"
        );
        figures["healthy_levels"] = serde_json::json!({"ok": ok, "warn": warn, "error": error, "stale": stale});
        if seen.model_bytes_max > 0 {
            println!(
                "fused model: largest one object's {:.1} KiB (cap {:.1} KiB)",
                seen.model_bytes_max as f64 / 1024.0,
                cfg.pipeline.model.as_ref().map_or(0.0, |m| m.max_bytes() as f64 / 1024.0)
            );
        }
        let verdict = hostile.is_some().then(|| hostile_verdict(&seen, &sent));
        if let Some(path) = &args.json {
            let mut j = figures;
            if let Some((v, _)) = &verdict {
                j["hostile"] = v.clone();
            }
            std::fs::write(path, serde_json::to_string_pretty(&j)?)
                .with_context(|| format!("writing {}", path.display()))?;
        }
        if let Some((_, Err(e))) = verdict {
            bail!("{e}");
        }
        anyhow::Ok(())
    })
}

/// Sample the process's resident memory every `every_s` until `end`.
async fn sample_rss(
    t0: i64,
    end: i64,
    every_s: f64,
    receipts: &Mutex<Receipts>,
    diag: &Mutex<soak::DiagSeen>,
) -> Vec<(f64, f64)> {
    let mut rss = vec![(0.0, rss_mib().unwrap_or(f64::NAN))];
    let every = Duration::from_secs_f64(every_s.max(0.5));
    let mut cpu = cpu_jiffies();
    while now_ns() < end {
        tokio::time::sleep(every.min(Duration::from_nanos(
            u64::try_from(end - now_ns()).unwrap_or(0).max(1),
        )))
        .await;
        let t = (now_ns() - t0) as f64 * 1e-9;
        let m = rss_mib().unwrap_or(f64::NAN);
        let (n, (k, cells, verts)) = receipts
            .lock()
            .map(|mut r| (r.total, std::mem::take(&mut r.sizes)))
            .unwrap_or_default();
        let per = |x: u64| x as f64 / k.max(1) as f64;
        let now_cpu = cpu_jiffies();
        let steal =
            steal_percent(cpu, now_cpu).map_or_else(String::new, |p| format!("  steal {p:4.1} %"));
        cpu = now_cpu;
        let heap = heap_mib().map_or_else(String::new, |(used, all)| {
            format!("  heap in use {used:7.1} of {all:7.1} MiB")
        });
        let model = diag.lock().map(|d| d.model_bytes_now).unwrap_or_default();
        let model = if model > 0 {
            format!("  fused models {:.1} KiB", model as f64 / 1024.0)
        } else {
            String::new()
        };
        println!(
            "  t={t:6.1} s  rss {m:7.1} MiB{heap}{model}  meshes received {n}  healthy grid cells {:.0}, vertices {:.0}{steal}",
            per(cells),
            per(verts)
        );
        rss.push((t, m));
    }
    rss
}

/// Per healthy stream: frames published in the measurement window and the
/// share of them whose mesh was received (any quality) and fitted.
fn meshed_shares(r: &Receipts, published: &[u64]) -> Vec<serde_json::Value> {
    published
        .iter()
        .zip(&r.meshed)
        .enumerate()
        .map(|(i, (&n, &(all, fitted)))| {
            let share = |k: u64| k as f64 / n.max(1) as f64;
            serde_json::json!({"stream": i, "published": n, "meshed": share(all), "fitted": share(fitted)})
        })
        .collect()
}

/// Print the figures; return them as JSON.
fn report(
    args: &BenchNodeArgs,
    cfg: &Config,
    summary: &NodeSummary,
    r: &Receipts,
    published: &[u64],
    rss: &[(f64, f64)],
) -> serde_json::Value {
    // Membrane iterations per mesh after warm-up: how much of the
    // per-frame budget went into evolving rather than fixed costs.
    let (n_it, sum_it, zero_it) = r.iterations;
    let it_mean = sum_it as f64 / n_it.max(1) as f64;
    let it_zero = 100.0 * zero_it as f64 / n_it.max(1) as f64;
    let n_lat = r.latency_us.len();
    let total: u64 = published.iter().sum();
    let frames: u64 = summary.streams.iter().map(|s| s.frames).sum();
    let drops: u64 = summary.streams.iter().map(|s| s.drops).sum();
    let late: u64 = summary.streams.iter().map(|s| s.late).sum();
    let received: u64 = summary.streams.iter().map(|s| s.received).sum();
    println!(
        "\n{:<32} {:>9} {:>7} {:>7} {:>6} {:>6} {:>6} {:>8} {:>8}",
        "stream", "received", "frames", "drops", "late", "warm", "cold", "p50 ms", "p95 ms"
    );
    let ms = |v: Option<f64>| v.map_or_else(|| "-".to_string(), |x| format!("{:.1}", x * 1e3));
    for s in &summary.streams {
        println!(
            "{:<32} {:>9} {:>7} {:>7} {:>6} {:>6} {:>6} {:>8} {:>8}",
            s.topic,
            s.received,
            s.frames,
            s.drops,
            s.late,
            s.warm,
            s.cold,
            ms(s.p50_s),
            ms(s.p95_s)
        );
    }
    let shares = meshed_shares(r, published);
    for s in &shares {
        println!(
            "healthy stream {}: published {} after warm-up, meshed {:.1} %, fitted {:.1} %",
            s["stream"],
            s["published"],
            100.0 * s["meshed"].as_f64().unwrap_or(0.0),
            100.0 * s["fitted"].as_f64().unwrap_or(0.0)
        );
    }
    let rss_at = |t: f64| {
        rss.iter()
            .min_by(|a, b| (a.0 - t).abs().total_cmp(&(b.0 - t).abs()))
            .map_or(f64::NAN, |x| x.1)
    };
    let ref_t = 300f64.min(args.duration / 2.0);
    let (rss_ref, rss_last) = (rss_at(ref_t), rss.last().map_or(f64::NAN, |x| x.1));
    let rss_max = rss.iter().map(|x| x.1).fold(f64::NAN, f64::max);
    let (p50, p95, p99) = (r.latency_ms(0.5), r.latency_ms(0.95), r.latency_ms(0.99));
    let mesh_rate = n_lat as f64 / (args.duration - args.warmup).max(1e-9);
    println!(
        "\nsummary: published (healthy, after warm-up) {total}, received by the node {received}, processed {frames}, dropped (keep-latest) {drops} ({:.1} %), late {late}; healthy meshes after warm-up {} ({mesh_rate:.1}/s)",
        100.0 * drops as f64 / received.max(1) as f64,
        n_lat
    );
    println!(
        "publish→mesh-receipt latency ms (healthy, after warm-up, {} meshes): p50 {p50:.1} p95 {p95:.1} p99 {p99:.1} max {:.1}",
        n_lat,
        r.latency_ms(1.0)
    );
    println!(
        "membrane iterations per mesh (after warm-up): mean {it_mean:.2}, none {it_zero:.1} %"
    );
    println!(
        "resident memory MiB: start {:.1}, at {ref_t:.0} s {rss_ref:.1}, end {rss_last:.1} ({:+.1} %), max {rss_max:.1}",
        rss[0].1,
        100.0 * (rss_last / rss_ref - 1.0)
    );
    println!("reasons (all streams): {:?}", summary.reasons);
    let (lost, seen) = r
        .sequences
        .values()
        .fold((0, 0), |(l, n), q| (l + q.lost(), n + q.received));
    println!(
        "output meshes lost in transport (sequence gaps, all streams): {lost} of {}",
        lost + seen
    );
    serde_json::json!({
        "meshes_lost_in_transport": lost,
        "streams": args.streams, "rate_hz": args.rate, "points": args.points,
        "duration_s": args.duration, "warmup_s": args.warmup,
        "deadline_ms": cfg.pipeline.deadline_ms,
        "published": total, "received": received, "processed": frames,
        "drops": drops, "late": late, "meshes": n_lat,
        "latency_ms": {"p50": p50, "p95": p95, "p99": p99, "n": n_lat},
        "healthy": shares,
        "iterations_per_mesh": {"mean": it_mean, "none_percent": it_zero},
        "rss_mib": rss.iter().map(|(t, m)| serde_json::json!([t, m])).collect::<Vec<_>>(),
        "rss_ref": {"t_s": ref_t, "mib": rss_ref}, "rss_end_mib": rss_last,
        "reasons": summary.reasons,
        "input_streams": summary.streams.len(), "own_outputs": summary.own_outputs,
        "clean_shutdown": summary.clean_shutdown,
    })
}

/// Whether every hostile stream was counted in `/diagnostics` under its own
/// reason (the node status's totals), as JSON and as a pass/fail.
fn hostile_verdict(
    seen: &soak::DiagSeen,
    sent: &BTreeMap<&'static str, u64>,
) -> (serde_json::Value, Result<(), String>) {
    let count = |r: &str| {
        seen.node_values
            .get(r)
            .and_then(|v| v.parse::<u64>().ok())
            .unwrap_or(0)
    };
    let mut missing = Vec::new();
    let mut kinds = serde_json::Map::new();
    for (name, reason) in soak::KINDS {
        let worst = seen.worst.get(&soak::topic(name));
        // A frame that never finishes (a decoder defect) cannot be counted
        // under its reason; the stall guard reports it ERROR "stalled".
        let stalled = worst.is_some_and(|(l, m)| *l == 2 && m.starts_with("stalled"));
        let n = count(reason);
        println!(
            "hostile {name:<10} sent {:>6}  counted under {reason} {n:>7}  worst /diagnostics level {}",
            sent.get(name).copied().unwrap_or(0),
            worst.map_or_else(|| "-".to_string(), |(l, m)| format!("{l} ({m})"))
        );
        if n == 0 && !stalled {
            missing.push(format!("{name} (no {reason})"));
        }
        kinds.insert(name.to_string(), serde_json::json!({"sent": sent.get(name), "reason": reason, "count": n, "stalled": stalled, "worst": worst}));
    }
    println!(
        "/diagnostics: {} arrays, largest {} bytes, most statuses {}; node values {:?}",
        seen.arrays, seen.max_bytes, seen.max_statuses, seen.node_values
    );
    let j = serde_json::json!({
        "kinds": kinds, "diagnostics_arrays": seen.arrays,
        "diagnostics_max_bytes": seen.max_bytes, "diagnostics_max_statuses": seen.max_statuses,
        "node_values": seen.node_values,
    });
    let ok = if !missing.is_empty() {
        Err(format!(
            "hostile streams not counted in /diagnostics: {}",
            missing.join(", ")
        ))
    } else if seen.arrays == 0 {
        Err("no /diagnostics array was received".into())
    } else {
        Ok(())
    };
    (j, ok)
}
