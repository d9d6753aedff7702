//! `sepmem replay`: run the frame pipeline over every PointCloud2 of a bag,
//! deterministically, with no network, as fast as possible.

use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use sepmem::bag::{Bag, BagWriter};
use sepmem::config::Config;
use sepmem::pipeline::engine::Engine;
use sepmem::pipeline::outputs;
use sepmem::pipeline::StartPath;
use sepmem::transport::keys::expand_topic_template;
use std::io::IsTerminal;
use std::path::Path;

const POINTCLOUD2: &str = "sensor_msgs/msg/PointCloud2";

/// Latency percentile (nearest rank) of sorted values.
pub fn percentile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let rank = ((q * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len());
    sorted[rank - 1]
}

/// Replay `bag`, optionally writing an output bag and restricting topics.
pub fn run(
    bag_path: &Path,
    out: Option<&Path>,
    topics: &[String],
    cfg: &Config,
    quiet: bool,
) -> Result<()> {
    run_with(
        bag_path,
        Outputs {
            bag: out,
            meshes: None,
        },
        topics,
        cfg,
        quiet,
    )
}

/// Where a replay writes its results.
#[derive(Debug, Clone, Copy, Default)]
pub struct Outputs<'a> {
    /// Output bag with the mesh, marker and diagnostics topics.
    pub bag: Option<&'a Path>,
    /// Folder receiving one binary PLY mesh per stream and frame.
    pub meshes: Option<&'a Path>,
}

/// Replay `bag` into the given outputs.
pub fn run_with(
    bag_path: &Path,
    outputs_to: Outputs<'_>,
    topics: &[String],
    cfg: &Config,
    quiet: bool,
) -> Result<()> {
    let out = outputs_to.bag;
    if let Some(dir) = outputs_to.meshes {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let bag = Bag::open(bag_path).with_context(|| format!("opening bag {}", bag_path.display()))?;
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
    let mut writer = out
        .map(|p| {
            BagWriter::create(p).with_context(|| format!("creating output bag {}", p.display()))
        })
        .transpose()?;
    let mut engine = Engine::new(cfg.membrane.clone(), cfg.pipeline.clone(), cfg.wire.clone());
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
    print(format!(
        "{:<32} {:>5} {:>7} {:<5} {:<22} {:>4} {:>6} {:>8}",
        "stream", "frame", "points", "path", "reason", "it", "eta_g", "ms"
    ));
    let (mut latencies, mut warm_it, mut cold_it) = (Vec::new(), Vec::new(), Vec::new());
    let (mut bad_samples, mut failed) = (0usize, 0usize);
    for m in &messages {
        bar.inc(1);
        let (sample, processed) = match engine.handle(&m.topic, &m.data) {
            Ok(x) => x,
            Err(e) => {
                bad_samples += 1;
                print(format!("skipped sample: {e}"));
                continue;
            }
        };
        let mut ok = Vec::new();
        for pr in &processed {
            match &pr.outcome {
                Ok(r) => {
                    latencies.push(r.latency_ms);
                    match r.path {
                        StartPath::Warm => warm_it.push(r.iterations as f64),
                        StartPath::Cold => cold_it.push(r.iterations as f64),
                    }
                    print(format!(
                        "{:<32} {:>5} {:>7} {:<5} {:<22} {:>4} {:>6.3} {:>8.1}",
                        pr.key.to_string(),
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
                    ));
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
                    ok.push(r);
                }
                Err(e) => {
                    failed += 1;
                    print(format!("{:<32} error: {e}", pr.key.to_string()));
                }
            }
        }
        if let Some(w) = writer.as_mut() {
            for r in &ok {
                w.write(
                    &expand_topic_template(&o.mesh, &m.topic),
                    m.log_time,
                    &outputs::surface_mesh(r, &sample.header),
                )?;
                w.write(
                    &expand_topic_template(&o.frame_diagnostics, &m.topic),
                    m.log_time,
                    &outputs::frame_diagnostics(
                        r,
                        &sample.header,
                        sample.points_in,
                        sample.dropped,
                    ),
                )?;
            }
            w.write(
                &expand_topic_template(&o.markers, &m.topic),
                m.log_time,
                &outputs::marker_array(&ok, &sample.header, &p.marker_namespace),
            )?;
        }
    }
    bar.finish_and_clear();
    latencies.sort_by(f64::total_cmp);
    let mean = |v: &[f64]| {
        if v.is_empty() {
            f64::NAN
        } else {
            v.iter().sum::<f64>() / v.len() as f64
        }
    };
    println!(
        "summary: {} samples, {} frames ok ({} warm, {} cold), {} failed, {} bad samples; latency ms p50 {:.1} p95 {:.1} max {:.1}; mean iterations warm {:.1} cold {:.1}",
        messages.len(),
        latencies.len(),
        warm_it.len(),
        cold_it.len(),
        failed,
        bad_samples,
        percentile(&latencies, 0.5),
        percentile(&latencies, 0.95),
        latencies.last().copied().unwrap_or(f64::NAN),
        mean(&warm_it),
        mean(&cold_it),
    );
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
