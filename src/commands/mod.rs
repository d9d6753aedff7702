//! One module per `sepmem` subcommand.

pub mod bench;
pub mod config;
