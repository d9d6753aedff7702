//! `sepmem replay`: run the frame pipeline over every PointCloud2 of a bag,
//! deterministically, with no network, as fast as possible.
//!
//! Deterministic means no wall-clock deadline: each frame runs until its
//! iteration cap or convergence, so the same bag and configuration give
//! the same meshes and scores on any machine, at any load. `--realtime`
//! applies the node's per-frame deadlines instead (`pipeline.deadline_ms`,
//! `cold_deadline_ms`), to see what a loaded node would publish. The
//! latency summary is measured either way. Without a deadline a frame
//! waits for its stream's background rebuild (`pipeline.rebuild`), which
//! the node's frames never do; the summary gives the warm frames' latency
//! with and without those waits.
//!
//! When the bag carries ground truth (`sepmem_msgs/msg/GroundTruth`, as
//! written by `sepmem synth`), every frame of every stream is scored against
//! the posed ground-truth mesh ([`sepmem::eval`]): F-score,
//! Chamfer-L1, precision against the full surface, recall on the part the
//! camera saw, the closure of the unseen side (`depth`: extent along the
//! viewing ray) and `vol`, the mesh's volume over the true solid's; the
//! summary gives per-stream means and minima. The robot's-view scores of
//! [`sepmem::eval::view`] follow at the end of each row (`seen` side depth
//! accuracy, `rim`: the same on the silhouette's rim alone,
//! volume `IoU` with the true solid, `rot` (°) and
//! `tr_mm` error of the tracked pose, `adds`: that error as the true
//! surface sees it (ADD-S, mm; 0 for a turn about an axis of symmetry),
//! `cover`: share of the true surface
//! seen so far, `out3s`: share of the points on the true surface that lie
//! outside the mesh by more than 3σ of the sensor noise, `excess`: the
//! mesh's projection beyond the true silhouette, as a share of the
//! silhouette, `pastex`: the largest such share in up to 8 of the stream's
//! earlier views, the object at its true pose there), and a `view` line
//! per stream gives them, with F, over the first and the last third of the
//! frames, and the points left out over all frames.
//!
//! `--compare-cold` also reconstructs every frame from a cold start (no
//! deadline, the cold iteration cap) outside the timed pipeline, and reports
//! per warm frame ΔF = F_cold − F_warm and the ratio of warm to cold
//! iterations: the acceptance check (ΔF ≤ 0.01 with at most a
//! quarter of the cold iterations). `--cold-repeats N` makes `F_cold` the
//! mean of `N` cold starts on different thinning subsets of the frame and
//! reports how often one cold start reaches the others' mean within 0.01:
//! on a single view a cold start's F-score moves by about ±0.02 with which
//! points were kept, so this is the resolution of the reference itself.

use super::pictures::{FrameView, ReplayPictures};
use anyhow::{bail, Context, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use sepmem::bag::{Bag, BagWriter};
use sepmem::config::Config;
use sepmem::eval::view::{ViewFrame, ViewScore, ViewTracker};
use sepmem::eval::{cold_references, score_frame, FrameScore, ScoreConfig};
use sepmem::pipeline::engine::Engine;
use sepmem::pipeline::StartPath;
use sepmem::synth::truth::GroundTruthIndex;
use sepmem::synth::view_metrics::SeenSide;
use sepmem::transport::keys::expand_topic_template;
use std::collections::BTreeMap;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};

