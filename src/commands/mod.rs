//! One module per `sepmem` subcommand.

pub mod config;
pub mod replay;
pub mod synth;
