//! The independent ROS 2 conformance client (`tests/python/zenoh_client.py`:
//! eclipse-zenoh + rosbags, no sepmem code) against the real executables:
//! `sepmem node` fed by `sepmem play` (the synthetic ellipsoid bag) and by
//! the client's own scripted stream. The client checks the graph tokens with
//! rmw_zenoh's grammar, every endpoint's type, hash and QoS, the attachment
//! of every sample (the player's clouds included), frames and stamps, the
//! TRANSIENT_LOCAL late join (the last mesh of every stream, by its stamp,
//! within 1 s of opening the late session), and the
//! collision objects (ADD, MOVE, then REMOVE after eviction). The node is
//! then stopped with SIGINT and must exit cleanly. Skips visibly when
//! python3 with `zenoh`, `rosbags` and `numpy` is not available.
#![allow(clippy::unwrap_used)]

mod common;

use std::io::{BufRead, BufReader, Read};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

fn python_zenoh() -> bool {
    Command::new("python3")
        .args(["-c", "import zenoh, zenoh.ext, rosbags, numpy"])
        .output()
        .is_ok_and(|o| o.status.success())
}

const PLAYED: &str = "/synth/ellipsoid/points";
const SCRIPTED: &str = "/conformance/points";

fn start_node(port: u16) -> Child {
    Command::new(env!("CARGO_BIN_EXE_sepmem"))
        .args([
            "--log",
            "info",
            "node",
            "--set",
            &format!("node.transport.zenoh.listen=[\"tcp/127.0.0.1:{port}\"]"),
            "--set",
            "node.transport.zenoh.connect=[]",
            "--set",
            &format!("node.topics=[\"{SCRIPTED}\", \"{PLAYED}\"]"),
            "--set",
            "node.transport.node_name=\"sepmem_conformance\"",
            // The late joiner comes after the last frame: streams must still
            // be alive then, and evicted (REMOVE) soon after.
            "--set",
            "node.evict_after_ms=6000",
            "--set",
            "node.diagnostics_period_ms=500",
            // A warm frame cut by the 15 ms deadline is not "fitted" and
            // sends no collision object: on the loaded 2-core machine that
            // left the scripted stream at ADD, REMOVE (no MOVE) in 1 of 4
            // runs. The wire behaviour is under test here, not the budget.
            "--set",
            "pipeline.deadline_ms=1000",
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

/// Stop the node with SIGINT; returns (exit success, stdout).
fn stop(mut node: Child) -> (bool, String) {
    let pid = node.id().to_string();
    Command::new("kill").args(["-INT", &pid]).status().unwrap();
    let t0 = Instant::now();
    let status = loop {
        if let Some(s) = node.try_wait().unwrap() {
            break s;
        }
        if t0.elapsed() > Duration::from_secs(30) {
            node.kill().unwrap();
            panic!("node did not stop within 30 s of SIGINT");
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let mut out = String::new();
    node.stdout
        .take()
        .unwrap()
        .read_to_string(&mut out)
        .unwrap();
    (status.success(), out)
}

#[test]
fn conformance_client_passes_against_node_and_player() {
    if !python_zenoh() {
        common::skipped(
            "conformance_client_passes_against_node_and_player",
            "python3 with eclipse-zenoh, rosbags and numpy not found \
             (pip install -r tests/python/requirements.txt)",
        );
        return;
    }
    let port = sepmem::transport::free_loopback_port().unwrap();
    let node = start_node(port);
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/python/zenoh_client.py");
    let mut client = Command::new("python3")
        .args([
            script,
            "--connect",
            &format!("tcp/127.0.0.1:{port}"),
            "--node-name",
            "sepmem_conformance",
            "--player-name",
            "sepmem_player",
            "--played-topic",
            PLAYED,
            "--scripted-topic",
            SCRIPTED,
        ])
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(client.stdout.take().unwrap()).lines();
    let ready = lines.next().unwrap().unwrap();
    assert_eq!(ready, "READY", "client: {ready}");
    let bag = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/bags/synth_ellipsoid.mcap"
    );
    let play = Command::new(env!("CARGO_BIN_EXE_sepmem"))
        .args([
            "play",
            bag,
            "--topic",
            PLAYED,
            "--set",
            &format!("node.transport.zenoh.connect=[\"tcp/127.0.0.1:{port}\"]"),
            "--set",
            "node.transport.zenoh.listen=[]",
            "--set",
            // The player names itself <node_name>_player.
            "node.transport.node_name=\"sepmem\"",
        ])
        .output()
        .unwrap();
    assert!(
        play.status.success(),
        "sepmem play: {}",
        String::from_utf8_lossy(&play.stderr)
    );
    let report: String = lines.map_while(Result::ok).collect::<Vec<_>>().join("\n");
    let status = client.wait().unwrap();
    eprintln!("client: {report}");
    let (node_ok, node_out) = stop(node);
    eprintln!("node stdout:\n{node_out}");
    assert!(node_ok, "node exit status");
    assert!(
        node_out.contains("clean shutdown: true"),
        "node summary: {node_out}"
    );
    let v: serde_json::Value = serde_json::from_str(report.trim().lines().last().unwrap()).unwrap();
    assert!(status.success(), "client failed: {report}");
    assert!(v["failures"].as_array().unwrap().is_empty());
    // Measured outcomes the client reports (each also a failure if wrong).
    assert!(v["samples_checked"].as_u64().unwrap() >= 30, "{v}");
    assert!(v["headers_checked"].as_u64().unwrap() >= 20, "{v}");
    // Outputs use zenoh's "drop" congestion control (RELIABLE + KEEP_LAST,
    // as rmw_zenoh maps it): on a loaded 2-core machine a cold frame's burst
    // lost the first marker array and collision object in 2 of 4 runs.
    // Gaps in the sequence numbers are counted: more than a tenth of the
    // samples sent (received and lost, at least 3) is a failure. A fixed 3
    // failed once with 4 of 92 (all marker arrays, the largest payloads)
    // while two replays shared the 2 cores.
    let lost: u64 = v["samples_lost"]
        .as_object()
        .unwrap()
        .values()
        .map(|n| n.as_u64().unwrap())
        .sum();
    let sent = v["samples_checked"].as_u64().unwrap() + lost;
    assert!(
        lost <= (sent / 10).max(3),
        "samples lost: {} of {sent}",
        v["samples_lost"]
    );
    // Collision objects travel in zenoh's DataHigh lane, not behind the
    // marker arrays' fragments: with both in the Data lane, 4 of 8 runs under
    // two busy cores lost one (and with it the only MOVE or the ADD); 0 of 12
    // in their own lane.
    assert!(
        v["samples_lost"].get("/collision_object").is_none(),
        "collision objects lost: {}",
        v["samples_lost"]
    );
    for t in [SCRIPTED, PLAYED] {
        assert!(v["late_join_s"][t].as_f64().unwrap() <= 1.0, "{v}");
    }
    let ops: Vec<u64> = v["collision_operations"]
        .as_array()
        .unwrap()
        .iter()
        .map(|o| o.as_u64().unwrap())
        .collect();
    assert_eq!(ops.first(), Some(&0), "ADD first: {ops:?}");
    assert!(ops.contains(&3), "a MOVE: {ops:?}");
    assert_eq!(ops.last(), Some(&1), "REMOVE last: {ops:?}");
}
