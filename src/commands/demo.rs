//! `sepmem demo`: the README's first command. Replays the bundled sample
//! bags (real mOSD tabletop objects recorded with Python `rosbags`, and
//! synthetic moving objects when present) through the frame pipeline with
//! the embedded default configuration, and writes the meshes (PLY) and an
//! output bag per input bag to a folder.

use super::replay::{run_with, Outputs};
use anyhow::{bail, Result};
use sepmem::config::Config;
use std::path::{Path, PathBuf};

/// The sample bags shipped in the repository, in demo order.
fn bundled_bags() -> Vec<PathBuf> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/bags");
    let mut bags: Vec<PathBuf> = [
        "mosd_rosbags",
        "synth_ellipsoid.mcap",
        "synth_two_labelled.mcap",
    ]
    .iter()
    .map(|n| root.join(n))
    .filter(|p| p.exists())
    .collect();
    bags.dedup();
    bags
}

/// Run the demo, writing into `out`.
pub fn run(out: &Path, cfg: &Config) -> Result<()> {
    let bags = bundled_bags();
    if bags.is_empty() {
        bail!("no bundled sample bag found under tests/data/bags (run from a sepmem checkout)");
    }
    for bag in &bags {
        let name = bag.file_stem().and_then(|n| n.to_str()).unwrap_or("bag");
        let dir = out.join(name);
        let out_bag = dir.join(format!("{name}_sepmem.mcap"));
        let meshes = dir.join("meshes");
        println!("== {} → {}", bag.display(), dir.display());
        run_with(
            bag,
            Outputs {
                bag: Some(&out_bag),
                meshes: Some(&meshes),
            },
            &[],
            cfg,
            false,
        )?;
    }
    println!("demo outputs are in {}", out.display());
    Ok(())
}
