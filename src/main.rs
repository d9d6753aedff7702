//! The `sepmem` command-line tool. Errors are reported here with `anyhow`;
//! the library uses typed errors.

use anyhow::Result;
use clap::{Parser, Subcommand};
use std::path::PathBuf;

mod commands;

/// sepmem: Separability Membrane reconstruction of segmented point clouds.
#[derive(Parser, Debug)]
#[command(name = "sepmem", version, about, long_about = None)]
struct Cli {
    /// Log filter (tracing env-filter syntax), e.g. `info` or `sepmem=debug`.
    #[arg(long, global = true, env = "SEPMEM_LOG", default_value = "warn")]
    log: String,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Print the effective configuration (defaults, file and overrides merged) as JSON.
    Config {
        /// Configuration file (.json5 or .toml) holding the keys to change.
        #[arg(long)]
        config: Option<PathBuf>,
        /// Override one parameter: section.key=value (repeatable).
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
        /// Print the annotated default file instead.
        #[arg(long)]
        annotated: bool,
    },
    /// Run the paper's evaluation (Table 1, sphere sweep, static vs adaptive,
    /// attribute ablation, real scans, speed); write bench.md and bench.json.
    Bench {
        /// Reduced set (few shapes, fewer points) that runs in seconds.
        #[arg(long)]
        quick: bool,
        /// Directory for bench.md and bench.json.
        #[arg(long, default_value = "bench-results")]
        out: PathBuf,
        /// Sections (table1, sweep, adaptive, ablation, real, speed) and/or
        /// Table 1 shape names to run, comma-separated or repeated.
        #[arg(long, value_delimiter = ',')]
        only: Vec<String>,
        /// Shared datasets directory (default: $SEPMEM_DATASETS, else ../shared/datasets).
        #[arg(long)]
        datasets: Option<PathBuf>,
    },
}

fn main() -> Result<()> {
    let cli = Cli::parse();
    tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::new(&cli.log))
        .with_writer(std::io::stderr)
        .init();
    match cli.command {
        Command::Config {
            config,
            set,
            annotated,
        } => commands::config::run(config.as_deref(), &set, annotated),
        Command::Bench {
            quick,
            out,
            only,
            datasets,
        } => commands::bench::run(quick, &out, &only, datasets),
    }
}
