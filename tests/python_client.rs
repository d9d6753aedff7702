//! An independent client against the real `sepmem node` executable:
//! `tests/python/zenoh_client.py` (eclipse-zenoh + rosbags, no sepmem code)
//! publishes PointCloud2 the rmw_zenoh way and decodes the node's
//! MarkerArray and DiagnosticArray outputs. The node is then stopped with
//! SIGINT and must exit cleanly. Skips visibly when python3 with `zenoh`,
//! `rosbags` and `numpy` is not available.
#![allow(clippy::unwrap_used)]

mod common;

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn python_zenoh() -> bool {
    Command::new("python3")
        .args(["-c", "import zenoh, rosbags, numpy"])
        .output()
        .is_ok_and(|o| o.status.success())
}

#[test]
fn python_zenoh_client_round_trips_through_the_node() {
    if !python_zenoh() {
        common::skipped(
            "python_zenoh_client_round_trips_through_the_node",
            "python3 with eclipse-zenoh, rosbags and numpy not found \
             (pip install -r tests/python/requirements.txt)",
        );
        return;
    }
    let port = sepmem::transport::free_loopback_port().unwrap();
    let mut node = Command::new(env!("CARGO_BIN_EXE_sepmem"))
        .args([
            "--log",
            "info",
            "node",
            "--set",
            &format!("node.transport.zenoh.listen=[\"tcp/127.0.0.1:{port}\"]"),
            "--set",
            "node.topics=[\"/pyclient/**\"]",
            "--set",
            "node.transport.node_name=\"sepmem_pytest\"",
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Give the node a moment to listen (the client retries its connection too).
    std::thread::sleep(Duration::from_millis(500));
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/python/zenoh_client.py");
    let client = Command::new("python3")
        .args([
            script,
            "--connect",
            &format!("tcp/127.0.0.1:{port}"),
            "--frames",
            "3",
            "--timeout",
            "90",
        ])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&client.stdout).to_string();
    eprintln!(
        "client: {stdout}{}",
        String::from_utf8_lossy(&client.stderr)
    );
    // Stop the node with SIGINT: graceful shutdown, exit status 0.
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
    let out = node.wait_with_output().unwrap();
    let node_out = String::from_utf8_lossy(&out.stdout).to_string();
    eprintln!("node stdout:\n{node_out}");
    assert!(status.success(), "node exit status {status}");
    assert!(
        node_out.contains("clean shutdown: true"),
        "node summary: {node_out}"
    );
    assert!(client.status.success(), "client failed: {stdout}");
    let v: serde_json::Value = serde_json::from_str(stdout.trim().lines().last().unwrap()).unwrap();
    assert!(v["failures"].as_array().unwrap().is_empty());
    assert!(v["marker_arrays_with_triangles"].as_u64().unwrap() >= 3);
    assert!(v["triangles"].as_u64().unwrap() > 100);
    let status = &v["status"]["values"];
    assert!(status["frames"].as_str().unwrap().parse::<u64>().unwrap() >= 3);
}
