//! `sepmem bench`: the paper's evaluation (§IV), reproduced and kept.
//!
//! Every experiment is deterministic (fixed base seed, per-experiment RNG
//! streams, see [`clouds::rng_for`]) so that results compare over time. The
//! scores are the SAP/ONet protocol of [`crate::metrics`]: both meshes
//! normalised by the ground truth's bounding box (longest edge 1),
//! area-uniform samples on each side, Chamfer-L1 = ½(accuracy +
//! completeness), F-score at τ = 0.01 and normal consistency.
//!
//! Sections (each can be selected with `--only`):
//!
//! | key | experiment |
//! |---|---|
//! | `table1` | Table 1 layout: every closed mesh of the shared ground-truth set plus the [`crate::shapes`], 20,000-point clouds, the paper's four [`clouds::Condition`]s and a non-uniform one (density falling 8:1 along the object; not in "overall"); genus > 0 shapes summarised apart |
//! | `sweep` | sphere robustness sweep: 1,000 points plus 1,000 duplicates perturbed with σ ∈ {0, 0.05, 0.1, 0.2, 0.3, 0.5} |
//! | `adaptive` | static 8×5 vs static 40×25 vs dynamic adjustment (§III-F, Fig. 10): Chamfer per iteration and total time |
//! | `ablation` | weighted separability (Eq. 9): spatial / intensity / density and their combinations, white object points and dark outliers |
//! | `real` | real scans: the PCL bunny scan against its mesh; the mOSD tabletop objects without ground truth |
//! | `speed` | cold reconstruction of a 20,000-point object on one thread: median time and per-phase breakdown |
//! | `ablation-mechanisms` | every optional mechanism switched in turn: ΔF on Table 1 (genus 0, genus > 0), the sweep and nine synth replays ([`mechanisms`]); only when named in `--only` |
//!
//! Missing datasets are reported as skips, never as failures.

pub mod clouds;
pub mod markdown;
pub mod mechanisms;

use crate::cloud::{Aabb, PointCloud, Vec3};
use crate::config::{Config, ConfigError};
use crate::membrane::{self, Budget, GrowthConfig, Membrane, MembraneConfig, MembraneError, Start};
use crate::mesh::TriMesh;
use crate::metrics::{self, MetricsConfig};
use crate::shapes::{self, ShapeError};
use clouds::{rng_for, seed_for, Condition};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;
use thiserror::Error;

