//! `sepmem node` and `sepmem play`: the live node and the bag player over zenoh.

use anyhow::{Context, Result};
use sepmem::config::Config;
use sepmem::node::player::{self, PlayOptions};
use sepmem::node::runtime::{self, NodeSummary};
use sepmem::transport::Participant;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// Resolves on SIGINT or SIGTERM.
pub async fn shutdown_signal() {
    #[cfg(unix)]
    {
        use tokio::signal::unix::{signal, SignalKind};
        match signal(SignalKind::terminate()) {
            Ok(mut term) => {
                tokio::select! {
                    _ = tokio::signal::ctrl_c() => {}
                    _ = term.recv() => {}
                }
            }
            Err(_) => {
                let _ = tokio::signal::ctrl_c().await;
            }
        }
    }
    #[cfg(not(unix))]
    {
        let _ = tokio::signal::ctrl_c().await;
    }
}

/// Print a node summary table.
pub fn print_summary(s: &NodeSummary) {
    println!(
        "{:<40} {:>7} {:>7} {:>6} {:>6} {:>6} {:>6} {:>8} {:>8}",
        "stream", "frames", "drops", "errors", "late", "warm", "cold", "p50 ms", "p95 ms"
    );
    let ms = |v: Option<f64>| v.map_or_else(|| "-".to_string(), |x| format!("{:.1}", x * 1e3));
    for t in &s.streams {
        println!(
            "{:<40} {:>7} {:>7} {:>6} {:>6} {:>6} {:>6} {:>8} {:>8}{}",
            t.topic,
            t.frames,
            t.drops,
            t.errors,
            t.late,
            t.warm,
            t.cold,
            ms(t.p50_s),
            ms(t.p95_s),
            if t.stale { "  (stale)" } else { "" }
        );
    }
    println!(
        "ignored samples: {} foreign keys, {} own outputs, {} other shard, {} over capacity, {} bad attachments; clean shutdown: {}",
        s.foreign_keys, s.own_outputs, s.other_shard, s.over_capacity, s.bad_attachments, s.clean_shutdown
    );
}

/// `sepmem node`.
pub fn run_node(config: Option<&Path>, sets: &[String]) -> Result<()> {
    let cfg = Config::load(config, sets)?;
    let backend = Arc::new(cfg.pipeline_backend()?);
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("starting tokio")?;
    let summary = rt.block_on(runtime::run(&cfg.node, backend, shutdown_signal()))?;
    print_summary(&summary);
    Ok(())
}

/// `sepmem play`.
pub fn run_play(
    bag: &Path,
    rate: f64,
    looped: bool,
    topics: &[String],
    config: Option<&Path>,
    sets: &[String],
) -> Result<()> {
    let cfg = Config::load(config, sets)?;
    let loaded = player::load(bag, topics)?;
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("starting tokio")?;
    let summary = rt.block_on(async {
        let mut tr = cfg.node.transport.clone();
        tr.node_name = format!("{}_player", tr.node_name);
        let p = Participant::open(&tr).await?;
        // Let the subscriptions of connected peers reach this session first,
        // so that the first messages are not put before anyone is known.
        tokio::time::sleep(std::time::Duration::from_millis(500)).await;
        let stop = Arc::new(AtomicBool::new(false));
        let s2 = stop.clone();
        tokio::spawn(async move {
            shutdown_signal().await;
            s2.store(true, Ordering::Relaxed);
        });
        let opts = PlayOptions {
            rate,
            looped,
            ..PlayOptions::default()
        };
        let r = player::play(&p, &loaded, &opts, || stop.load(Ordering::Relaxed)).await;
        p.close().await?;
        anyhow::Ok(r?)
    })?;
    for (t, n) in &summary.per_topic {
        println!("{t}: {n} messages");
    }
    println!("{} pass(es)", summary.passes);
    Ok(())
}
