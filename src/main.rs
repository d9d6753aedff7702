//! The `sepmem` command-line tool. Errors are reported here with `anyhow`;
//! the library uses typed errors.
//!
//! A failing command prints one line, `error: ` and the error's chain of
//! causes, and exits with status 1. It never prints a backtrace: the chain
//! is formatted here (`{:#}`), not by anyhow's `Debug`, which appends a
//! stack backtrace whenever `RUST_BACKTRACE` is set. Logs go to stderr,
//! filtered by `--log` / `$SEPMEM_LOG`, else `$RUST_LOG`, else `warn`, with
//! colour only when stderr is a terminal (and `$NO_COLOR` is unset).
#![cfg_attr(test, allow(clippy::unwrap_used))]

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use std::io::IsTerminal;
use std::path::PathBuf;
use std::process::ExitCode;

mod commands;

/// sepmem: Separability Membrane reconstruction of segmented point clouds.
#[derive(Parser, Debug)]
#[command(name = "sepmem", version, about, long_about = None)]
struct Cli {
    /// Log filter (tracing env-filter syntax), e.g. `info` or `sepmem=debug`
    /// [default: $RUST_LOG, else warn].
    #[arg(long, global = true, env = "SEPMEM_LOG")]
    log: Option<String>,
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
    /// Reconstruct a watertight mesh of one object's point cloud with the
    /// separability membrane; prints one summary line.
    Reconstruct {
        /// Input point cloud (.ply, .pcd, .xyz/.txt/.csv, .obj vertices).
        input: PathBuf,
        /// Output mesh (.ply with a per-vertex `separability` property, or .obj).
        #[arg(short, long)]
        output: PathBuf,
        /// Configuration file (.json5 or .toml) holding the keys to change.
        #[arg(long)]
        config: Option<PathBuf>,
        /// Override one parameter: section.key=value (repeatable), e.g. membrane.step.beta=0.8.
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
        /// Also write the full report (per-iteration η_g, grids and times,
        /// per-phase times, viewpoint, point counts) as JSON to this file.
        #[arg(long)]
        report: Option<PathBuf>,
        /// Also write a PNG of the mesh with its input points from the
        /// camera side, the side and the back.
        #[arg(long, value_name = "FILE.png")]
        snapshot: Option<PathBuf>,
    },
    /// The 3D separability filter (paper Fig. 6): write the cloud as a PLY
    /// coloured by the separability of the two halves of a cuboid at each point.
    Filter {
        /// Input point cloud (.ply, .pcd, .xyz/.txt/.csv, .obj vertices).
        input: PathBuf,
        /// Output cloud (.ply, colour + float `separability`; or .pcd).
        #[arg(short, long)]
        output: PathBuf,
        /// Split direction: x, y, z, all (maximum over x, y, z) or normal
        /// (each point's PCA normal, separability.normal_k neighbours).
        #[arg(long, default_value = "all")]
        direction: String,
        /// Cuboid size W[,H[,D]] (H and D default to W): a fraction of the
        /// object size, or with suffix `m` in metres, or `d` in multiples of
        /// the point spacing δ.
        #[arg(long, default_value = "8d")]
        size: String,
        /// Configuration file (.json5 or .toml): density.* and separability.* apply.
        #[arg(long)]
        config: Option<PathBuf>,
        /// Override one parameter, e.g. separability.weights.luma=1.
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
    },
    /// Score a predicted mesh against a ground-truth mesh: Chamfer-L1/L2,
    /// F-score at τ and normal consistency (metrics.* keys).
    Eval {
        /// Predicted mesh (.ply or .obj).
        #[arg(long)]
        pred: PathBuf,
        /// Ground-truth mesh (.ply or .obj).
        #[arg(long)]
        gt: PathBuf,
        /// Configuration file (.json5 or .toml).
        #[arg(long)]
        config: Option<PathBuf>,
        /// Override one parameter, e.g. metrics.samples=20000.
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
        /// Print one JSON object instead of a table.
        #[arg(long)]
        json: bool,
    },
    /// Demo: start the live node and a bag player on zenoh over loopback,
    /// replay the bundled sample bags, and write the received meshes (PLY)
    /// and output bags to a folder. Needs no router or ROS.
    Demo {
        /// Output folder.
        #[arg(short, long, default_value = "demo-out")]
        out: PathBuf,
        /// Speed factor of the replay (1 = recorded timing).
        #[arg(long, default_value_t = 1.0)]
        rate: f64,
        /// Configuration file (.json5 or .toml) holding the keys to change.
        #[arg(long)]
        config: Option<PathBuf>,
        /// Override one parameter: section.key=value (repeatable).
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
    },
    /// Run the frame pipeline over every PointCloud2 of a rosbag2 bag (MCAP or
    /// db3), deterministically and as fast as possible; print a per-frame table
    /// and a latency summary, and optionally write meshes, markers and
    /// diagnostics to an output bag.
    Replay(commands::replay::ReplayArgs),
    /// Write a synthetic depth-camera sequence of moving objects (procedural
    /// shapes or mesh files) as a rosbag2 MCAP bag, with per-frame ground
    /// truth on /synth/ground_truth.
    Synth(commands::synth::SynthArgs),
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
        /// Configuration file (.json5 or .toml) holding the membrane keys to
        /// change (benchmark a tuned configuration; default: the embedded one).
        #[arg(long)]
        config: Option<PathBuf>,
        /// Override one parameter: section.key=value (repeatable).
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
        /// Base seed of every random stream (point sampling, noise, outliers,
        /// metric samples). The default keeps results comparable over time;
        /// another seed re-runs the same benchmark on fresh samplings.
        #[arg(long, default_value_t = sepmem::bench::DEFAULT_SEED)]
        seed: u64,
        /// Peers' F-scores per input condition, JSON
        /// `{"method": {"condition": F}}`, drawn beside sepmem's in
        /// `conditions.png` (e.g. the paper's Table 1: tests/data/peers_paper_table1.json).
        #[arg(long, value_name = "FILE.json")]
        peers: Option<PathBuf>,
    },
    /// Run the live node: subscribe to PointCloud2 topics over zenoh
    /// (rmw_zenoh keys by default), publish meshes, markers and diagnostics,
    /// until SIGINT/SIGTERM.
    Node {
        /// Configuration file (.json5 or .toml) holding the keys to change.
        #[arg(long)]
        config: Option<PathBuf>,
        /// Override one parameter: section.key=value (repeatable).
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
    },
    /// Benchmark the live node over zenoh loopback: N streams at R Hz with P
    /// points each; publish→mesh latency percentiles, drops, memory over time.
    BenchNode(commands::bench_node::BenchNodeArgs),
    /// Publish a bag's PointCloud2 (and other) messages over zenoh as a ROS 2
    /// publisher would (rmw_zenoh keys, attachments, liveliness tokens), with
    /// the recorded timing.
    Play {
        /// Input bag: a `.mcap` file, a `.db3` file or a bag directory.
        bag: PathBuf,
        /// Speed factor (2 = twice as fast; 0 = as fast as possible).
        #[arg(long, default_value_t = 1.0)]
        rate: f64,
        /// Start again at the end, until interrupted.
        #[arg(long = "loop")]
        looped: bool,
        /// Only play these topics (repeatable; default: all).
        #[arg(long)]
        topic: Vec<String>,
        /// Configuration file (transport settings: node.transport.*).
        #[arg(long)]
        config: Option<PathBuf>,
        /// Override one parameter: section.key=value (repeatable).
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
    },
}

