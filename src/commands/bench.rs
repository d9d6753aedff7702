//! `sepmem bench`: run the paper's evaluation, write `bench.md` and
//! `bench.json` to `--out`, and print the Markdown.

use anyhow::{Context, Result};
use sepmem::bench::{self, BenchOptions};
use sepmem::membrane::MembraneConfig;
use std::path::{Path, PathBuf};

/// Run the benchmark with the membrane configuration `membrane` and write
/// its Markdown and JSON reports into `out`.
pub fn run(
    quick: bool,
    out: &Path,
    only: &[String],
    datasets: Option<PathBuf>,
    membrane: MembraneConfig,
    seed: u64,
    peers: Option<&Path>,
) -> Result<()> {
    let peers = peers.map(super::pictures::load_peers).transpose()?;
    let datasets = datasets.or_else(default_datasets);
    match &datasets {
        Some(d) if d.is_dir() => eprintln!("bench: datasets at {}", d.display()),
        Some(d) => eprintln!(
            "SKIPPED dataset sections: shared datasets not found at {} (set SEPMEM_DATASETS or --datasets)",
            d.display()
        ),
        None => eprintln!("SKIPPED dataset sections: no shared datasets directory (set SEPMEM_DATASETS or --datasets)"),
    }
    let datasets = datasets.filter(|d| d.is_dir());
    let mut opts =
        BenchOptions::new(quick, datasets).context("loading the default configuration")?;
    opts.membrane = membrane;
    opts.seed = seed;
    opts.only = only
        .iter()
        .flat_map(|o| o.split(','))
        .map(|s| s.trim().to_string())
        .filter(|s| !s.is_empty())
        .collect();
    let report = bench::run(&opts, &mut |line| eprintln!("bench: {line}"))?;
    let md = bench::markdown::render(&report);
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let md_path = out.join("bench.md");
    let json_path = out.join("bench.json");
    std::fs::write(&md_path, &md).with_context(|| format!("writing {}", md_path.display()))?;
    let json = serde_json::to_string_pretty(&report).context("serialising the report")?;
    std::fs::write(&json_path, json).with_context(|| format!("writing {}", json_path.display()))?;
    let plots = super::pictures::bench_plots(&report, peers.as_ref(), out)?;
    for s in &report.skipped {
        eprintln!("SKIPPED {}: {}", s.what, s.reason);
    }
    print!("{md}");
    eprintln!(
        "bench: wrote {} and {}",
        md_path.display(),
        json_path.display()
    );
    for p in &plots {
        eprintln!("bench: wrote {}", p.display());
    }
    Ok(())
}

/// `$SEPMEM_DATASETS`, else `../shared/datasets` next to the crate.
fn default_datasets() -> Option<PathBuf> {
    std::env::var_os("SEPMEM_DATASETS")
        .map(PathBuf::from)
        .or_else(|| Some(PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/datasets")))
}
