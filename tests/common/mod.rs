//! Helpers shared by the integration tests.
#![allow(dead_code, clippy::unwrap_used)]

use std::path::PathBuf;

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