/// Arguments of `sepmem replay`.
#[derive(Args, Debug)]
pub struct ReplayArgs {
    /// Input bag: a `.mcap` file, a `.db3` file or a bag directory.
    pub bag: PathBuf,
    /// Output bag (`.mcap` file, or a directory with metadata.yaml).
    #[arg(short, long)]
    pub out: Option<PathBuf>,
    /// Only replay these topics (repeatable; default: every PointCloud2 topic).
    #[arg(long)]
    pub topic: Vec<String>,
    /// Configuration file (.json5 or .toml) holding the keys to change.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Override one parameter: section.key=value (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub set: Vec<String>,
    /// Do not score frames against the bag's ground truth.
    #[arg(long)]
    pub no_score: bool,
    /// Also reconstruct every frame cold (untimed) and report, per warm
    /// frame, ΔF = F_cold − F_warm and the warm/cold iteration ratio.
    #[arg(long)]
    pub compare_cold: bool,
    /// With --compare-cold: cold starts per frame, each on another
    /// pseudo-random thinning subset of the same size (the first is the
    /// pipeline's own). F_cold is then their mean, and the summary also
    /// says how often one cold start reaches the others' mean within 0.01
    /// (how reproducible the cold reference itself is).
    #[arg(long, default_value_t = 1, requires = "compare_cold", value_parser = clap::value_parser!(u64).range(1..=16))]
    pub cold_repeats: u64,
    /// Apply the per-frame deadlines (`pipeline.deadline_ms`,
    /// `cold_deadline_ms`) as `sepmem node` does: how many iterations a
    /// frame gets then depends on the machine's speed and load. Without
    /// it a replay has no deadline, only the iteration caps, and is
    /// deterministic: the same bag and configuration give the same meshes
    /// on any machine.
    #[arg(long)]
    pub realtime: bool,
    /// Print only the summary.
    #[arg(short, long)]
    pub quiet: bool,
    /// Write one PNG per stream and frame into this folder: the mesh with
    /// its input points (and the ground truth, when the bag has it) from
    /// the camera side, the side and the back.
    #[arg(long, value_name = "DIR")]
    pub snapshots: Option<PathBuf>,
    /// Write a PNG plot of F, visible recall R_vis (when scored) and
    /// latency over the frames of each stream.
    #[arg(long, value_name = "FILE.png")]
    pub plot: Option<PathBuf>,
}

/// Run `sepmem replay` from its arguments.
pub fn run_args(a: &ReplayArgs) -> Result<()> {
    join_the_global_pool();
    let mut cfg = Config::load(a.config.as_deref(), &a.set)?;
    if !a.realtime {
        // 0 disables every deadline (warm and cold).
        cfg.pipeline.deadline_ms = 0.0;
    }
    run_opts(
        &a.bag,
        Outputs {
            bag: a.out.as_deref(),
            meshes: None,
            snapshots: a.snapshots.as_deref(),
            plot: a.plot.as_deref(),
        },
        &a.topic,
        &cfg,
        Options {
            quiet: a.quiet,
            score: !a.no_score,
            compare_cold: a.compare_cold,
            cold_repeats: a.cold_repeats as usize,
        },
    )
}

/// Make this thread, which runs the frames, the first worker of rayon's
/// global pool (`RAYON_NUM_THREADS` threads, else one per core), so that a
/// frame's parallel steps run on it instead of being handed to a pool
/// thread while it waits. Handed over, a one-thread replay had two threads
/// of frame work (this one between the parallel steps, the pool's worker
/// looking for the next one) next to the background rebuild on a two-core
/// machine: the 6 231-point turning mug (`RAYON_NUM_THREADS=1 sepmem
/// replay tests/data/bags/synth_turn_mug.mcap -q --no-score`) was preempted
/// 479-526 times and its warm frames took p95 16.7-30.3 ms without the
/// waits; joined, 22-44 times and p95 16.4-16.6 ms (4 runs each). The pool
/// is built once per process; when something built it first, the frames
/// hand their steps over as before.
fn join_the_global_pool() {
    if let Err(e) = rayon::ThreadPoolBuilder::new()
        .use_current_thread()
        .build_global()
    {
        tracing::debug!("replay: frames hand their parallel steps to rayon's pool: {e}");
    }
}

/// What a replay computes and prints besides the pipeline itself.
#[derive(Debug, Clone, Copy, Default)]
pub struct Options {
    /// Print only the summary.
    pub quiet: bool,
    /// Score frames against the bag's ground truth, when it has some.
    pub score: bool,
    /// Reconstruct every frame cold too and compare (needs ground truth for ΔF).
    pub compare_cold: bool,
    /// Cold starts per frame with `compare_cold` (at least 1; see
    /// [`sepmem::eval::cold_references`]).
    pub cold_repeats: usize,
}

/// Per-stream accumulators of the summary.
#[derive(Debug, Default)]
struct StreamSummary {
    scores: Vec<FrameScore>,
    /// The robot's-view scores, one per entry of `scores`.
    views: Vec<ViewScore>,
    /// The tracked pose and coverage behind `views`.
    view_tracker: ViewTracker,
    /// (ΔF, warm/cold iteration ratio) of warm frames.
    warm_vs_cold: Vec<(f64, f64)>,
    /// Over the warm frames' cold references (with more than one per
    /// frame): how many reached the mean F of the frame's other cold
    /// references within 0.01, of how many.
    cold_vs_cold: (usize, usize),
    /// Most bytes the stream's fused model held after a frame.
    model_bytes_max: Option<usize>,
    /// Frames whose view restarted the fused model.
    model_resets: Vec<u64>,
}

