//! Helpers shared by the integration tests.
#![allow(dead_code, clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::process::Command;

/// The repository's committed test data (`tests/data`).
pub fn data_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data")
}

/// The larger shared datasets (`../shared/datasets`, or `$SEPMEM_DATASETS`).
/// Returns `None`, after printing a visible skip message naming `test`, when
/// they are absent.
pub fn shared_datasets(test: &str) -> Option<PathBuf> {
    let dir = std::env::var_os("SEPMEM_DATASETS")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/datasets"));
    if dir.is_dir() {
        Some(dir)
    } else {
        eprintln!(
            "SKIPPED {test}: shared datasets not found at {} (set SEPMEM_DATASETS)",
            dir.display()
        );
        None
    }
}

/// True when python3 with rosbags, mcap and mcap-ros2-support is available.
pub fn python_tools() -> bool {
    Command::new("python3")
        .args(["-c", "import rosbags, mcap, mcap_ros2"])
        .output()
        .is_ok_and(|o| o.status.success())
}

/// Run the independent reader `tests/python/check_bag.py` on `bag` with
/// `args`; returns its stdout (asserting success), or `None` after a visible
/// SKIPPED line naming `test` when the Python tools are missing.
pub fn external_bag_check(bag: &Path, args: &[String], test: &str) -> Option<String> {
    if !python_tools() {
        eprintln!(
            "SKIPPED {test} (external check): python3 with rosbags/mcap/mcap-ros2-support \
             not available (pip install -r tests/python/requirements.txt)"
        );
        return None;
    }
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/python/check_bag.py");
    let out = Command::new("python3")
        .arg(script)
        .arg(bag)
        .args(args)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout).to_string();
    assert!(
        out.status.success(),
        "check_bag.py failed on {}:\n{stdout}\n{}",
        bag.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    Some(stdout)
}