/// Errors that stop the benchmark (a failing reconstruction does not: it is
/// recorded in its row).
#[derive(Debug, Error)]
pub enum BenchError {
    /// The default configuration could not be loaded.
    #[error("bench: configuration: {0}")]
    Config(#[from] ConfigError),
    /// The membrane configuration is invalid.
    #[error("bench: {0}")]
    Membrane(#[from] membrane::ConfigError),
    /// A procedural shape could not be built.
    #[error("bench: procedural shape: {0}")]
    Shape(#[from] ShapeError),
    /// Scoring a mesh failed.
    #[error("bench: metrics for {what}: {message}")]
    Metrics {
        /// What was being scored.
        what: String,
        /// The metric error.
        message: String,
    },
    /// `--only` named something that is neither a section nor a shape.
    #[error("bench: --only `{0}` is neither a section (table1, sweep, adaptive, ablation, real, speed, ablation-mechanisms) nor a Table 1 shape")]
    UnknownSelection(String),
    /// A synth replay of the mechanism ablation could not be written or replayed.
    #[error("bench: synth replay {what}: {message}")]
    Replay {
        /// The sequence (or folder).
        what: String,
        /// The error.
        message: String,
    },
}

/// F-score threshold τ in the unit frame (1 % of the longest edge).
pub const F_SCORE_TAU: f64 = 0.01;

/// Samples per mesh in the metrics (the SAP/ONet protocol).
pub const METRIC_SAMPLES: usize = 100_000;

/// The sections of the benchmark.
pub const SECTIONS: [&str; 7] = [
    "table1",
    "sweep",
    "adaptive",
    "ablation",
    "real",
    "speed",
    mechanisms::SECTION,
];

/// Sections that run only when `--only` names them (not in the full run).
pub const OPT_IN_SECTIONS: [&str; 1] = [mechanisms::SECTION];

/// The base seed of `sepmem bench` unless `--seed` gives another.
pub const DEFAULT_SEED: u64 = 20250307;

/// What to run.
#[derive(Debug, Clone)]
pub struct BenchOptions {
    /// Reduced set (few shapes, fewer points) that runs in seconds.
    pub quick: bool,
    /// Sections and/or Table 1 shape names to restrict to (empty = everything).
    pub only: Vec<String>,
    /// Shared datasets directory (`None`: datasets are skipped).
    pub datasets: Option<PathBuf>,
    /// Base seed of every random stream.
    pub seed: u64,
    /// Membrane configuration (normally the embedded defaults).
    pub membrane: MembraneConfig,
}

impl BenchOptions {
    /// Full benchmark with the embedded default configuration.
    ///
    /// # Errors
    /// [`BenchError::Config`] if the embedded configuration is broken.
    pub fn new(quick: bool, datasets: Option<PathBuf>) -> Result<Self, BenchError> {
        Ok(Self {
            quick,
            only: Vec::new(),
            datasets,
            seed: DEFAULT_SEED,
            membrane: Config::defaults()?.membrane,
        })
    }

    fn section_selected(&self, key: &str) -> bool {
        let sections: Vec<&String> = self
            .only
            .iter()
            .filter(|o| SECTIONS.contains(&o.as_str()))
            .collect();
        if sections.is_empty() {
            !OPT_IN_SECTIONS.contains(&key)
        } else {
            sections.iter().any(|s| s.as_str() == key)
        }
    }

    fn shape_filter(&self) -> Vec<&str> {
        self.only
            .iter()
            .filter(|o| !SECTIONS.contains(&o.as_str()))
            .map(String::as_str)
            .collect()
    }

    fn points(&self) -> usize {
        if self.quick {
            5_000
        } else {
            20_000
        }
    }

    /// Samples per mesh for the metrics: always the protocol's 100,000 (with
    /// fewer, the sample spacing approaches τ and F is biased low even for a
    /// perfect reconstruction).
    fn metric_samples(&self) -> usize {
        METRIC_SAMPLES
    }
}

/// Scores of one reconstruction against its ground truth.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Scores {
    /// Chamfer-L1 (unit frame of the ground truth).
    pub chamfer_l1: f64,
    /// F-score at τ = 0.01.
    pub fscore: f64,
    /// Normal consistency.
    pub normal_consistency: f64,
}

/// One membrane run, scored or not.
#[derive(Debug, Clone, Serialize)]
pub struct RunResult {
    /// Scores against the ground truth (`None` without ground truth or on failure).
    pub scores: Option<Scores>,
    /// Wall-clock time of `membrane::reconstruct` (ms).
    pub time_ms: f64,
    /// Iterations run.
    pub iterations: usize,
    /// Final global separability η_g.
    pub eta_final: f64,
    /// Final control grid.
    pub grid: [usize; 2],
    /// Output mesh watertight and outward-oriented.
    pub watertight: bool,
    /// Why the evolution stopped.
    pub stop: String,
    /// The error, when the reconstruction failed.
    pub error: Option<String>,
}

/// One Table 1 row.
#[derive(Debug, Clone, Serialize)]
pub struct Table1Row {
    /// Shape name (procedural name, or the mesh file name).
    pub shape: String,
    /// Genus of the ground truth (from its Euler characteristic).
    pub genus: u32,
    /// Input condition.
    pub condition: Condition,
    /// Points in the input cloud.
    pub points: usize,
    /// The run.
    pub run: RunResult,
}

/// Mean scores over a group of rows.
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    /// Group label (condition name or "overall").
    pub group: String,
    /// Rows averaged.
    pub rows: usize,
    /// Rows that failed (no scores); excluded from the means.
    pub failed: usize,
    /// Mean Chamfer-L1.
    pub chamfer_l1: f64,
    /// Mean F-score.
    pub fscore: f64,
    /// Mean normal consistency.
    pub normal_consistency: f64,
    /// Mean time (ms).
    pub time_ms: f64,
}

/// A ground-truth mesh left out of Table 1, and why.
#[derive(Debug, Clone, Serialize)]
pub struct Skip {
    /// What was skipped (file or section).
    pub what: String,
    /// Why.
    pub reason: String,
}

/// Table 1 results.
#[derive(Debug, Clone, Serialize, Default)]
pub struct Table1 {
    /// Points per cloud (before outliers are added).
    pub points: usize,
    /// Every row.
    pub rows: Vec<Table1Row>,
    /// Means per condition over the genus-0 shapes, then "overall" (the
    /// paper's four conditions).
    pub genus0: Vec<Summary>,
    /// Means per condition over the genus > 0 shapes, then "overall" (the
    /// paper's four conditions).
    pub genus_pos: Vec<Summary>,
}

/// One point of the sphere sweep.
#[derive(Debug, Clone, Serialize)]
pub struct SweepRow {
    /// Perturbation σ of the duplicates.
    pub sigma: f64,
    /// The run.
    pub run: RunResult,
}

/// One configuration of the static-vs-adaptive experiment.
#[derive(Debug, Clone, Serialize)]
pub struct AdaptiveRow {
    /// `static 8x5`, `static 40x25` or `adaptive`.
    pub mode: String,
    /// The full (unbudgeted) run.
    pub run: RunResult,
    /// `(iterations allowed, Chamfer-L1 of the returned surface)`.
    pub chamfer_per_iteration: Vec<(usize, f64)>,
    /// η_g per iteration, from the membrane report.
    pub eta_per_iteration: Vec<f64>,
}

/// Static vs adaptive results.
#[derive(Debug, Clone, Serialize, Default)]
pub struct Adaptive {
    /// The shape used.
    pub shape: String,
    /// One row per configuration.
    pub rows: Vec<AdaptiveRow>,
}

/// One row of the attribute ablation.
#[derive(Debug, Clone, Serialize)]
pub struct AblationRow {
    /// Shape.
    pub shape: String,
    /// Outlier σ.
    pub sigma: f64,
    /// Separabilities combined (e.g. `spatial+intensity`).
    pub features: String,
    /// The run.
    pub run: RunResult,
}

/// One real-scan row.
#[derive(Debug, Clone, Serialize)]
pub struct RealRow {
    /// Input file (relative to the datasets directory).
    pub input: String,
    /// Reference mesh, when there is one.
    pub reference: Option<String>,
    /// Points in the input.
    pub points: usize,
    /// The run.
    pub run: RunResult,
}

/// Speed results.
#[derive(Debug, Clone, Serialize, Default)]
pub struct Speed {
    /// Object.
    pub shape: String,
    /// Points in the cloud.
    pub points: usize,
    /// Repeats.
    pub repeats: usize,
    /// Median wall-clock time of `membrane::reconstruct` (ms).
    pub median_ms: f64,
    /// Minimum and maximum (ms).
    pub min_ms: f64,
    /// Maximum (ms).
    pub max_ms: f64,
    /// Median of each phase from the membrane report (ms).
    pub phases: Vec<(String, f64)>,
    /// Iterations of the median run.
    pub iterations: usize,
    /// Warm-started frames of the same object, moved slightly each frame.
    pub warm: Option<WarmSpeed>,
}

/// Warm-started reconstructions (the frame pipeline's path): each frame is
/// the object's cloud shifted by 1 % of its size (alternating direction),
/// started from the previous frame's surface, under an iteration cap.
#[derive(Debug, Clone, Serialize, Default)]
pub struct WarmSpeed {
    /// Frames timed.
    pub frames: usize,
    /// Iteration cap per frame.
    pub max_iterations: usize,
    /// Median wall-clock time (ms).
    pub median_ms: f64,
    /// 95th percentile (ms).
    pub p95_ms: f64,
    /// Maximum (ms).
    pub max_ms: f64,
    /// Median of each phase (ms).
    pub phases: Vec<(String, f64)>,
    /// Median iterations.
    pub iterations: f64,
    /// Median F-score of the warm frames against the (shifted) ground truth.
    pub fscore: f64,
}

/// Everything the benchmark measured.
#[derive(Debug, Clone, Serialize, Default)]
pub struct BenchReport {
    /// Reduced (`--quick`) run.
    pub quick: bool,
    /// Base seed.
    pub seed: u64,
    /// Threads available to the non-speed sections (0 = all cores).
    pub threads: usize,
    /// Wall-clock time of the whole benchmark (s).
    pub total_s: f64,
    /// Table 1.
    pub table1: Option<Table1>,
    /// Sphere sweep.
    pub sweep: Option<Vec<SweepRow>>,
    /// Static vs adaptive.
    pub adaptive: Option<Adaptive>,
    /// Attribute ablation.
    pub ablation: Option<Vec<AblationRow>>,
    /// Real scans.
    pub real: Option<Vec<RealRow>>,
    /// Speed.
    pub speed: Option<Speed>,
    /// The mechanism ablation (only when asked for).
    pub mechanisms: Option<mechanisms::Mechanisms>,
    /// Shapes, files or sections skipped, with the reason.
    pub skipped: Vec<Skip>,
}

/// Sample `n` points area-uniformly on `mesh` (seeded).
fn sample(mesh: &TriMesh, n: usize, seed: u64, what: &str) -> Result<Vec<Vec3>, BenchError> {
    metrics::sample_surface(mesh, n, seed)
        .map(|s| s.points)
        .map_err(|e| BenchError::Metrics {
            what: what.to_string(),
            message: e.to_string(),
        })
}

/// Score `pred` against `gt` with the SAP/ONet protocol.
///
/// # Errors
/// The metric error's message (empty or degenerate ground truth, bad indices).
pub fn score(pred: &TriMesh, gt: &TriMesh, samples: usize, seed: u64) -> Result<Scores, String> {
    let cfg = MetricsConfig {
        samples,
        tau: F_SCORE_TAU,
        seed,
    };
    let m = metrics::evaluate(pred, gt, &cfg).map_err(|e| e.to_string())?;
    Ok(Scores {
        chamfer_l1: m.chamfer_l1,
        fscore: m.fscore,
        normal_consistency: m.normal_consistency,
    })
}

/// Run the membrane on `cloud` and score the result against `gt` (if any).
fn run_one(
    cloud: &PointCloud,
    cfg: &Membrane,
    budget: &Budget,
    gt: Option<&TriMesh>,
    samples: usize,
    seed: u64,
) -> RunResult {
    run_with_report(cloud, cfg, budget, gt, samples, seed).0
}

/// [`run_one`], also returning the membrane's report.
fn run_with_report(
    cloud: &PointCloud,
    cfg: &Membrane,
    budget: &Budget,
    gt: Option<&TriMesh>,
    samples: usize,
    seed: u64,
) -> (RunResult, Option<membrane::Report>) {
    let t = Instant::now();
    let rec = cfg.reconstruct(cloud, budget, &Start::Cold);
    let time_ms = t.elapsed().as_secs_f64() * 1e3;
    match rec {
        Ok(rec) => {
            let topo = rec.mesh.topology();
            let watertight = topo.is_watertight() && rec.mesh.signed_volume() > 0.0;
            let (scores, error) = match gt.map(|g| score(&rec.mesh, g, samples, seed)) {
                None => (None, None),
                Some(Ok(s)) => (Some(s), None),
                Some(Err(e)) => (None, Some(format!("metrics: {e}"))),
            };
            let run = RunResult {
                scores,
                time_ms,
                iterations: rec.report.iterations,
                eta_final: rec.report.eta_final,
                grid: rec.report.grid,
                watertight,
                stop: rec.report.stop.to_string(),
                error,
            };
            (run, Some(rec.report))
        }
        Err(e) => (failed_run(time_ms, &e), None),
    }
}

fn failed_run(time_ms: f64, e: &MembraneError) -> RunResult {
    RunResult {
        scores: None,
        time_ms,
        iterations: 0,
        eta_final: 0.0,
        grid: [0, 0],
        watertight: false,
        stop: "error".into(),
        error: Some(e.to_string()),
    }
}

/// A Table 1 ground-truth shape.
struct GtShape {
    name: String,
    genus: u32,
    mesh: TriMesh,
}

/// Every closed mesh under `dir` (recursively, `.obj`/`.ply`), normalised
/// to a unit longest edge; open or unreadable meshes go to `skipped`.
fn load_gt_meshes(dir: &Path, skipped: &mut Vec<Skip>) -> Vec<GtShape> {
    let mut files = Vec::new();
    collect_files(dir, &mut files);
    files.sort();
    let mut out = Vec::new();
    for f in files {
        let ext = f
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        if !matches!(ext.as_deref(), Some("obj" | "ply")) {
            continue;
        }
        let name = f
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let rel = f.strip_prefix(dir).unwrap_or(&f).display().to_string();
        let mut mesh = match crate::io::load_mesh(&f) {
            Ok(m) => m.mesh,
            Err(e) => {
                skipped.push(Skip {
                    what: rel,
                    reason: format!("unreadable: {e}"),
                });
                continue;
            }
        };
        let topo = mesh.topology();
        if !topo.is_watertight() {
            skipped.push(Skip {
                what: rel,
                reason: format!(
                    "not watertight ({} boundary, {} non-manifold, {} misoriented edges, {} degenerate triangles)",
                    topo.boundary_edges,
                    topo.non_manifold_edges,
                    topo.misoriented_edges,
                    topo.degenerate_triangles
                ),
            });
            continue;
        }
        if mesh.signed_volume() < 0.0 {
            mesh.flip();
        }
        shapes::normalise_unit_longest_edge(&mut mesh);
        let genus = shapes::genus(&mesh).unwrap_or(0);
        out.push(GtShape { name, genus, mesh });
    }
    out
}

fn collect_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(rd) = std::fs::read_dir(dir) else {
        return;
    };
    for e in rd.flatten() {
        let p = e.path();
        if p.is_dir() {
            collect_files(&p, out);
        } else {
            out.push(p);
        }
    }
}