/// Restore the default SIGPIPE action (end quietly, as `cat` or `grep` do)
/// for the subcommands that read and write files and print: Rust ignores
/// SIGPIPE, so `sepmem config | head` panicked in `println!` on the closed
/// pipe. The networked subcommands (node, play, demo, bench-node) keep it
/// ignored: a peer closing a unix socket must not end the node.
#[cfg(unix)]
#[allow(unsafe_code)]
fn end_quietly_on_broken_pipe() {
    // SAFETY: installs the default action, no handler code; called once at
    // the start of main, before any thread exists.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

#[cfg(not(unix))]
fn end_quietly_on_broken_pipe() {}

/// glibc's allocator, tuned for a long-running node:
/// - Every allocation of 1 MiB or more is its own mapping, returned to the
///   system when freed. glibc's default threshold rises to 32 MiB after a
///   large block is freed, so the node's large receive and decode buffers
///   (a payload may be `wire.max_bytes`) then came from the heap and stayed
///   resident: in the 30-minute soak the node's RSS wandered 336–375 MiB
///   around its 5-minute 339 MiB.
/// - At most two arenas. With glibc's default (8 per core) every tokio,
///   rayon and zenoh thread kept an arena of its own, each holding free
///   pages the others could not reuse: in the 30-minute soak of 2026-12-03
///   the heap in use stayed at 79–87 MiB while the arenas grew to 107–116
///   MiB and the RSS from 111.5 MiB at 5 minutes to 126.9 (+13.8 %). With
///   two arenas (`MALLOC_ARENA_MAX=2`, a 15-minute soak) the arenas held
///   95–100 MiB and the RSS stayed at 110.5–115.5 MiB after its 114.8 at 5
///   minutes, with healthy p95 45.9 ms and 93.8–94.7 % of frames meshed.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
#[allow(unsafe_code)]
fn tune_allocator() {
    // SAFETY: mallopt only sets allocator parameters; called once at the
    // start of main, before any thread exists.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 1 << 20);
        libc::mallopt(libc::M_ARENA_MAX, 2);
    }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn tune_allocator() {}

/// Every 10 s, glibc's `malloc_trim(0)` gives the free pages of every
/// arena back to the system. What the node holds is bounded, but its
/// per-thread arenas fragment: in a 10-minute soak the heap in use stayed
/// at 199-225 MiB (`mallinfo2`) while the RSS climbed from 188 MiB at 5
/// minutes to 209 MiB (+11 %). A background thread, so no tokio worker or
/// compute thread ever waits for it.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
#[allow(unsafe_code)]
fn trim_heap_periodically() {
    let spawned = std::thread::Builder::new()
        .name("sepmem-trim".into())
        .spawn(|| loop {
            std::thread::sleep(std::time::Duration::from_secs(10));
            // SAFETY: malloc_trim only returns free memory to the system.
            unsafe {
                libc::malloc_trim(0);
            }
        });
    if let Err(e) = spawned {
        tracing::warn!("heap trimming thread not started: {e}");
    }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn trim_heap_periodically() {}

fn main() -> ExitCode {
    tune_allocator();
    let cli = Cli::parse();
    let long_running = matches!(
        cli.command,
        Command::Node { .. } | Command::Play { .. } | Command::Demo { .. } | Command::BenchNode(_)
    );
    if long_running {
        trim_heap_periodically();
    } else {
        end_quietly_on_broken_pipe();
    }
    match init_logging(cli.log.as_deref()).and_then(|()| run(cli.command)) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // The chain of causes on one line, without the backtrace that
            // anyhow's Debug output adds when RUST_BACKTRACE is set.
            eprintln!("error: {}", one_line(&e));
            ExitCode::FAILURE
        }
    }
}

