//! `sepmem bench --only ablation-mechanisms`: does every optional mechanism
//! earn its place (issue 19, item 4)?
//!
//! The baseline configuration and, in turn, the baseline with one optional
//! mechanism switched ([`MECHANISMS`]: an `Option` set to `null`, a bool to
//! `false`, a method to its plain variant; a mechanism that is off by
//! default is switched *on*) are measured on four figures:
//!
//! - the overall mean F of Table 1's genus-0 and genus > 0 shapes (the
//!   [`super::table1`] code path: the same shapes, the paper's four
//!   conditions, the same clouds and seeds as the `table1` section, so the
//!   baseline row is the `table1` section's figure), and the mean F of its
//!   non-uniform condition over every shape;
//! - the mean F of the sphere sweep ([`super::sweep`], its six σ);
//! - the mean F of nine synth replays ([`replay_specs`]: ellipsoid, bottle
//!   and mug turning in place and orbited by the camera, and the three pairs
//!   swapped on one stream; 6 frames of about 2,500 points each, Kinect
//!   noise, mesh resolution 48), written in-process by
//!   [`crate::synth::sequence`] and scored frame by frame by
//!   [`crate::eval::replay_scored`] as `sepmem replay` scores them (no
//!   deadline: deterministic). The figure is the mean over the sequences of
//!   each sequence's mean frame F.
//!
//! Each row gives ΔF = F(switched) − F(baseline) per figure. A mechanism
//! whose switch moves no figure by more than [`THRESHOLD`] is a candidate for
//! removal (unless a committed measurement on another input shows it is
//! needed). With the shared datasets the full run is 18 configurations ×
//! (Table 1: 18 shapes × 5 conditions at 20,000 points; 6 sweep runs; 54
//! replay frames), about 30 min niced on two shared cores. `--quick` uses
//! the quick Table 1 (sphere and torus, 5,000 points), the sweep and one
//! replay (ellipsoid turning, 2 frames).
//!
//! Not in the default run (it repeats Table 1 seventeen times): only when
//! named in `--only`.

use super::clouds::Condition;
use super::{sweep, table1, BenchError, BenchOptions, Skip, SweepRow, Table1};
use crate::config::Config;
use crate::eval::replay_scored;
use crate::synth::sequence::{write_sequence, SceneMotion, SequenceSpec};
use crate::synth::Noise;
use serde::Serialize;
use std::path::PathBuf;

/// The section's key in `--only`.
pub const SECTION: &str = "ablation-mechanisms";

/// A mechanism whose switch moves no figure by more than this is a
/// candidate for removal.
pub const THRESHOLD: f64 = 0.003;

/// The optional mechanisms and the `--set` override that switches each.
/// Pure cost bounds (`prepare.max_points`, `schedule.time_limit_ms`,
/// `schedule.growth.max_control_per_point`, iteration caps) are not
/// mechanisms and are not switched.
pub const MECHANISMS: [&str; 20] = [
    "membrane.prepare.outlier_factor=null",
    // Off by default (global δ): switched on.
    "membrane.prepare.search_delta=local",
    "membrane.prepare.local_spacing=null",
    // membrane.prepare.density_sample is null by default; the pipeline's warm
    // frames use it (pipeline.warm_density_sample 256): 0 switches it off there.
    "pipeline.warm_density_sample=0",
    "membrane.init.pole_axis_candidates=1",
    "membrane.step.inside_denser=null",
    "membrane.step.significance=0",
    "membrane.step.sparse_warm_search=false",
    "membrane.step.sparse_cold_search=false",
    "membrane.step.inward=null",
    "membrane.regularize.median_filter=false",
    "membrane.regularize.pole_tension=null",
    "membrane.regularize.warm_back_smoothing=null",
    "membrane.fit.redistribute_stretch=null",
    "membrane.schedule.growth=null",
    "membrane.view.viewpoint=none",
    // Off by default ("none", null): switched on.
    "membrane.view.completion=mirror",
    "membrane.view.back={extent: 1.0}",
    // The tracker's mechanisms (they act on the synth replays only).
    "pipeline.icp_min_inliers=null",
    "pipeline.model=null",
];

/// The five figures of one configuration (mean F-scores).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Figures {
    /// Table 1, genus-0 shapes, overall mean F.
    pub table1_genus0: f64,
    /// Table 1, genus > 0 shapes, overall mean F.
    pub table1_genus_pos: f64,
    /// Table 1, the non-uniform condition, mean F over every shape.
    pub table1_non_uniform: f64,
    /// Mean F of the sphere sweep.
    pub sweep: f64,
    /// Mean over the synth replays of their mean frame F.
    pub replays: f64,
}

