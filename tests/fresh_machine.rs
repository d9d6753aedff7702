//! What a user on a fresh machine sees: a user error is one line without a
//! stack backtrace even with `RUST_BACKTRACE=1`; `RUST_LOG` is honoured
//! beside `SEPMEM_LOG` (which wins); nothing written to a pipe carries ANSI
//! colour codes; and the skip log that `.ci/run` summarises lists every
//! skipped test with its reason.
#![allow(clippy::unwrap_used)]

mod common;

use std::process::{Command, Output};

/// `sepmem args` with `env` set and the logging variables cleared first
/// (stdout and stderr are pipes).
fn sepmem(args: &[&str], env: &[(&str, &str)]) -> Output {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_sepmem"));
    cmd.args(args)
        .env_remove("SEPMEM_LOG")
        .env_remove("RUST_LOG")
        .env_remove("NO_COLOR");
    for (k, v) in env {
        cmd.env(k, v);
    }
    cmd.output().unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).to_string()
}

fn no_escape(o: &Output, what: &str) {
    for (name, bytes) in [("stdout", &o.stdout), ("stderr", &o.stderr)] {
        assert!(
            !bytes.contains(&0x1b),
            "{what}: ESC byte in {name} written to a pipe:\n{}",
            String::from_utf8_lossy(bytes)
        );
    }
}

#[test]
fn a_user_error_is_one_line_without_a_backtrace_even_with_rust_backtrace() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("no-such-cloud.ply");
    let out = dir.path().join("mesh.ply");
    for (cmd, needle) in [
        (
            vec![
                "reconstruct",
                missing.to_str().unwrap(),
                "-o",
                out.to_str().unwrap(),
            ],
            "no-such-cloud.ply",
        ),
        (
            vec!["replay", missing.to_str().unwrap()],
            "no-such-cloud.ply",
        ),
        (
            vec!["config", "--set", "membrane.no_such_key=1"],
            "no_such_key",
        ),
    ] {
        let o = sepmem(
            &cmd,
            &[("RUST_BACKTRACE", "1"), ("RUST_LIB_BACKTRACE", "1")],
        );
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{cmd:?}: {err}");
        let lines: Vec<&str> = err.lines().collect();
        assert_eq!(lines.len(), 1, "{cmd:?}: not one line:\n{err}");
        assert!(
            lines[0].starts_with("error: ") && lines[0].contains(needle),
            "{cmd:?}: {err}"
        );
        assert!(!err.to_lowercase().contains("backtrace"), "{cmd:?}: {err}");
        // A typed error that names its source is not followed by that
        // source again (it read "…: No such file or directory (os error
        // 2): No such file or directory (os error 2)").
        assert!(
            err.matches("os error").count() <= 1,
            "{cmd:?}: a cause repeated: {err}"
        );
        no_escape(&o, "user error");
    }
}

#[test]
fn rust_log_is_honoured_and_sepmem_log_wins() {
    let debug_line = |o: &Output| {
        stderr(o)
            .lines()
            .any(|l| l.contains("DEBUG") && l.contains("logging to stderr"))
    };
    let o = sepmem(&["config"], &[("RUST_LOG", "debug")]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(debug_line(&o), "RUST_LOG=debug ignored: {}", stderr(&o));
    assert!(stderr(&o).contains("source=\"RUST_LOG\""), "{}", stderr(&o));
    no_escape(&o, "RUST_LOG=debug");

    let o = sepmem(
        &["config"],
        &[("RUST_LOG", "debug"), ("SEPMEM_LOG", "warn")],
    );
    assert!(!debug_line(&o), "SEPMEM_LOG=warn must win: {}", stderr(&o));
    let o = sepmem(&["--log", "debug", "config"], &[("RUST_LOG", "warn")]);
    assert!(debug_line(&o), "--log debug must win: {}", stderr(&o));
    let o = sepmem(&["config"], &[]);
    assert!(
        stderr(&o).is_empty(),
        "default warn is quiet: {}",
        stderr(&o)
    );

    let o = sepmem(&["config"], &[("RUST_LOG", "sepmem=loud")]);
    assert_eq!(o.status.code(), Some(1));
    let err = stderr(&o);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(
        err.contains("invalid log filter") && err.contains("RUST_LOG"),
        "{err}"
    );
}

#[test]
fn nothing_written_to_a_pipe_is_coloured() {
    for (args, what) in [
        (vec!["--definitely-not-a-flag"], "clap usage error"),
        (vec!["--help"], "clap help"),
        (vec!["replay", "--help"], "subcommand help"),
    ] {
        let o = sepmem(&args, &[("RUST_LOG", "trace")]);
        assert!(
            !o.stdout.is_empty() || !o.stderr.is_empty(),
            "{what}: no output"
        );
        no_escape(&o, what);
    }
}

#[test]
fn the_skip_log_lists_each_skipped_test_with_its_reason_for_the_ci_summary() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("skipped.log");
    common::skipped_to(&log, "some_test", "python3 with rosbags not found");
    common::skipped_to(&log, "other_test", "shared datasets not found at x");
    let summary = Command::new("bash")
        .arg(concat!(env!("CARGO_MANIFEST_DIR"), "/.ci/skip-summary"))
        .arg(&log)
        .output()
        .unwrap();
    assert!(summary.status.success());
    let text = String::from_utf8_lossy(&summary.stdout);
    assert!(text.contains("2 skipped"), "{text}");
    assert!(
        text.contains("SKIPPED(some_test): python3 with rosbags not found"),
        "{text}"
    );
    assert!(
        text.contains("SKIPPED(other_test): shared datasets not found at x"),
        "{text}"
    );
    let none = Command::new("bash")
        .arg(concat!(env!("CARGO_MANIFEST_DIR"), "/.ci/skip-summary"))
        .arg(dir.path().join("absent.log"))
        .output()
        .unwrap();
    assert!(String::from_utf8_lossy(&none.stdout).contains("0 skipped"));
}

