//! One module per `sepmem` subcommand.

pub mod bench;
pub mod bench_node;
pub mod config;
pub mod demo;
pub mod eval;
pub mod filter;
pub mod node;
pub mod pictures;
pub mod reconstruct;
pub mod replay;
pub mod soak;
pub mod synth;
