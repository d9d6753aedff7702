//! One module per `sepmem` subcommand.

pub mod bench_node;
pub mod config;
pub mod demo;
pub mod node;
pub mod replay;
pub mod synth;