fn summarise(group: &str, rows: &[&Table1Row]) -> Summary {
    let ok: Vec<(&Scores, f64)> = rows
        .iter()
        .filter_map(|r| r.run.scores.as_ref().map(|s| (s, r.run.time_ms)))
        .collect();
    let n = ok.len().max(1) as f64;
    let nan_if_empty = |v: f64| if ok.is_empty() { f64::NAN } else { v };
    Summary {
        group: group.to_string(),
        rows: rows.len(),
        failed: rows.len() - ok.len(),
        chamfer_l1: nan_if_empty(ok.iter().map(|(s, _)| s.chamfer_l1).sum::<f64>() / n),
        fscore: nan_if_empty(ok.iter().map(|(s, _)| s.fscore).sum::<f64>() / n),
        normal_consistency: nan_if_empty(
            ok.iter().map(|(s, _)| s.normal_consistency).sum::<f64>() / n,
        ),
        time_ms: nan_if_empty(ok.iter().map(|(_, t)| t).sum::<f64>() / n),
    }
}

/// The means per condition over the rows of genus 0 or genus > 0, then
/// "overall": the mean over the paper's four conditions
/// ([`Condition::PAPER`]; the non-uniform condition has its own row only,
/// so that "overall" stays the paper's figure).
fn summaries(rows: &[Table1Row], genus_pos: bool) -> Vec<Summary> {
    let sel: Vec<&Table1Row> = rows.iter().filter(|r| (r.genus > 0) == genus_pos).collect();
    if sel.is_empty() {
        return Vec::new();
    }
    let of = |c: Condition| -> Vec<&Table1Row> {
        sel.iter().copied().filter(|r| r.condition == c).collect()
    };
    let mut out: Vec<Summary> = Condition::ALL
        .iter()
        .filter(|&&c| Condition::PAPER.contains(&c) || !of(c).is_empty())
        .map(|&c| summarise(c.name(), &of(c)))
        .collect();
    let paper: Vec<&Table1Row> = sel
        .iter()
        .copied()
        .filter(|r| Condition::PAPER.contains(&r.condition))
        .collect();
    out.push(summarise("overall", &paper));
    out
}