impl Figures {
    /// The figures as an array, in table order.
    pub fn values(&self) -> [f64; 5] {
        [
            self.table1_genus0,
            self.table1_genus_pos,
            self.table1_non_uniform,
            self.sweep,
            self.replays,
        ]
    }

    fn minus(&self, base: &Figures) -> Figures {
        Figures {
            table1_genus0: self.table1_genus0 - base.table1_genus0,
            table1_genus_pos: self.table1_genus_pos - base.table1_genus_pos,
            table1_non_uniform: self.table1_non_uniform - base.table1_non_uniform,
            sweep: self.sweep - base.sweep,
            replays: self.replays - base.replays,
        }
    }

    /// The largest |value| (NaN when any value is NaN).
    pub fn max_abs(&self) -> f64 {
        self.values().iter().fold(
            0.0,
            |m, v| if v.is_nan() { f64::NAN } else { m.max(v.abs()) },
        )
    }
}

/// One configuration of the mechanism ablation.
#[derive(Debug, Clone, Serialize)]
pub struct MechanismRow {
    /// The `--set` override (`baseline` for the baseline row).
    pub switch: String,
    /// Its five figures.
    pub figures: Figures,
    /// ΔF = F(switched) − F(baseline) per figure.
    pub delta: Figures,
    /// Runs or frames without a score (excluded from the means).
    pub failed: usize,
    /// No |ΔF| above [`THRESHOLD`]: a removal candidate.
    pub below_threshold: bool,
}

/// The mechanism ablation's results.
#[derive(Debug, Clone, Serialize, Default)]
pub struct Mechanisms {
    /// Points per Table 1 cloud.
    pub table1_points: usize,
    /// Table 1 shapes.
    pub table1_shapes: Vec<String>,
    /// The synth replays (`shapes/motion`) and their frames.
    pub replays: Vec<String>,
    /// Frames per replay.
    pub replay_frames: usize,
    /// [`THRESHOLD`].
    pub threshold: f64,
    /// The baseline first, then one row per switched mechanism.
    pub rows: Vec<MechanismRow>,
}

/// The synth replays: (name, spec).
pub fn replay_specs(quick: bool) -> Vec<(String, SequenceSpec)> {
    let spec = |shapes: &[&str], motion: SceneMotion, frames: usize| SequenceSpec {
        shapes: shapes.iter().map(|s| (*s).to_string()).collect(),
        frames,
        points_per_object: 2_500,
        motion,
        noise: Noise::kinect(),
        mesh_resolution: 48,
        seed: 19,
        ..SequenceSpec::default()
    };
    let name = |shapes: &[&str], motion: &str| format!("{}/{motion}", shapes.join("+"));
    if quick {
        let s = ["ellipsoid"];
        return vec![(
            name(&s, "turn"),
            spec(&s, SceneMotion::Turn { degrees: 60.0 }, 2),
        )];
    }
    let mut out = Vec::new();
    for shape in ["ellipsoid", "bottle", "mug"] {
        let s = [shape];
        out.push((
            name(&s, "turn"),
            spec(&s, SceneMotion::Turn { degrees: 60.0 }, 6),
        ));
        out.push((
            name(&s, "orbit"),
            spec(&s, SceneMotion::Orbit { degrees: 60.0 }, 6),
        ));
    }
    for pair in [
        ["ellipsoid", "bottle"],
        ["bottle", "mug"],
        ["mug", "ellipsoid"],
    ] {
        out.push((
            name(&pair, "swap"),
            spec(&pair, SceneMotion::Swap { degrees: 60.0 }, 6),
        ));
    }
    out
}

/// The replays' bags, written once into a private temporary folder that is
/// removed on drop.
struct ReplayBags {
    dir: PathBuf,
    bags: Vec<(String, crate::bag::Bag)>,
}

impl ReplayBags {
    fn write(quick: bool) -> Result<Self, BenchError> {
        let dir = std::env::temp_dir().join(format!("sepmem-ablation-{}", std::process::id()));
        let err = |what: &str, message: String| BenchError::Replay {
            what: what.to_string(),
            message,
        };
        std::fs::create_dir_all(&dir)
            .map_err(|e| err(&dir.display().to_string(), e.to_string()))?;
        let mut out = Self {
            dir,
            bags: Vec::new(),
        };
        for (k, (name, spec)) in replay_specs(quick).into_iter().enumerate() {
            let path = out.dir.join(format!("{k}.mcap"));
            write_sequence(&spec, &path, |_| {}).map_err(|e| err(&name, e.to_string()))?;
            let bag = crate::bag::Bag::open(&path).map_err(|e| err(&name, e.to_string()))?;
            out.bags.push((name, bag));
        }
        Ok(out)
    }
}