/// An error and its causes on one line, `: `-separated; a cause whose text
/// an outer message already holds (a typed error that names its source) is
/// not repeated.
fn one_line(e: &anyhow::Error) -> String {
    let mut out = String::new();
    for cause in e.chain() {
        let text = cause.to_string();
        if out.contains(&text) {
            continue;
        }
        if !out.is_empty() {
            out.push_str(": ");
        }
        out.push_str(&text);
    }
    out
}

/// Install the stderr logger: the filter from `--log` / `$SEPMEM_LOG`, else
/// `$RUST_LOG`, else `warn`; ANSI colour only on a terminal.
fn init_logging(flag: Option<&str>) -> Result<()> {
    let from_env = std::env::var("RUST_LOG")
        .ok()
        .filter(|v| !v.trim().is_empty());
    let (spec, source) = match (flag, &from_env) {
        (Some(f), _) => (f, "--log / SEPMEM_LOG"),
        (None, Some(e)) => (e.as_str(), "RUST_LOG"),
        (None, None) => ("warn", "the default"),
    };
    let filter = tracing_subscriber::EnvFilter::try_new(spec)
        .with_context(|| format!("invalid log filter {spec:?} (from {source})"))?;
    let colour = std::io::stderr().is_terminal() && std::env::var_os("NO_COLOR").is_none();
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(colour)
        .init();
    tracing::debug!(filter = spec, source, colour, "logging to stderr");
    Ok(())
}

/// Run one subcommand.
fn run(command: Command) -> Result<()> {
    match command {
        Command::Config {
            config,
            set,
            annotated,
        } => commands::config::run(config.as_deref(), &set, annotated),
        Command::Reconstruct {
            input,
            output,
            config,
            set,
            report,
            snapshot,
        } => commands::reconstruct::run(
            &input,
            &output,
            config.as_deref(),
            &set,
            report.as_deref(),
            snapshot.as_deref(),
        ),
        Command::Filter {
            input,
            output,
            direction,
            size,
            config,
            set,
        } => commands::filter::run(&input, &output, &direction, &size, config.as_deref(), &set),
        Command::Eval {
            pred,
            gt,
            config,
            set,
            json,
        } => commands::eval::run(&pred, &gt, config.as_deref(), &set, json),
        Command::Demo {
            out,
            rate,
            config,
            set,
        } => {
            let cfg = sepmem::config::Config::load(config.as_deref(), &set)?;
            commands::demo::run(&out, &cfg, rate)
        }
        Command::Replay(args) => commands::replay::run_args(&args),
        Command::Synth(args) => commands::synth::run(&args),
        Command::Bench {
            quick,
            out,
            only,
            datasets,
            config,
            set,
            seed,
            peers,
        } => {
            let cfg = sepmem::config::Config::load(config.as_deref(), &set)?;
            commands::bench::run(
                quick,
                &out,
                &only,
                datasets,
                cfg.membrane,
                seed,
                peers.as_deref(),
            )
        }
        Command::BenchNode(args) => commands::bench_node::run(&args),
        Command::Node { config, set } => commands::node::run_node(config.as_deref(), &set),
        Command::Play {
            bag,
            rate,
            looped,
            topic,
            config,
            set,
        } => commands::node::run_play(&bag, rate, looped, &topic, config.as_deref(), &set),
    }
}