const POINTCLOUD2: &str = "sensor_msgs/msg/PointCloud2";

/// The model line's note of the frames whose view restarted the fused
/// model (empty when none did).
fn resets_note(frames: &[u64]) -> String {
    if frames.is_empty() {
        return String::new();
    }
    let mut list: Vec<String> = frames.iter().take(8).map(u64::to_string).collect();
    if frames.len() > 8 {
        list.push("…".to_owned());
    }
    format!(
        "; restarted {} by a view that saw through more than pipeline.model.reset_share of it (the object changed, or was swapped): frame {}",
        match frames.len() {
            1 => "once".to_owned(),
            n => format!("{n} times"),
        },
        list.join(", ")
    )
}

/// Latency percentile (nearest rank) of sorted values.
pub fn percentile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let rank = ((q * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len());
    sorted[rank - 1]
}

/// Where a replay writes its results.
#[derive(Debug, Clone, Copy, Default)]
pub struct Outputs<'a> {
    /// Output bag with the mesh, marker and diagnostics topics.
    pub bag: Option<&'a Path>,
    /// Folder receiving one binary PLY mesh per stream and frame.
    pub meshes: Option<&'a Path>,
    /// Folder receiving one PNG snapshot per stream and frame.
    pub snapshots: Option<&'a Path>,
    /// PNG plot of F, R_vis and latency over the frames.
    pub plot: Option<&'a Path>,
}