impl Drop for ReplayBags {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// Mean of the finite values and how many were not finite (NaN when none is).
fn mean_finite(values: impl IntoIterator<Item = f64>) -> (f64, usize) {
    let (mut sum, mut n, mut bad) = (0.0, 0usize, 0usize);
    for v in values {
        if v.is_finite() {
            sum += v;
            n += 1;
        } else {
            bad += 1;
        }
    }
    (if n == 0 { f64::NAN } else { sum / n as f64 }, bad)
}

/// Mean over the replays of their mean frame F, and the unscored frames.
fn replay_figure(bags: &ReplayBags, cfg: &Config) -> Result<(f64, usize), BenchError> {
    let mut failed = 0;
    let mut means = Vec::new();
    for (name, bag) in &bags.bags {
        let frames = replay_scored(bag, cfg, 0).map_err(|e| BenchError::Replay {
            what: name.clone(),
            message: e.to_string(),
        })?;
        let (m, bad) = mean_finite(
            frames
                .iter()
                .map(|f| f.score.map_or(f64::NAN, |s| s.fscore)),
        );
        failed += bad;
        means.push(m);
    }
    let (m, bad) = mean_finite(means);
    Ok((m, failed + bad))
}

/// The overall mean F of Table 1's genus-0 and genus > 0 shapes, the
/// failed runs among them, and the mean F of the non-uniform rows (every
/// genus; failed ones excluded).
fn table1_figures(t: &Table1) -> (f64, f64, usize, f64) {
    let overall = |s: &[super::Summary]| s.last().map_or((f64::NAN, 0), |o| (o.fscore, o.failed));
    let (g0, f0) = overall(&t.genus0);
    let (gp, fp) = overall(&t.genus_pos);
    let (nu, _) = mean_finite(
        t.rows
            .iter()
            .filter(|r| r.condition == Condition::NonUniform)
            .map(|r| r.run.scores.map_or(f64::NAN, |s| s.fscore)),
    );
    (g0, gp, f0 + fp, nu)
}

/// What one configuration measured.
struct Measured {
    figures: Figures,
    /// Runs or frames without a score.
    failed: usize,
    /// The Table 1 shapes.
    shapes: Vec<String>,
}

/// The four figures of `cfg`.
fn figures(
    opts: &BenchOptions,
    cfg: &Config,
    bags: &ReplayBags,
    skipped: &mut Vec<Skip>,
    log: &mut dyn FnMut(&str),
) -> Result<Measured, BenchError> {
    let variant = BenchOptions {
        membrane: cfg.membrane.clone(),
        ..opts.clone()
    };
    let t = table1(&variant, skipped, log)?;
    let (table1_genus0, table1_genus_pos, t_failed, table1_non_uniform) = table1_figures(&t);
    let rows: Vec<SweepRow> = sweep(&variant, log)?;
    let (sweep_f, s_failed) = mean_finite(
        rows.iter()
            .map(|r| r.run.scores.map_or(f64::NAN, |s| s.fscore)),
    );
    let (replays, r_failed) = replay_figure(bags, cfg)?;
    let mut shapes: Vec<String> = t.rows.iter().map(|r| r.shape.clone()).collect();
    shapes.dedup();
    Ok(Measured {
        figures: Figures {
            table1_genus0,
            table1_genus_pos,
            table1_non_uniform,
            sweep: sweep_f,
            replays,
        },
        failed: t_failed + s_failed + r_failed,
        shapes,
    })
}

/// The configuration every row starts from: the bench's membrane section
/// in the default configuration, without deadlines (as `sepmem replay`).
///
/// # Errors
/// [`BenchError::Config`] if the embedded configuration is broken.
pub fn baseline_config(opts: &BenchOptions) -> Result<Config, BenchError> {
    let mut cfg = Config::defaults()?;
    cfg.membrane = opts.membrane.clone();
    cfg.pipeline.deadline_ms = 0.0;
    Ok(cfg)
}

/// The mechanism ablation over `switches` (normally [`MECHANISMS`]).
///
/// # Errors
/// [`BenchError`] for a bad switch, an invalid switched configuration, or
/// a replay that fails.
pub fn ablate(
    opts: &BenchOptions,
    switches: &[&str],
    skipped: &mut Vec<Skip>,
    log: &mut dyn FnMut(&str),
) -> Result<Mechanisms, BenchError> {
    let base = baseline_config(opts)?;
    let bags = ReplayBags::write(opts.quick)?;
    let mut rows: Vec<MechanismRow> = Vec::new();
    let mut baseline = None;
    let mut shapes = Vec::new();
    for switch in std::iter::once("baseline").chain(switches.iter().copied()) {
        let cfg = if switch == "baseline" {
            base.clone()
        } else {
            base.with_sets(&[switch.to_string()])?
        };
        crate::membrane::Membrane::new(cfg.membrane.clone())?;
        // Only the baseline's skips are reported (the others repeat them).
        let mut own_skips = Vec::new();
        let sink = if switch == "baseline" {
            &mut *skipped
        } else {
            &mut own_skips
        };
        let m = figures(opts, &cfg, &bags, sink, &mut |l| {
            log(&format!("[{switch}] {l}"));
        })?;
        let f = m.figures;
        let base_f = *baseline.get_or_insert(f);
        if shapes.is_empty() {
            shapes = m.shapes;
        }
        let delta = f.minus(&base_f);
        log(&format!(
            "ablation-mechanisms {switch}: F {:.4} {:.4} {:.4} {:.4} {:.4}, ΔF {:+.4} {:+.4} {:+.4} {:+.4} {:+.4}",
            f.table1_genus0, f.table1_genus_pos, f.table1_non_uniform, f.sweep, f.replays,
            delta.table1_genus0, delta.table1_genus_pos, delta.table1_non_uniform, delta.sweep, delta.replays
        ));
        rows.push(MechanismRow {
            switch: switch.to_string(),
            figures: f,
            delta,
            failed: m.failed,
            below_threshold: delta.max_abs() <= THRESHOLD,
        });
    }
    Ok(Mechanisms {
        table1_points: opts.points(),
        table1_shapes: shapes,
        replays: bags.bags.iter().map(|(n, _)| n.clone()).collect(),
        replay_frames: replay_specs(opts.quick)
            .first()
            .map_or(0, |(_, s)| s.frames),
        threshold: THRESHOLD,
        rows,
    })
}

/// The section as `sepmem bench` runs it: every mechanism of [`MECHANISMS`].
///
/// # Errors
/// As [`ablate`].
pub fn run(
    opts: &BenchOptions,
    skipped: &mut Vec<Skip>,
    log: &mut dyn FnMut(&str),
) -> Result<Mechanisms, BenchError> {
    ablate(opts, &MECHANISMS, skipped, log)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_switch_changes_the_configuration_it_runs_with() {
        let opts = BenchOptions::new(true, None).unwrap();
        let base = baseline_config(&opts).unwrap();
        for switch in MECHANISMS {
            let cfg = base.with_sets(&[switch.to_string()]).unwrap();
            assert_ne!(cfg, base, "{switch} changes nothing");
            crate::membrane::Membrane::new(cfg.membrane.clone()).unwrap();
        }
        assert_eq!(base.with_sets(&[]).unwrap(), base);
    }

    #[test]
    fn the_baseline_row_is_the_table1_figure_and_a_switch_moves_it() {
        let opts = BenchOptions::new(true, None).unwrap();
        let mut skipped = Vec::new();
        let got = ablate(
            &opts,
            &["membrane.schedule.growth=null"],
            &mut skipped,
            &mut |_| {},
        )
        .unwrap();
        assert_eq!(got.rows.len(), 2);
        let (base, off) = (&got.rows[0], &got.rows[1]);
        assert_eq!(base.switch, "baseline");
        assert_eq!(base.delta.values(), [0.0; 5]);
        let plain = table1(&opts, &mut Vec::new(), &mut |_| {}).unwrap();
        let (g0, gp, failed, nu) = table1_figures(&plain);
        assert_eq!(failed, 0);
        assert_eq!(base.figures.table1_genus0, g0);
        assert_eq!(base.figures.table1_genus_pos, gp);
        assert_eq!(base.figures.table1_non_uniform, nu);
        assert_eq!(got.table1_shapes, ["sphere", "torus"]);
        assert!(
            base.figures.values().iter().all(|v| v.is_finite()),
            "{base:?}"
        );
        assert_eq!(base.failed, 0);
        eprintln!("{base:?}\n{off:?}");
        assert!(off.delta.table1_genus_pos < -THRESHOLD, "{off:?}");
        assert!(!off.below_threshold);
    }
}