/// Table 1: ground-truth meshes plus procedural shapes, five conditions.
fn table1(
    opts: &BenchOptions,
    skipped: &mut Vec<Skip>,
    log: &mut dyn FnMut(&str),
) -> Result<Table1, BenchError> {
    let res = if opts.quick { 64 } else { 128 };
    let filter = opts.shape_filter();
    let mut gts: Vec<GtShape> = Vec::new();
    let names: Vec<&str> = if opts.quick {
        vec!["sphere", "torus"]
    } else {
        shapes::NAMES.to_vec()
    };
    for n in names {
        let s = shapes::by_name(n, res)?;
        gts.push(GtShape {
            name: s.name.to_string(),
            genus: s.genus,
            mesh: s.mesh,
        });
    }
    if !opts.quick {
        match &opts.datasets {
            Some(d) => {
                let dir = d.join("meshes_ground_truth");
                if dir.is_dir() {
                    gts.extend(load_gt_meshes(&dir, skipped));
                } else {
                    skipped.push(Skip {
                        what: dir.display().to_string(),
                        reason: "ground-truth mesh directory not found".into(),
                    });
                }
            }
            None => skipped.push(Skip {
                what: "meshes_ground_truth".into(),
                reason: "shared datasets not found".into(),
            }),
        }
    }
    if !filter.is_empty() {
        gts.retain(|g| filter.contains(&g.name.as_str()));
    }
    let n = opts.points();
    let samples = opts.metric_samples();
    let engine = Membrane::new(opts.membrane.clone())?;
    let mut rows = Vec::new();
    for g in &gts {
        let surface = sample(&g.mesh, n, seed_for(opts.seed, &g.name), &g.name)?;
        for c in Condition::ALL {
            let key = format!("{}/{}", g.name, c.name());
            // A condition that keeps only some of its surface samples (the
            // non-uniform one) draws its own, more of them.
            let own = match c.candidates_per_point() {
                1 => None,
                m => Some(sample(&g.mesh, m * n, seed_for(opts.seed, &key), &key)?),
            };
            let from = own.as_deref().unwrap_or(&surface[..]);
            let cloud = PointCloud::from_points(c.apply(from, &mut rng_for(opts.seed, &key)));
            let run = run_one(
                &cloud,
                &engine,
                &Budget::unlimited(),
                Some(&g.mesh),
                samples,
                seed_for(opts.seed, &format!("eval/{key}")),
            );
            log(&format!(
                "table1 {key}: F {} CD {} {:.0} ms",
                run.scores
                    .map_or("-".into(), |s| format!("{:.3}", s.fscore)),
                run.scores
                    .map_or("-".into(), |s| format!("{:.4}", s.chamfer_l1)),
                run.time_ms
            ));
            rows.push(Table1Row {
                shape: g.name.clone(),
                genus: g.genus,
                condition: c,
                points: cloud.len(),
                run,
            });
        }
    }
    Ok(Table1 {
        points: n,
        genus0: summaries(&rows, false),
        genus_pos: summaries(&rows, true),
        rows,
    })
}