/// Replay `bag` into the given outputs with the given options.
pub fn run_opts(
    bag_path: &Path,
    outputs_to: Outputs<'_>,
    topics: &[String],
    cfg: &Config,
    opts: Options,
) -> Result<()> {
    let quiet = opts.quiet;
    let out = outputs_to.bag;
    if let Some(dir) = outputs_to.meshes {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let bag = Bag::open(bag_path).with_context(|| format!("opening bag {}", bag_path.display()))?;
    let mut pictures = ReplayPictures::new(outputs_to.snapshots, outputs_to.plot)?;
    let cloud_topics: Vec<&str> = bag
        .topics
        .iter()
        .filter(|t| t.type_name == POINTCLOUD2)
        .map(|t| t.name.as_str())
        .filter(|t| topics.is_empty() || topics.iter().any(|w| w == t))
        .collect();
    if cloud_topics.is_empty() {
        bail!(
            "no {POINTCLOUD2} topic to replay in {} (topics: {})",
            bag_path.display(),
            bag.topics
                .iter()
                .map(|t| t.name.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    let messages = bag.read(&cloud_topics)?;
    let truth = if opts.score || opts.compare_cold {
        GroundTruthIndex::from_bag(&bag)
            .with_context(|| format!("reading ground truth of {}", bag_path.display()))?
    } else {
        GroundTruthIndex::default()
    };
    let scored = !truth.is_empty();
    let score_cfg = ScoreConfig::from_config(cfg);
    let mut per_stream: BTreeMap<String, StreamSummary> = BTreeMap::new();
    let mut writer = out
        .map(|p| {
            BagWriter::create(p).with_context(|| format!("creating output bag {}", p.display()))
        })
        .transpose()?;
    let mut engine = Engine::new(&cfg.membrane, cfg.pipeline.clone(), cfg.wire.clone())?;
    let p = &cfg.pipeline;
    let o = &cfg.node.outputs;

    let bar = if std::io::stderr().is_terminal() && !quiet {
        let b = ProgressBar::new(messages.len() as u64);
        b.set_style(
            ProgressStyle::with_template("{bar:40} {pos}/{len} frames {msg}")
                .unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        b
    } else {
        ProgressBar::hidden()
    };
    let print = |line: String| {
        if !quiet {
            bar.suspend(|| println!("{line}"));
        }
    };
    let mut header = format!(
        "{:<32} {:>5} {:>7} {:<5} {:<22} {:>4} {:>6} {:>8}",
        "stream", "frame", "points", "path", "reason", "it", "eta_g", "ms"
    );
    if scored {
        header += &format!(
            " {:>6} {:>6} {:>6} {:>7} {:>5} {:>5}",
            "F", "P", "R_vis", "CD", "depth", "vol"
        );
    }
    if opts.compare_cold {
        header += &format!(" {:>7} {:>5} {:>7} {:>5}", "F_cold", "it_c", "dF", "ratio");
        if opts.cold_repeats > 1 {
            header += &format!(" {:>6}", "spread");
        }
    }
    if scored {
        header.extend(VIEW_COLUMNS.map(|c| format!(" {c:>6}")));
    }
    print(header);
    let (mut latencies, mut warm_it, mut cold_it) = (Vec::new(), Vec::new(), Vec::new());
    // The warm frames' latencies alone (the cost: warm frame p95).
    let mut warm_latencies = Vec::new();
    // Warm frames' latency less their wait for a rebuild, and the waits.
    let mut warm_own = Vec::new();
    let mut waits = Vec::new();
    let (mut bad_samples, mut failed) = (0usize, 0usize);
    // Points dropped before tracking: detached from their object's main
    // body, and flying pixels.
    let (mut detached, mut flying) = (Dropped::default(), Dropped::default());
    // Frames the flying-pixel filter found not one depth image.
    let mut not_an_image = 0usize;
    // Frames that restarted a rebuild starved at the lowest priority.
    let mut rebuilds_starved = 0usize;
    for m in &messages {
        bar.inc(1);
        let now = i64::try_from(m.log_time).unwrap_or(i64::MAX);
        let frame = match engine.handle(&m.topic, &m.data, None, now) {
            Ok(x) => x,
            Err(e) => {
                bad_samples += 1;
                print(format!("skipped sample: {e}"));
                continue;
            }
        };
        let (sample, streams, processed) = (&frame.sample, &frame.sample.streams, &frame.processed);
        let stamp = sample.header.stamp.to_nanos();
        for (sc, pr) in streams.iter().zip(processed) {
            match &pr.outcome {
                Ok(r) => {
                    latencies.push(r.latency_ms);
                    detached.add(r.reconstruction.report.points_detached);
                    flying.add(r.flying.dropped);
                    not_an_image += usize::from(r.flying.not_an_image);
                    rebuilds_starved += usize::from(r.rebuild_starved);
                    match r.path {
                        StartPath::Warm => {
                            warm_it.push(r.iterations as f64);
                            warm_latencies.push(r.latency_ms);
                            warm_own.push(r.latency_ms - r.rebuild_wait_ms);
                            if r.rebuild_wait_ms > 0.0 {
                                waits.push(r.rebuild_wait_ms);
                            }
                        }
                        StartPath::Cold => cold_it.push(r.iterations as f64),
                    }
                    let id = pr.key.to_string();
                    let gt = truth.posed_mesh(&id, stamp);
                    let score = match &gt {
                        Some(gt) => Some(
                            score_frame(&r.reconstruction.mesh, gt, &sc.cloud.points, &score_cfg)
                                .with_context(|| format!("scoring {id} frame {}", r.frame))?,
                        ),
                        None => None,
                    };
                    let mut line = format!(
                        "{:<32} {:>5} {:>7} {:<5} {:<22} {:>4} {:>6.3} {:>8.1}",
                        id,
                        r.frame,
                        pr.points,
                        if r.path == StartPath::Warm {
                            "warm"
                        } else {
                            "cold"
                        },
                        r.reason.to_string(),
                        r.iterations,
                        r.reconstruction.report.eta_final,
                        r.latency_ms
                    );
                    let entry = per_stream.entry(id.clone()).or_default();
                    entry.model_bytes_max = entry.model_bytes_max.max(r.model_bytes);
                    if r.model_reset {
                        entry.model_resets.push(r.frame);
                    }
                    if let Some(sc) = &score {
                        entry.scores.push(*sc);
                        line += &format!(
                            " {:>6.3} {:>6.3} {:>6.3} {:>7.4} {:>5.2} {:>5.2}",
                            sc.fscore,
                            sc.precision,
                            sc.recall_visible,
                            sc.chamfer_l1,
                            sc.depth_ratio,
                            sc.volume_ratio
                        );
                    } else if scored {
                        let dash = "-";
                        line += &format!(
                            " {dash:>6} {dash:>6} {dash:>6} {dash:>7} {dash:>5} {dash:>5}"
                        );
                    }
                    if opts.compare_cold {
                        let refs = cold_references(
                            &sc.cloud,
                            &engine.membranes,
                            &cfg.pipeline,
                            opts.cold_repeats.max(1),
                        )
                        .with_context(|| format!("cold reference of {id} frame {}", r.frame))?;
                        let mut f_refs = Vec::with_capacity(refs.len());
                        for c in &refs {
                            f_refs.push(match &gt {
                                Some(gt) => {
                                    score_frame(&c.mesh, gt, &sc.cloud.points, &score_cfg)?.fscore
                                }
                                None => f64::NAN,
                            });
                        }
                        let it_c = refs.iter().map(|c| c.report.iterations as f64).sum::<f64>()
                            / refs.len() as f64;
                        let f_cold = mean(&f_refs);
                        let df = f_cold - score.map_or(f64::NAN, |s| s.fscore);
                        let ratio = r.iterations as f64 / it_c.max(1.0);
                        if r.path == StartPath::Warm {
                            entry.warm_vs_cold.push((df, ratio));
                            if f_refs.len() > 1 {
                                let sum: f64 = f_refs.iter().sum();
                                let others = (f_refs.len() - 1) as f64;
                                let reached = f_refs
                                    .iter()
                                    .filter(|&&f| f >= (sum - f) / others - 0.01)
                                    .count();
                                entry.cold_vs_cold.0 += reached;
                                entry.cold_vs_cold.1 += f_refs.len();
                            }
                        }
                        line += &format!(" {f_cold:>7.3} {it_c:>5.1} {df:>+7.3} {ratio:>5.2}");
                        if f_refs.len() > 1 {
                            line += &format!(" {:>6.3}", max(&f_refs) - min(&f_refs));
                        }
                    }
                    if let Some(gt) = &gt {
                        let at = (id.as_str(), stamp);
                        let points = &sc.cloud.points;
                        let v = view_score(&truth, entry, at, gt, r, points, cfg.metrics.tau)?;
                        line += &view_columns(v.as_ref());
                    } else if scored {
                        line += &view_columns(None);
                    }
                    print(line);
                    pictures.frame(&FrameView {
                        stream: &id,
                        frame: r.frame,
                        mesh: &r.reconstruction.mesh,
                        points: &sc.cloud.points,
                        truth: gt.as_ref(),
                        viewpoint: r.reconstruction.report.viewpoint,
                        score: score.map(|s| (s.fscore, s.recall_visible)),
                        latency_ms: r.latency_ms,
                    })?;
                    if let Some(dir) = outputs_to.meshes {
                        let name = format!(
                            "{}_{:04}.ply",
                            pr.key
                                .to_string()
                                .trim_start_matches('/')
                                .replace(['/', '#'], "_"),
                            r.frame
                        );
                        sepmem::io::save_mesh(dir.join(name), &r.reconstruction.mesh)?;
                    }
                }
                Err(e) => {
                    failed += 1;
                    print(format!("{:<32} error: {e}", pr.key.to_string()));
                }
            }
        }
        if let Some(w) = writer.as_mut() {
            let msgs = frame.messages(&p.marker_namespace, &p.label_channel);
            for (mesh, diag) in &msgs.objects {
                w.write(&expand_topic_template(&o.mesh, &m.topic), m.log_time, mesh)?;
                w.write(
                    &expand_topic_template(&o.frame_diagnostics, &m.topic),
                    m.log_time,
                    diag,
                )?;
            }
            w.write(
                &expand_topic_template(&o.markers, &m.topic),
                m.log_time,
                &msgs.markers,
            )?;
            if let Some(model) = &msgs.model {
                w.write(
                    &expand_topic_template(&o.model, &m.topic),
                    m.log_time,
                    model,
                )?;
            }
        }
    }
    bar.finish_and_clear();
    latencies.sort_by(f64::total_cmp);
    warm_latencies.sort_by(f64::total_cmp);
    warm_own.sort_by(f64::total_cmp);
    println!(
        "summary: {} samples, {} frames ok ({} warm, {} cold), {} failed, {} bad samples; {}; warm frames: {}; {}; mean iterations warm {} cold {}; {}",
        messages.len(),
        latencies.len(),
        warm_it.len(),
        cold_it.len(),
        failed,
        bad_samples,
        latency_summary(&latencies),
        latency_summary(&warm_latencies),
        rebuild_waits(&warm_own, &waits),
        one_decimal(mean(&warm_it)),
        one_decimal(mean(&cold_it)),
        if p.deadline_ms > 0.0 {
            format!(
                "deadlines {} ms warm, {} ms cold",
                p.deadline_ms,
                p.cold_budget_ms()
            )
        } else {
            "no deadline (deterministic; --realtime applies pipeline.deadline_ms)".to_string()
        },
    );
    detached.say(
        "detached",
        "away from their object's main body (membrane.prepare.detached)",
    );
    flying.say(
        "flying",
        "behind their object's depth edges (pipeline.flying)",
    );
    if not_an_image > 0 {
        println!(
            "not a depth image: {not_an_image} frames were not one depth image seen from their frame's origin; the flying-pixel filter kept their points (publish the segmented cloud in the camera's optical frame)"
        );
    }
    if rebuilds_starved > 0 {
        println!(
            "rebuilds starved: {rebuilds_starved} frames found their background rebuild not done pipeline.rebuild.starved_frames after it was due and restarted it at a higher priority (the machine had no idle time for it)"
        );
    }
    for (id, st) in &per_stream {
        if let (Some(b), Some(m)) = (st.model_bytes_max, &p.model) {
            println!(
                "model {id}: at most {:.1} KiB after a frame (cap {:.1} KiB: pipeline.model's max_voxels, max_views, view_side){}",
                b as f64 / 1024.0,
                m.max_bytes() as f64 / 1024.0,
                resets_note(&st.model_resets)
            );
        }
        if !st.scores.is_empty() {
            let f: Vec<f64> = st.scores.iter().map(|s| s.fscore).collect();
            let pick = |g: fn(&FrameScore) -> f64| st.scores.iter().map(g).collect::<Vec<_>>();
            println!(
                "score {id}: {} frames; F mean {:.3} min {:.3}; precision mean {:.3} min {:.3}; visible recall mean {:.3} min {:.3}; Chamfer-L1 mean {:.4}; depth ratio min {:.2} max {:.2}; volume ratio min {:.2} max {:.2} (tau {}, {} samples)",
                f.len(),
                mean(&f),
                min(&f),
                mean(&pick(|s| s.precision)),
                min(&pick(|s| s.precision)),
                mean(&pick(|s| s.recall_visible)),
                min(&pick(|s| s.recall_visible)),
                mean(&pick(|s| s.chamfer_l1)),
                min(&pick(|s| s.depth_ratio)),
                max(&pick(|s| s.depth_ratio)),
                min(&pick(|s| s.volume_ratio)),
                max(&pick(|s| s.volume_ratio)),
                score_cfg.tau,
                score_cfg.samples,
            );
        }
        if !st.views.is_empty() {
            println!("{}", view_summary(id, st));
        }
        if opts.compare_cold && !st.warm_vs_cold.is_empty() {
            let df: Vec<f64> = st.warm_vs_cold.iter().map(|x| x.0).collect();
            let ratio: Vec<f64> = st.warm_vs_cold.iter().map(|x| x.1).collect();
            let pass = st
                .warm_vs_cold
                .iter()
                .filter(|(d, r)| *d <= 0.01 && *r <= 0.25)
                .count();
            let mut summary = format!(
                "warm vs cold {id}: {} warm frames; dF = F_cold - F_warm mean {:+.4} max {:+.4}; iteration ratio mean {:.3} max {:.3}; {pass}/{} warm frames within dF <= 0.01 at <= 1/4 of the cold iterations",
                df.len(),
                mean(&df),
                max(&df),
                mean(&ratio),
                max(&ratio),
                df.len(),
            );
            if opts.cold_repeats > 1 {
                summary += &format!(
                    " (F_cold: mean of {} cold starts on different thinning subsets); cold vs cold: {}/{} cold starts within 0.01 of the other subsets' mean",
                    opts.cold_repeats, st.cold_vs_cold.0, st.cold_vs_cold.1
                );
            }
            println!("{summary}");
        }
    }
    pictures.finish()?;
    if let Some(w) = writer {
        let s = w.finish()?;
        println!(
            "wrote {} ({} topics)",
            s.mcap_path.display(),
            s.counts.len()
        );
    }
    Ok(())
}

/// The robot's-view scores of one frame of stream `at.0` at stamp `at.1`
/// (its input `points`), recorded in the stream's summary (`None` when the
/// bag has no truth frame for this stamp).
fn view_score(
    truth: &GroundTruthIndex,
    entry: &mut StreamSummary,
    (id, stamp): (&str, i64),
    posed_truth: &sepmem::TriMesh,
    r: &sepmem::pipeline::FrameResult,
    points: &[sepmem::Vec3],
    tau_fraction: f64,
) -> Result<Option<ViewScore>> {
    let (Some(track), Some(frame)) = (truth.streams.get(id), truth.frame(id, stamp)) else {
        return Ok(None);
    };
    let v = entry
        .view_tracker
        .score(&ViewFrame {
            truth: frame,
            track,
            posed_truth,
            mesh: &r.reconstruction.mesh,
            points,
            warm_motion: r.motion,
            tau_fraction,
        })
        .with_context(|| format!("view scores of {id} frame {}", r.frame))?;
    entry.views.push(v);
    Ok(Some(v))
}

/// The names of the per-frame columns of [`view_columns`], in order.
const VIEW_COLUMNS: [&str; 10] = [
    "seen", "rim", "IoU", "rot", "tr_mm", "adds", "cover", "out3s", "excess", "pastex",
];

/// The per-frame columns [`VIEW_COLUMNS`] (dashes without a score); `rim` is the seen side on the silhouette's
/// rim alone, `adds` the tracked pose's ADD-S in mm (the true surface's
/// mean distance from itself placed by that pose: 0 for a turn about an
/// axis of symmetry), `out3s` the share of the points on the true surface
/// that lie outside the mesh by more than 3σ, `excess` the mesh's
/// projection beyond the true silhouette, as a share of the silhouette,
/// and `pastex` the largest such share in the stream's earlier views.
fn view_columns(v: Option<&ViewScore>) -> String {
    let opt = |x: Option<f64>| x.map_or_else(|| "-".to_string(), |x| format!("{x:.3}"));
    match v {
        Some(v) => format!(
            " {:>6} {:>6} {:>6} {:>6.2} {:>6.1} {:>6.2} {:>6.3} {:>6} {:>6} {:>6}",
            opt(v.seen_side()),
            opt(v.seen_side_rim()),
            opt(v.volume_iou),
            v.rotation_deg,
            v.translation_mm,
            v.surface_error_mm,
            v.coverage,
            opt(v.outside.share()),
            opt(v.silhouette_excess),
            opt(v.past_silhouette_excess)
        ),
        None => format!(" {:>6}", "-").repeat(VIEW_COLUMNS.len()),
    }
}

/// The `view` summary line of a stream: the whole-object F, seen side,
/// volume IoU, pose error and coverage over the first and the last third
/// of its scored frames (means), the median seen side over all frames
/// (and on the silhouette's rim alone, and inside it), the largest pose
/// error (rotation, translation, ADD-S), the points left out, the
/// silhouette excess in the current view and in earlier ones (median and
/// largest over the frames) and the seen side's failed rays by kind
/// ([`failed_rays`]).
fn view_summary(id: &str, st: &StreamSummary) -> String {
    let n = st.views.len().min(st.scores.len());
    let third = n.div_ceil(3);
    let part = |range: std::ops::Range<usize>| {
        let f: Vec<f64> = st.scores[range.clone()].iter().map(|s| s.fscore).collect();
        let v = &st.views[range];
        let pick = |g: fn(&ViewScore) -> Option<f64>| v.iter().filter_map(g).collect::<Vec<_>>();
        format!(
            "F {:.3} seen side {:.3} IoU {:.3} rot {:.2} deg trans {:.1} mm ADD-S {:.2} mm coverage {:.3}",
            mean(&f),
            mean(&pick(|v| v.seen_side())),
            mean(&pick(|v| v.volume_iou)),
            mean(&pick(|v| Some(v.rotation_deg))),
            mean(&pick(|v| Some(v.translation_mm))),
            mean(&pick(|v| Some(v.surface_error_mm))),
            mean(&pick(|v| Some(v.coverage))),
        )
    };
    let views = &st.views[..n];
    // The frames' values of an optional score, sorted.
    let sorted = |g: fn(&ViewScore) -> Option<f64>| {
        let mut v: Vec<f64> = views.iter().filter_map(g).collect();
        v.sort_by(f64::total_cmp);
        v
    };
    let seen = sorted(|v| v.seen_side());
    let rim = sorted(|v| v.seen_side_rim());
    let inner = sorted(|v| v.seen_rays.inner_accuracy());
    let excess = sorted(|v| v.silhouette_excess);
    let past = sorted(|v| v.past_silhouette_excess);
    let all = |g: fn(&ViewScore) -> f64| views.iter().map(g).collect::<Vec<_>>();
    let on_surface: usize = views.iter().map(|v| v.outside.on_surface).sum();
    let outside: usize = views.iter().map(|v| v.outside.outside).sum();
    let rays = views
        .iter()
        .fold(SeenSide::default(), |a, v| a + v.seen_rays);
    format!(
        "view {id}: {n} frames; first third ({third}): {}; last third ({third}): {}; seen side median {:.3} min {:.3} (on the silhouette's rim median {:.3}, inside it {:.3}); pose error max rot {:.2} deg trans {:.1} mm ADD-S {:.2} mm; points outside by > 3 sigma {outside} of {on_surface} ({} frames with any), worst {:.1} sigma; silhouette excess median {:.3} max {:.3} (in earlier views median {:.3} max {:.3}); {}",
        part(0..third),
        part(n - third..n),
        percentile(&seen, 0.5),
        min(&seen),
        percentile(&rim, 0.5),
        percentile(&inner, 0.5),
        max(&all(|v| v.rotation_deg)),
        max(&all(|v| v.translation_mm)),
        max(&all(|v| v.surface_error_mm)),
        views.iter().filter(|v| v.outside.outside > 0).count(),
        max(&all(|v| v.outside.worst_sigmas)),
        percentile(&excess, 0.5),
        max(&excess),
        percentile(&past, 0.5),
        max(&past),
        failed_rays(&rays),
    )
}

/// The seen side's failed rays over a stream's frames, by kind: where the
/// mesh stands in front of the object, where the object stands out of it
/// (behind: a planner would collide there) and where the ray misses it.
fn failed_rays(r: &SeenSide) -> String {
    let failed = r.rays - r.within;
    let pc = |n: usize| 100.0 * n as f64 / failed.max(1) as f64;
    format!(
        "seen side's failed rays {failed} of {}: mesh in front {:.0} %, behind {:.0} %, missed {:.0} %",
        r.rays,
        pc(r.in_front),
        pc(r.behind),
        pc(r.missed()),
    )
}

/// The warm frames' latency less their waits for a rebuild (`own`,
/// sorted), and how many waited how long in all (`waits`).
fn rebuild_waits(own: &[f64], waits: &[f64]) -> String {
    if waits.is_empty() {
        return "no frame waited for a rebuild".to_string();
    }
    format!(
        "{} waited for a rebuild (adopted or refused), {:.1} ms in all; without the waits: {}",
        waits.len(),
        waits.iter().sum::<f64>(),
        latency_summary(own)
    )
}

/// `latency ms p50 … p95 … max …` of sorted latencies, or a plain
/// sentence when no frame succeeded (it printed "p50 NaN" before).
fn latency_summary(sorted: &[f64]) -> String {
    match sorted.last() {
        Some(max) => format!(
            "latency ms p50 {:.1} p95 {:.1} max {max:.1}",
            percentile(sorted, 0.5),
            percentile(sorted, 0.95)
        ),
        None => "latency: none (no frame succeeded)".to_string(),
    }
}

/// A value with one decimal, `-` when it is undefined (an empty mean).
fn one_decimal(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.1}")
    } else {
        "-".to_string()
    }
}

fn mean(v: &[f64]) -> f64 {
    if v.is_empty() {
        f64::NAN
    } else {
        v.iter().sum::<f64>() / v.len() as f64
    }
}

fn min(v: &[f64]) -> f64 {
    v.iter().copied().fold(f64::NAN, f64::min)
}

fn max(v: &[f64]) -> f64 {
    v.iter().copied().fold(f64::NAN, f64::max)
}

/// Points a filter dropped over a replay, and in how many frames.
#[derive(Debug, Default)]
struct Dropped {
    points: usize,
    frames: usize,
}

impl Dropped {
    fn add(&mut self, points: usize) {
        self.points += points;
        self.frames += usize::from(points > 0);
    }

    /// The summary line `what: N points dropped in M frames, why`, when any were.
    fn say(&self, what: &str, why: &str) {
        if self.points > 0 {
            println!(
                "{what}: {} points dropped in {} frames, {why}",
                self.points, self.frames
            );
        }
    }
}
