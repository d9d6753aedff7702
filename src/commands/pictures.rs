//! The pictures of `replay` (`--snapshots DIR`, `--plot FILE.png`),
//! `reconstruct` (`--snapshot FILE.png`) and `bench` (`sweep.png`,
//! `conditions.png`): glue between the commands' results and
//! [`sepmem::viz`], kept apart from the commands' own code paths.

use anyhow::{bail, Context, Result};
use sepmem::bench::BenchReport;
use sepmem::mesh::TriMesh;
use sepmem::viz::plot::{write_bars, write_lines, Bars, Panel, Series};
use sepmem::viz::snapshot::{write_snapshot, Scene};
use sepmem::Vec3;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// One reconstructed frame of a replay, as the pictures need it.
#[derive(Debug, Clone, Copy)]
pub struct FrameView<'a> {
    /// Stream id (`topic#label`).
    pub stream: &'a str,
    /// Frame number within the stream.
    pub frame: u64,
    /// The frame's mesh.
    pub mesh: &'a TriMesh,
    /// The frame's input points.
    pub points: &'a [Vec3],
    /// The posed ground truth, when the bag has it.
    pub truth: Option<&'a TriMesh>,
    /// The reconstruction's viewpoint.
    pub viewpoint: Option<[f64; 3]>,
    /// `(F, R_vis)` against the ground truth, when scored.
    pub score: Option<(f64, f64)>,
    /// Frame latency (ms).
    pub latency_ms: f64,
}

/// `(frame, F, R_vis, latency)` of one stream's frames.
type FramePoint = (f64, Option<(f64, f64)>, f64);
type Track = Vec<FramePoint>;

/// What `replay --snapshots/--plot` collect while the replay runs.
#[derive(Debug, Default)]
pub struct ReplayPictures {
    snapshots: Option<PathBuf>,
    plot: Option<PathBuf>,
    tracks: BTreeMap<String, Track>,
    written: usize,
}

impl ReplayPictures {
    /// Pictures into the folder `snapshots` (one PNG per stream and frame)
    /// and the plot file `plot`; either may be off.
    pub fn new(snapshots: Option<&Path>, plot: Option<&Path>) -> Result<Self> {
        if let Some(dir) = snapshots {
            std::fs::create_dir_all(dir)
                .with_context(|| format!("creating snapshot folder {}", dir.display()))?;
        }
        Ok(ReplayPictures {
            snapshots: snapshots.map(Path::to_path_buf),
            plot: plot.map(Path::to_path_buf),
            ..Default::default()
        })
    }

    /// Record one frame: write its snapshot, keep its figures for the plot.
    pub fn frame(&mut self, f: &FrameView<'_>) -> Result<()> {
        if let Some(dir) = &self.snapshots {
            let name = format!(
                "{}_{:04}.png",
                f.stream.trim_start_matches('/').replace(['/', '#'], "_"),
                f.frame
            );
            let caption = match f.score {
                Some((fs, rv)) => {
                    format!("{} frame {}: F {fs:.3}, R_vis {rv:.3}", f.stream, f.frame)
                }
                None => format!("{} frame {}", f.stream, f.frame),
            };
            let scene = Scene {
                mesh: f.mesh,
                points: f.points,
                truth: f.truth,
                viewpoint: f.viewpoint.map(Vec3::from),
                caption: &caption,
            };
            let path = dir.join(name);
            write_snapshot(&scene, &path)
                .with_context(|| format!("snapshot of {} frame {}", f.stream, f.frame))?;
            self.written += 1;
        }
        if self.plot.is_some() {
            self.tracks.entry(f.stream.to_string()).or_default().push((
                f.frame as f64,
                f.score,
                f.latency_ms,
            ));
        }
        Ok(())
    }

    /// Write the plot; say what was written.
    pub fn finish(self) -> Result<()> {
        if let Some(dir) = &self.snapshots {
            println!("wrote {} snapshots to {}", self.written, dir.display());
        }
        let Some(path) = &self.plot else {
            return Ok(());
        };
        if self.tracks.is_empty() {
            bail!(
                "no frame was reconstructed: nothing to plot in {}",
                path.display()
            );
        }
        write_lines(&replay_panels(&self.tracks), path)
            .with_context(|| format!("plotting {}", path.display()))?;
        println!("wrote {}", path.display());
        Ok(())
    }
}

/// F and R_vis per frame (when scored), then latency per frame.
fn replay_panels(tracks: &BTreeMap<String, Track>) -> Vec<Panel> {
    let series =
        |name: &str, id: &str, pick: &dyn Fn(&FramePoint) -> Option<f64>, t: &Track| Series {
            label: format!("{name} {id}"),
            points: t.iter().filter_map(|p| pick(p).map(|y| (p.0, y))).collect(),
        };
    let mut quality = Vec::new();
    let mut latency = Vec::new();
    for (id, t) in tracks {
        if t.iter().any(|p| p.1.is_some()) {
            quality.push(series("F", id, &|p| p.1.map(|s| s.0), t));
            quality.push(series("R_vis", id, &|p| p.1.map(|s| s.1), t));
        }
        latency.push(series("latency", id, &|p| Some(p.2), t));
    }
    let mut panels = Vec::new();
    if !quality.is_empty() {
        panels.push(Panel {
            title: "F-score and seen-side accuracy (visible recall R_vis) per frame".into(),
            x_label: "frame".into(),
            y_label: "F, R_vis".into(),
            y_range: Some((0.0, 1.02)),
            series: quality,
        });
    }
    panels.push(Panel {
        title: "frame latency".into(),
        x_label: "frame".into(),
        y_label: "ms".into(),
        y_range: None,
        series: latency,
    });
    panels
}