/// The σ values of the sphere sweep.
pub const SWEEP_SIGMAS: [f64; 6] = [0.0, 0.05, 0.1, 0.2, 0.3, 0.5];

fn sweep(opts: &BenchOptions, log: &mut dyn FnMut(&str)) -> Result<Vec<SweepRow>, BenchError> {
    let sphere = shapes::sphere(if opts.quick { 64 } else { 128 })?;
    let surface = sample(
        &sphere.mesh,
        1000,
        seed_for(opts.seed, "sweep"),
        "sweep sphere",
    )?;
    let engine = Membrane::new(opts.membrane.clone())?;
    let mut out = Vec::new();
    for sigma in SWEEP_SIGMAS {
        let key = format!("sweep/{sigma}");
        let pts = clouds::with_perturbed_duplicates(&surface, sigma, &mut rng_for(opts.seed, &key));
        let run = run_one(
            &PointCloud::from_points(pts),
            &engine,
            &Budget::unlimited(),
            Some(&sphere.mesh),
            opts.metric_samples(),
            seed_for(opts.seed, &format!("eval/{key}")),
        );
        log(&format!(
            "sweep σ={sigma}: F {}",
            run.scores
                .map_or("-".into(), |s| format!("{:.3}", s.fscore))
        ));
        out.push(SweepRow { sigma, run });
    }
    Ok(out)
}

/// The shape with detail used by the static-vs-adaptive experiment: the
/// odedstein bunny when the datasets are present, else the bottle.
fn detail_shape(opts: &BenchOptions) -> Result<(String, TriMesh), BenchError> {
    if !opts.quick {
        if let Some(d) = &opts.datasets {
            let f = d.join("meshes_ground_truth/odedstein_meshes/bunny.obj");
            if let Ok(m) = crate::io::load_mesh(&f) {
                let mut mesh = m.mesh;
                if mesh.topology().is_watertight() {
                    if mesh.signed_volume() < 0.0 {
                        mesh.flip();
                    }
                    shapes::normalise_unit_longest_edge(&mut mesh);
                    return Ok(("bunny.obj".into(), mesh));
                }
            }
        }
    }
    Ok(("bottle".into(), shapes::bottle(96)?.mesh))
}

fn adaptive(opts: &BenchOptions, log: &mut dyn FnMut(&str)) -> Result<Adaptive, BenchError> {
    let (name, gt) = detail_shape(opts)?;
    let surface = sample(&gt, opts.points(), seed_for(opts.seed, "adaptive"), &name)?;
    let cloud = PointCloud::from_points(surface);
    let base = &opts.membrane;
    let with = |grid: [usize; 2], growth: Option<GrowthConfig>| {
        let mut cfg = base.clone();
        cfg.init.grid = grid;
        cfg.schedule.growth = growth;
        cfg
    };
    let growth = base.schedule.growth.clone().unwrap_or_default();
    let modes: [(&str, MembraneConfig); 3] = [
        ("static 8x5", with([8, 5], None)),
        ("static 40x25", with([40, 25], None)),
        ("adaptive", with(base.init.grid, Some(growth))),
    ];
    let samples = opts.metric_samples();
    let eval_seed = seed_for(opts.seed, "eval/adaptive");
    let mut rows = Vec::new();
    for (mode, cfg) in modes {
        let cfg = Membrane::new(cfg)?;
        let (run, report) = run_with_report(
            &cloud,
            &cfg,
            &Budget::unlimited(),
            Some(&gt),
            samples,
            eval_seed,
        );
        let eta = report.map(|r| r.eta).unwrap_or_default();
        // Chamfer of the surface returned after k iterations: re-run with an
        // iteration budget of k (the evolution is deterministic).
        let stride = if opts.quick { 20 } else { 1 };
        let mut per_iter = Vec::new();
        let mut k = 1;
        while k <= run.iterations {
            if let Ok(r) = cfg.reconstruct(&cloud, &Budget::iterations(k), &Start::Cold) {
                if let Ok(s) = score(&r.mesh, &gt, samples, eval_seed) {
                    per_iter.push((k, s.chamfer_l1));
                }
            }
            k += stride;
        }
        log(&format!(
            "adaptive {mode}: {} iterations, CD {}, {:.0} ms",
            run.iterations,
            run.scores
                .map_or("-".into(), |s| format!("{:.4}", s.chamfer_l1)),
            run.time_ms
        ));
        rows.push(AdaptiveRow {
            mode: mode.to_string(),
            run,
            chamfer_per_iteration: per_iter,
            eta_per_iteration: eta,
        });
    }
    Ok(Adaptive { shape: name, rows })
}

