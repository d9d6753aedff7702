//! Helpers shared by the integration tests.
#![allow(dead_code, clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::process::Command;

/// Say that `test` was skipped and why: a `SKIPPED(<test>): <reason>` line
/// on stderr (shown with `--nocapture`), and the same line appended to the
/// skip log that `.ci/run` summarises at the end of the CI log:
/// `$SEPMEM_SKIP_LOG`, else `skipped.log` in cargo's target tmp dir.
pub fn skipped(test: &str, reason: &str) {
    let log = std::env::var_os("SEPMEM_SKIP_LOG")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("skipped.log"));
    skipped_to(&log, test, reason);
}

/// [`skipped`] into the log file `log`.
pub fn skipped_to(log: &Path, test: &str, reason: &str) {
    use std::io::Write;
    let line = format!("SKIPPED({test}): {reason}");
    eprintln!("{line}");
    // One write per line in append mode: parallel tests do not interleave.
    let appended = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(log)
        .and_then(|mut f| f.write_all(format!("{line}\n").as_bytes()));
    if let Err(e) = appended {
        eprintln!("(could not append to the skip log {}: {e})", log.display());
    }
}

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
        skipped(
            test,
            &format!(
                "shared datasets not found at {} (set SEPMEM_DATASETS)",
                dir.display()
            ),
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
        skipped(
            &format!("{test} (external check)"),
            "python3 with rosbags/mcap/mcap-ros2-support not available \
             (pip install -r tests/python/requirements.txt)",
        );
        return None;
    }
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/python/check_bag.py");
    let mut cmd = Command::new("python3");
    cmd.arg(script).arg(bag).args(args);
    Some(stdout_of(
        cmd,
        &format!("check_bag.py on {}", bag.display()),
    ))
}

/// The number after `label` in `text` (a figure of `sepmem`'s printed
/// summaries).
pub fn figure(text: &str, label: &str) -> f64 {
    let at = text
        .find(label)
        .unwrap_or_else(|| panic!("no `{label}` in {text}"));
    text[at + label.len()..]
        .split(|c: char| !(c.is_ascii_digit() || c == '.' || c == '-'))
        .next()
        .and_then(|w| w.parse().ok())
        .unwrap_or_else(|| panic!("no figure after `{label}` in {text}"))
}

/// The frames whose view restarted a stream's model, from the `model`
/// summary lines of `sepmem replay`'s output (none when they name none).
pub fn model_restarts(out: &str) -> Vec<usize> {
    out.lines()
        .filter(|l| l.starts_with("model "))
        .filter_map(|l| l.split("swapped): frame ").nth(1))
        .flat_map(|list| list.split(", ").filter_map(|f| f.trim().parse().ok()))
        .collect()
}

/// Run the built `sepmem` with `args`; its stdout, after asserting that it
/// succeeded (the failure message holds both streams).
pub fn sepmem_stdout<S: AsRef<std::ffi::OsStr>>(args: &[S]) -> String {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_sepmem"));
    cmd.args(args);
    stdout_of(cmd, "sepmem")
}

/// Run `cmd`; its stdout, after asserting that it succeeded (the failure
/// message names `what` and holds both streams).
fn stdout_of(mut cmd: Command, what: &str) -> String {
    let o = cmd.output().unwrap();
    let out = String::from_utf8_lossy(&o.stdout).to_string();
    assert!(
        o.status.success(),
        "{what} failed:\n{out}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    out
}