/// `reconstruct --snapshot`: the mesh and its input points.
pub fn reconstruct_snapshot(
    path: &Path,
    mesh: &TriMesh,
    points: &[Vec3],
    viewpoint: Option<[f64; 3]>,
    caption: &str,
) -> Result<()> {
    let scene = Scene {
        mesh,
        points,
        truth: None,
        viewpoint: viewpoint.map(Vec3::from),
        caption,
    };
    write_snapshot(&scene, path).with_context(|| format!("writing snapshot {}", path.display()))
}

/// Peers' F-scores per input condition: method → condition → F.
pub type Peers = BTreeMap<String, BTreeMap<String, f64>>;

/// Read a peers file (JSON: `{"method": {"condition": F, ...}, ...}`), the
/// conditions named as in `bench.json` (`original`, `noise`,
/// `region_outliers`, `surface_outliers`).
pub fn load_peers(path: &Path) -> Result<Peers> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("reading peers {}", path.display()))?;
    let peers: Peers = serde_json::from_str(&text).with_context(|| {
        format!(
            "parsing peers {} (expected {{\"method\": {{\"condition\": F}}}})",
            path.display()
        )
    })?;
    let known = sepmem::bench::clouds::Condition::ALL.map(|c| c.name());
    for (method, by) in &peers {
        if let Some(bad) = by.keys().find(|c| !known.contains(&c.as_str())) {
            bail!(
                "peers {}: method {method:?} names unknown condition {bad:?} (known: {})",
                path.display(),
                known.join(", ")
            );
        }
    }
    Ok(peers)
}

/// `bench`'s plots into `out`: the sphere sweep and the F-score per input
/// condition (with the peers' figures when given). Returns the files written.
pub fn bench_plots(
    report: &BenchReport,
    peers: Option<&Peers>,
    out: &Path,
) -> Result<Vec<PathBuf>> {
    let mut written = Vec::new();
    if let Some(rows) = report.sweep.as_ref().filter(|r| !r.is_empty()) {
        let pick = |g: fn(&sepmem::bench::Scores) -> f64| -> Vec<(f64, f64)> {
            rows.iter()
                .filter_map(|r| r.run.scores.as_ref().map(|s| (r.sigma, g(s))))
                .collect()
        };
        let panel = |title: &str, y: &str, label: &str, points| Panel {
            title: title.into(),
            x_label: "σ of the perturbed duplicates".into(),
            y_label: y.into(),
            y_range: None,
            series: vec![Series {
                label: label.into(),
                points,
            }],
        };
        let panels = [
            panel("sphere sweep: F-score", "F", "sepmem", pick(|s| s.fscore)),
            panel(
                "sphere sweep: Chamfer-L1",
                "Chamfer-L1",
                "sepmem",
                pick(|s| s.chamfer_l1),
            ),
        ];
        let path = out.join("sweep.png");
        write_lines(&panels, &path).with_context(|| format!("plotting {}", path.display()))?;
        written.push(path);
    }
    if let Some(t1) = &report.table1 {
        let bars = condition_bars(t1, peers);
        if bars
            .series
            .iter()
            .any(|(_, v)| v.iter().any(Option::is_some))
        {
            let path = out.join("conditions.png");
            write_bars(&bars, &path).with_context(|| format!("plotting {}", path.display()))?;
            written.push(path);
        }
    }
    Ok(written)
}

/// Table 1's mean F-score per condition (genus 0, and genus > 0 when
/// measured), then each peer's.
fn condition_bars(t1: &sepmem::bench::Table1, peers: Option<&Peers>) -> Bars {
    let conditions = sepmem::bench::clouds::Condition::ALL.map(|c| c.name());
    let ours = |sums: &[sepmem::bench::Summary]| -> Vec<Option<f64>> {
        conditions
            .iter()
            .map(|c| {
                sums.iter()
                    .find(|s| s.group == *c && s.rows > s.failed)
                    .map(|s| s.fscore)
            })
            .collect()
    };
    let mut series = vec![("sepmem (genus 0)".to_string(), ours(&t1.genus0))];
    if t1.genus_pos.iter().any(|s| s.rows > s.failed) {
        series.push(("sepmem (genus > 0)".to_string(), ours(&t1.genus_pos)));
    }
    for (method, by) in peers.into_iter().flatten() {
        series.push((
            method.clone(),
            conditions.iter().map(|c| by.get(*c).copied()).collect(),
        ));
    }
    Bars {
        title: "Table 1: F-score per input condition".into(),
        y_label: "F-score (τ = 0.01)".into(),
        groups: conditions.iter().map(|c| c.to_string()).collect(),
        series,
    }
}