/// Feature combinations of the attribute ablation: (label, spatial weight, attributes).
fn ablation_features(quick: bool) -> Vec<(&'static str, f64, Vec<&'static str>)> {
    let all = vec![
        ("spatial", 1.0, vec![]),
        ("intensity", 0.0, vec!["intensity"]),
        ("density", 0.0, vec!["density"]),
        ("spatial+intensity", 1.0, vec!["intensity"]),
        ("spatial+density", 1.0, vec!["density"]),
        ("intensity+density", 0.0, vec!["intensity", "density"]),
        (
            "spatial+intensity+density",
            1.0,
            vec!["intensity", "density"],
        ),
    ];
    if quick {
        all.into_iter()
            .filter(|f| f.0 == "spatial" || f.0 == "spatial+intensity")
            .collect()
    } else {
        all
    }
}

fn ablation(
    opts: &BenchOptions,
    log: &mut dyn FnMut(&str),
) -> Result<Vec<AblationRow>, BenchError> {
    let shape_names: &[&str] = if opts.quick {
        &["sphere"]
    } else {
        &["sphere", "bottle", "rounded_box"]
    };
    let sigmas: &[f64] = if opts.quick { &[0.025] } else { &[0.01, 0.025] };
    let mut out = Vec::new();
    for &name in shape_names {
        let gt = shapes::by_name(name, 96)?.mesh;
        let surface = sample(
            &gt,
            opts.points(),
            seed_for(opts.seed, &format!("ablation/{name}")),
            name,
        )?;
        for &sigma in sigmas {
            let key = format!("ablation/{name}/{sigma}");
            let cloud =
                clouds::coloured_with_dark_outliers(&surface, sigma, &mut rng_for(opts.seed, &key));
            for (label, spatial, attrs) in ablation_features(opts.quick) {
                let mut cfg = opts.membrane.clone();
                cfg.step.spatial_weight = spatial;
                cfg.step.attributes = attrs
                    .iter()
                    .map(|a| membrane::AttributeWeight {
                        name: (*a).to_string(),
                        weight: 1.0,
                    })
                    .collect();
                let run = run_one(
                    &cloud,
                    &Membrane::new(cfg)?,
                    &Budget::unlimited(),
                    Some(&gt),
                    opts.metric_samples(),
                    seed_for(opts.seed, &format!("eval/{key}")),
                );
                log(&format!(
                    "ablation {name} σ={sigma} {label}: F {}",
                    run.scores
                        .map_or("-".into(), |s| format!("{:.3}", s.fscore))
                ));
                out.push(AblationRow {
                    shape: name.to_string(),
                    sigma,
                    features: label.to_string(),
                    run,
                });
            }
        }
    }
    Ok(out)
}

fn real(opts: &BenchOptions, skipped: &mut Vec<Skip>, log: &mut dyn FnMut(&str)) -> Vec<RealRow> {
    let mut out = Vec::new();
    let Some(d) = &opts.datasets else {
        skipped.push(Skip {
            what: "real".into(),
            reason: "shared datasets not found".into(),
        });
        return out;
    };
    let mut jobs: Vec<(String, Option<String>)> = vec![(
        "pcl_test_data/bunny.pcd".into(),
        Some("meshes_ground_truth/common_3d_test_models/stanford-bunny.obj".into()),
    )];
    if !opts.quick {
        let mut files = Vec::new();
        collect_files(
            &d.join("mosd_tabletop_segmentation/extracted_objects"),
            &mut files,
        );
        files.sort();
        jobs.extend(files.iter().filter_map(|f| {
            let rel = f.strip_prefix(d).ok()?.display().to_string();
            rel.ends_with(".pcd").then_some((rel, None))
        }));
    }
    let engine = match Membrane::new(opts.membrane.clone()) {
        Ok(e) => e,
        Err(e) => {
            skipped.push(Skip {
                what: "real".into(),
                reason: format!("invalid membrane configuration: {e}"),
            });
            return Vec::new();
        }
    };
    for (input, reference) in jobs {
        let cloud = match crate::io::load_cloud(d.join(&input)) {
            Ok(c) => c.cloud,
            Err(e) => {
                skipped.push(Skip {
                    what: input,
                    reason: format!("unreadable: {e}"),
                });
                continue;
            }
        };
        let gt = match &reference {
            Some(r) => match crate::io::load_mesh(d.join(r)) {
                Ok(m) => Some(m.mesh),
                Err(e) => {
                    skipped.push(Skip {
                        what: r.clone(),
                        reason: format!(
                            "reference unreadable ({e}); scan reported without ground truth"
                        ),
                    });
                    None
                }
            },
            None => None,
        };
        let run = run_one(
            &cloud,
            &engine,
            &Budget::unlimited(),
            gt.as_ref(),
            opts.metric_samples(),
            seed_for(opts.seed, &format!("eval/{input}")),
        );
        log(&format!(
            "real {input}: η_g {:.3}, {:.0} ms",
            run.eta_final, run.time_ms
        ));
        out.push(RealRow {
            input,
            reference,
            points: cloud.len(),
            run,
        });
    }
    out
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    if v.is_empty() {
        f64::NAN
    } else {
        v[v.len() / 2]
    }
}

/// Iteration cap of a warm frame (the pipeline's `warm_max_iterations` default).
pub const WARM_MAX_ITERATIONS: usize = 6;

