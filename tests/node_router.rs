//! `sepmem node` with its default transport settings finds a zenoh router at
//! `tcp/localhost:7447`, as rmw_zenoh's default session config does (a
//! stock node next to `ros2 run rmw_zenoh_cpp rmw_zenohd`). The router is a
//! zenoh session in router mode run by the test; the node's liveliness
//! tokens are read through it: its node token, and the subscription token
//! of its exact input topic, declared at start before any data.
#![allow(clippy::unwrap_used)]

mod common;

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const TOPIC: &str = "/router_test/points";

fn router_config() -> zenoh::Config {
    let mut c = zenoh::Config::default();
    c.insert_json5("mode", "\"router\"").unwrap();
    c.insert_json5("listen/endpoints", "[\"tcp/localhost:7447\"]")
        .unwrap();
    c.insert_json5("scouting/multicast/enabled", "false")
        .unwrap();
    c
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn default_node_connects_to_a_router_on_localhost_7447() {
    if std::net::TcpListener::bind("127.0.0.1:7447").is_err() {
        common::skipped(
            "default_node_connects_to_a_router_on_localhost_7447",
            "port 7447 is in use (another router runs here)",
        );
        return;
    }
    let router = zenoh::open(router_config()).await.unwrap();
    // No transport override at all: the defaults of launch/sepmem.json5.
    let mut node = Command::new(env!("CARGO_BIN_EXE_sepmem"))
        .args([
            "--log",
            "info",
            "node",
            "--set",
            &format!("node.topics=[\"{TOPIC}\"]"),
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let t0 = Instant::now();
    let mut keys = Vec::new();
    let found = loop {
        keys.clear();
        let replies = router.liveliness().get("@ros2_lv/**").await.unwrap();
        while let Ok(r) = replies.recv_async().await {
            if let Ok(s) = r.result() {
                keys.push(s.key_expr().as_str().to_string());
            }
        }
        let nn = keys.iter().any(|k| k.ends_with("/NN/%/%/sepmem"));
        let ms = keys.iter().any(|k| {
            k.contains("/MS/%/%/sepmem/%router_test%points/sensor_msgs::msg::dds_::PointCloud2_/")
        });
        if nn && ms {
            break true;
        }
        if t0.elapsed() > Duration::from_secs(30) {
            break false;
        }
        tokio::time::sleep(Duration::from_millis(200)).await;
    };
    let elapsed = t0.elapsed();
    node.kill().unwrap();
    let out = node.wait_with_output().unwrap();
    router.close().await.unwrap();
    assert!(
        found,
        "node tokens not seen at the router within 30 s; tokens: {keys:?}\nnode stderr:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    eprintln!(
        "node reached the router at tcp/localhost:7447 and showed its NN and MS tokens after {:.2} s",
        elapsed.as_secs_f64()
    );
}
