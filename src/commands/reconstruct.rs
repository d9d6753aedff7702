//! `sepmem reconstruct`: one point cloud in, one watertight membrane mesh out.

use anyhow::{Context, Result};
use sepmem::config::Config;
use sepmem::membrane::{reconstruct, Budget};
use std::path::Path;
use std::time::Duration;

/// Load `input`, run the membrane with the merged configuration, write `output`
/// and print one summary line.
pub fn run(
    input: &Path,
    output: &Path,
    config: Option<&Path>,
    set: &[String],
    report: Option<&Path>,
    snapshot: Option<&Path>,
) -> Result<()> {
    let cfg = Config::load(config, set).context("loading configuration")?;
    sepmem::io::check_output(output, sepmem::io::OutputKind::Mesh)
        .context("checking the output path before reconstructing")?;
    let loaded = sepmem::io::load_cloud(input)
        .with_context(|| format!("reading point cloud {}", input.display()))?;
    let read_dropped = loaded.report.dropped_non_finite;
    let mcfg = &cfg.membrane;
    let budget = match mcfg.schedule.time_limit_ms {
        Some(ms) => Budget::within(Duration::from_secs_f64(ms / 1e3)),
        None => Budget::unlimited(),
    };
    let rec = reconstruct(&loaded.cloud, mcfg, &budget, None)
        .with_context(|| format!("reconstructing {}", input.display()))?;
    sepmem::io::save_mesh(output, &rec.mesh)
        .with_context(|| format!("writing mesh {}", output.display()))?;
    let r = &rec.report;
    if let Some(path) = report {
        let text = serde_json::to_string_pretty(r)?;
        std::fs::write(path, text).with_context(|| format!("writing report {}", path.display()))?;
    }
    if let Some(png) = snapshot {
        let caption = format!(
            "{}: {} points, {} iterations",
            input.display(),
            r.points_used,
            r.iterations
        );
        super::pictures::reconstruct_snapshot(
            png,
            &rec.mesh,
            &loaded.cloud.points,
            r.viewpoint,
            &caption,
        )?;
    }
    let t = &r.times;
    println!(
        "{}: points in {} used {} dropped {} (non-finite {}, duplicates {}, detached {}, outliers {}); grid {}x{}; iterations {}; eta_g {:.4}; stop {}; {:.1} ms (prepare {:.1}, init {:.1}, search {:.1}, fit {:.1}, mesh {:.1}, other pole axes {:.1}; pole axis {} of {} tried) -> {}",
        input.display(),
        r.points_in + read_dropped,
        r.points_used,
        read_dropped
            + r.points_non_finite
            + r.points_duplicate
            + r.points_detached
            + r.points_outliers,
        read_dropped + r.points_non_finite,
        r.points_duplicate,
        r.points_detached,
        r.points_outliers,
        r.grid[0],
        r.grid[1],
        r.iterations,
        r.eta_final,
        r.stop,
        t.total_ms,
        t.prepare_ms,
        t.init_ms,
        t.search_ms,
        t.fit_ms,
        t.mesh_ms,
        t.other_axes_ms,
        ["x", "y", "z"][r.pole_axis.min(2)],
        r.pole_axes_tried,
        output.display(),
    );
    Ok(())
}