fn phases_of(reports: &[membrane::Report]) -> Vec<(String, f64)> {
    let phase = |f: fn(&membrane::PhaseTimes) -> f64| {
        let mut v: Vec<f64> = reports.iter().map(|r| f(&r.times)).collect();
        median(&mut v)
    };
    vec![
        ("prepare".to_string(), phase(|t| t.prepare_ms)),
        ("init".to_string(), phase(|t| t.init_ms)),
        ("search".to_string(), phase(|t| t.search_ms)),
        ("fit".to_string(), phase(|t| t.fit_ms)),
        ("mesh".to_string(), phase(|t| t.mesh_ms)),
        ("other pole axes".to_string(), phase(|t| t.other_axes_ms)),
        ("total (report)".to_string(), phase(|t| t.total_ms)),
    ]
}

fn speed(
    opts: &BenchOptions,
    skipped: &mut Vec<Skip>,
    log: &mut dyn FnMut(&str),
) -> Result<Speed, BenchError> {
    let name = "rounded_box";
    let gt = shapes::rounded_box(96)?.mesh;
    let n = opts.points();
    let surface = sample(&gt, n, seed_for(opts.seed, "speed"), name)?;
    let cloud = PointCloud::from_points(surface.clone());
    let mut serial = opts.membrane.clone();
    serial.step.threads = 1;
    let cfg = Membrane::new(serial)?;
    let repeats = if opts.quick { 3 } else { 9 };
    let mut totals = Vec::new();
    let mut reports = Vec::new();
    let mut last = None;
    // One untimed run first: the membrane's factorisation cache is filled
    // once per grid size (as in a running node); every timed run is cold
    // (no warm start).
    for r in 0..=repeats {
        let t = Instant::now();
        match cfg.reconstruct(&cloud, &Budget::unlimited(), &Start::Cold) {
            Ok(rec) => {
                if r > 0 {
                    totals.push(t.elapsed().as_secs_f64() * 1e3);
                    reports.push(rec.report.clone());
                }
                last = Some(rec);
            }
            Err(e) => {
                skipped.push(Skip {
                    what: "speed".into(),
                    reason: format!("reconstruction failed: {e}"),
                });
                return Ok(Speed::default());
            }
        }
    }
    let phases = phases_of(&reports);
    let min_ms = totals.iter().copied().fold(f64::INFINITY, f64::min);
    let max_ms = totals.iter().copied().fold(0.0, f64::max);
    let median_ms = median(&mut totals);
    let iterations = reports.first().map_or(0, |r| r.iterations);
    log(&format!(
        "speed {name} {n} points: cold median {median_ms:.1} ms over {repeats}"
    ));

    // Warm frames.
    let frames = if opts.quick { 5 } else { 40 };
    let mut warm_ms = Vec::new();
    let mut warm_reports = Vec::new();
    let mut warm_f = Vec::new();
    let step = 0.01 * Aabb::from_points(&surface).longest_edge();
    for f in 0..frames {
        let Some(prev) = last.as_ref() else { break };
        let off = if f % 2 == 0 {
            Vec3::new(step, 0.5 * step, 0.0)
        } else {
            Vec3::zeros()
        };
        let moved = PointCloud::from_points(surface.iter().map(|p| p + off).collect());
        let ws = prev.warm_start();
        let t = Instant::now();
        match cfg.reconstruct(
            &moved,
            &Budget::iterations(WARM_MAX_ITERATIONS),
            &Start::Warm(ws),
        ) {
            Ok(rec) => {
                warm_ms.push(t.elapsed().as_secs_f64() * 1e3);
                if f < 3 {
                    let mut g = gt.clone();
                    for v in &mut g.vertices {
                        *v += off;
                    }
                    if let Ok(sc) = score(&rec.mesh, &g, opts.metric_samples(), 5) {
                        warm_f.push(sc.fscore);
                    }
                }
                warm_reports.push(rec.report.clone());
                last = Some(rec);
            }
            Err(e) => {
                skipped.push(Skip {
                    what: "speed (warm)".into(),
                    reason: format!("reconstruction failed: {e}"),
                });
                break;
            }
        }
    }
    let warm = (!warm_ms.is_empty()).then(|| {
        let mut its: Vec<f64> = warm_reports.iter().map(|r| r.iterations as f64).collect();
        let mut sorted = warm_ms.clone();
        sorted.sort_by(f64::total_cmp);
        let p95 = sorted[((sorted.len() as f64 * 0.95).ceil() as usize).clamp(1, sorted.len()) - 1];
        let w = WarmSpeed {
            frames: warm_ms.len(),
            max_iterations: WARM_MAX_ITERATIONS,
            median_ms: median(&mut warm_ms.clone()),
            p95_ms: p95,
            max_ms: sorted.last().copied().unwrap_or(0.0),
            phases: phases_of(&warm_reports),
            iterations: median(&mut its),
            fscore: median(&mut warm_f),
        };
        log(&format!(
            "speed {name} {n} points: warm median {:.1} ms, p95 {:.1} ms over {} frames",
            w.median_ms, w.p95_ms, w.frames
        ));
        w
    });
    Ok(Speed {
        shape: name.into(),
        points: n,
        repeats,
        median_ms,
        min_ms,
        max_ms,
        phases,
        iterations,
        warm,
    })
}

