//! `sepmem eval`: score a predicted mesh against a ground-truth mesh with the
//! ONet / Shape-as-Points protocol (Chamfer-L1/L2, F-score at τ, normal
//! consistency), see [`sepmem::metrics`].

use anyhow::{Context, Result};
use sepmem::config::Config;
use std::path::Path;

/// Load both meshes, evaluate and print the scores (one `key value` line
/// each, or one JSON object with `json`).
pub fn run(
    pred: &Path,
    gt: &Path,
    config: Option<&Path>,
    set: &[String],
    json: bool,
) -> Result<()> {
    let cfg = Config::load(config, set).context("loading configuration")?;
    let p = sepmem::io::load_mesh(pred)
        .with_context(|| format!("reading predicted mesh {}", pred.display()))?;
    let g = sepmem::io::load_mesh(gt)
        .with_context(|| format!("reading ground-truth mesh {}", gt.display()))?;
    let m = sepmem::metrics::evaluate(&p.mesh, &g.mesh, &cfg.metrics)
        .with_context(|| format!("evaluating {} against {}", pred.display(), gt.display()))?;
    if json {
        println!("{}", serde_json::to_string(&m)?);
        return Ok(());
    }
    println!("pred                {}", pred.display());
    println!("gt                  {}", gt.display());
    println!("samples             {}", m.samples);
    println!("tau                 {}", m.tau);
    println!("chamfer_l1          {:.6}", m.chamfer_l1);
    println!("chamfer_l2          {:.8}", m.chamfer_l2);
    println!("accuracy            {:.6}", m.accuracy);
    println!("completeness        {:.6}", m.completeness);
    println!("precision           {:.4}", m.precision);
    println!("recall              {:.4}", m.recall);
    println!("fscore              {:.4}", m.fscore);
    println!("normal_consistency  {:.4}", m.normal_consistency);
    if m.empty_prediction {
        println!("note                the prediction has no surface (F = 0)");
    }
    Ok(())
}
