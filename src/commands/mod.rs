//! One module per `sepmem` subcommand.

pub mod bench;
pub mod config;
pub mod demo;
pub mod replay;
pub mod synth;