/// Run the selected sections. `log` receives one progress line per run.
///
/// # Errors
/// [`BenchError`] for a broken selection, shape or sampling; failed
/// reconstructions are recorded in their rows instead.
pub fn run(opts: &BenchOptions, log: &mut dyn FnMut(&str)) -> Result<BenchReport, BenchError> {
    let known: Vec<&'static str> = shapes::NAMES.to_vec();
    for o in opts.shape_filter() {
        // Shape names of loaded meshes end in an extension; anything else must be procedural.
        if !known.contains(&o) && !o.contains('.') {
            return Err(BenchError::UnknownSelection(o.to_string()));
        }
    }
    let t0 = Instant::now();
    let mut rep = BenchReport {
        quick: opts.quick,
        seed: opts.seed,
        threads: opts.membrane.step.threads,
        ..Default::default()
    };
    let mut skipped = Vec::new();
    if opts.section_selected("table1") {
        rep.table1 = Some(table1(opts, &mut skipped, log)?);
    }
    if opts.section_selected("sweep") {
        rep.sweep = Some(sweep(opts, log)?);
    }
    if opts.section_selected("adaptive") {
        rep.adaptive = Some(adaptive(opts, log)?);
    }
    if opts.section_selected("ablation") {
        rep.ablation = Some(ablation(opts, log)?);
    }
    if opts.section_selected("real") {
        rep.real = Some(real(opts, &mut skipped, log));
    }
    if opts.section_selected("speed") {
        rep.speed = Some(speed(opts, &mut skipped, log)?);
    }
    if opts.section_selected(mechanisms::SECTION) {
        rep.mechanisms = Some(mechanisms::run(opts, &mut skipped, log)?);
    }
    rep.skipped = skipped;
    rep.total_s = t0.elapsed().as_secs_f64();
    Ok(rep)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ground_truth_scores_perfectly_against_itself_and_a_shifted_copy_does_not() {
        let gt = shapes::sphere(64).unwrap().mesh;
        let s = score(&gt, &gt, METRIC_SAMPLES, 5).unwrap();
        assert!(s.fscore > 0.99, "{s:?}");
        assert!(s.chamfer_l1 < 0.005, "{s:?}");
        assert!(s.normal_consistency > 0.99, "{s:?}");
        // Shifted by 3 % of the size: most samples fall outside τ = 1 %.
        let mut moved = gt.clone();
        for v in &mut moved.vertices {
            v.x += 0.03;
        }
        let m = score(&moved, &gt, METRIC_SAMPLES, 5).unwrap();
        assert!(m.fscore < 0.6, "{m:?}");
        assert!(m.chamfer_l1 > 0.01, "{m:?}");
    }

    fn row(shape: &str, genus: u32, c: Condition, f: Option<f64>) -> Table1Row {
        Table1Row {
            shape: shape.into(),
            genus,
            condition: c,
            points: 10,
            run: RunResult {
                scores: f.map(|f| Scores {
                    chamfer_l1: 1.0 - f,
                    fscore: f,
                    normal_consistency: f,
                }),
                time_ms: 10.0,
                iterations: 1,
                eta_final: 0.5,
                grid: [8, 5],
                watertight: true,
                stop: "converged".into(),
                error: None,
            },
        }
    }

    #[test]
    fn summaries_average_per_condition_and_keep_genus_apart() {
        let rows = vec![
            row("a", 0, Condition::Original, Some(1.0)),
            row("b", 0, Condition::Original, Some(0.5)),
            row("a", 0, Condition::Noise, None),
            row("t", 1, Condition::Original, Some(0.2)),
        ];
        let g0 = summaries(&rows, false);
        assert_eq!(g0.len(), 5);
        assert_eq!(g0[0].group, "original");
        assert!((g0[0].fscore - 0.75).abs() < 1e-12);
        assert_eq!(g0[1].failed, 1);
        assert!(g0[1].fscore.is_nan());
        let overall = g0.last().unwrap();
        assert_eq!((overall.rows, overall.failed), (3, 1));
        let gp = summaries(&rows, true);
        assert!((gp.last().unwrap().fscore - 0.2).abs() < 1e-12);
    }

    #[test]
    fn open_ground_truth_meshes_are_skipped_with_a_reason() {
        let dir = tempfile::tempdir().unwrap();
        let closed = shapes::torus(16).unwrap().mesh;
        let mut open = shapes::sphere(16).unwrap().mesh;
        open.triangles.truncate(open.triangles.len() - 3);
        crate::io::save_mesh(dir.path().join("closed.obj"), &closed).unwrap();
        crate::io::save_mesh(dir.path().join("open.obj"), &open).unwrap();
        std::fs::write(dir.path().join("notes.txt"), "not a mesh").unwrap();
        let mut skipped = Vec::new();
        let got = load_gt_meshes(dir.path(), &mut skipped);
        assert_eq!(got.len(), 1);
        assert_eq!(got[0].name, "closed.obj");
        assert_eq!(got[0].genus, 1);
        assert!((got[0].mesh.aabb().longest_edge() - 1.0).abs() < 1e-9);
        assert_eq!(skipped.len(), 1);
        assert!(
            skipped[0].reason.contains("not watertight"),
            "{:?}",
            skipped[0]
        );
    }

    #[test]
    fn the_mechanism_ablation_runs_only_when_named() {
        let mut o = BenchOptions::new(true, None).unwrap();
        assert!(o.section_selected("table1"));
        assert!(!o.section_selected(mechanisms::SECTION));
        o.only = vec![mechanisms::SECTION.into(), "sphere".into()];
        assert!(o.section_selected(mechanisms::SECTION));
        assert!(!o.section_selected("table1"));
        assert_eq!(o.shape_filter(), ["sphere"]);
    }

    #[test]
    fn unknown_selection_is_an_error() {
        let mut o = BenchOptions::new(true, None).unwrap();
        o.only = vec!["teapot".into()];
        assert!(matches!(
            run(&o, &mut |_| {}),
            Err(BenchError::UnknownSelection(_))
        ));
    }
}
