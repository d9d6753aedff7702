//! `sepmem config`: show the effective configuration.

use anyhow::{Context, Result};
use sepmem::config::{Config, DEFAULT_CONFIG};
use std::path::Path;

/// Print the merged configuration as pretty JSON, or the annotated defaults.
pub fn run(config: Option<&Path>, set: &[String], annotated: bool) -> Result<()> {
    if annotated {
        print!("{DEFAULT_CONFIG}");
        return Ok(());
    }
    let cfg = Config::load(config, set).context("loading configuration")?;
    println!("{}", serde_json::to_string_pretty(&cfg)?);
    Ok(())
}