/// The README's first command, `sepmem demo`, with no router anywhere: the
/// test holds rmw_zenoh's router port 127.0.0.1:7447 itself (so no router
/// can sit there) and counts the connections made to it, which must be none
/// (the demo's node and player talk over their own loopback endpoints).
#[test]
fn the_demo_needs_no_router_and_never_dials_one() {
    use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
    use std::sync::Arc;
    use std::time::{Duration, Instant};
    let Ok(listener) = std::net::TcpListener::bind("127.0.0.1:7447") else {
        common::skipped(
            "the_demo_needs_no_router_and_never_dials_one",
            "port 7447 is in use (a router may run here)",
        );
        return;
    };
    listener.set_nonblocking(true).unwrap();
    let (stop, dialed) = (
        Arc::new(AtomicBool::new(false)),
        Arc::new(AtomicUsize::new(0)),
    );
    let watcher = {
        let (stop, dialed) = (stop.clone(), dialed.clone());
        std::thread::spawn(move || {
            while !stop.load(Ordering::Relaxed) {
                match listener.accept() {
                    Ok(_) => {
                        dialed.fetch_add(1, Ordering::Relaxed);
                    }
                    Err(_) => std::thread::sleep(Duration::from_millis(10)),
                }
            }
        })
    };
    let out = tempfile::tempdir().unwrap();
    let mut demo = Command::new(env!("CARGO_BIN_EXE_sepmem"))
        .args(["demo", "-o"])
        .arg(out.path())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let t0 = Instant::now();
    while demo.try_wait().unwrap().is_none() {
        if t0.elapsed() > Duration::from_secs(120) {
            demo.kill().unwrap();
            panic!("sepmem demo did not finish within 120 s");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let o = demo.wait_with_output().unwrap();
    stop.store(true, Ordering::Relaxed);
    watcher.join().unwrap();
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{text}\n{}", stderr(&o));
    let frames: usize = text
        .lines()
        .find_map(|l| l.strip_prefix("demo: "))
        .and_then(|l| l.split_whitespace().next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no demo summary line:\n{text}"));
    eprintln!(
        "demo: {frames} object frames in {:.1} s, {} connections to 127.0.0.1:7447",
        t0.elapsed().as_secs_f64(),
        dialed.load(Ordering::Relaxed)
    );
    assert_eq!(
        dialed.load(Ordering::Relaxed),
        0,
        "the demo dialed the router port"
    );
    // Each bundled bag gave meshes (PLY) and an output bag.
    for bag in ["mosd_rosbags", "synth_ellipsoid", "synth_two_labelled"] {
        let dir = out.path().join(bag);
        let meshes = std::fs::read_dir(dir.join("meshes")).map_or(0, |d| d.count());
        assert!(meshes > 0, "{bag}: no mesh written\n{text}");
        assert!(dir.join(format!("{bag}_sepmem.mcap")).is_file(), "{bag}");
    }
    assert!(frames >= 3, "{text}");
}
