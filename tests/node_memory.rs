//! `wire.max_bytes` bounds what the node holds of one received message
//! (issue 22, defect 7): the release binary runs as its own process on a
//! real zenoh loopback session with `wire.max_bytes` = 4 MiB; a peer sends
//! it three 192 MiB payloads (reliable, blocking, so zenoh does send them)
//! next to a healthy cloud stream. The node's peak resident memory
//! (`VmHWM` in /proc) must stay within 64 MiB of its value before, and the
//! healthy stream must keep being meshed. Before the fix the node received
//! and copied every payload whole before checking the limit (a 1,000 MiB
//! payload took it to 2.2 GB).
#![allow(clippy::unwrap_used)]

mod common;

use sepmem::cloud::{PointCloud, Vec3};
use sepmem::transport::liveliness::{Durability, Qos, Reliability};
use sepmem::transport::{free_loopback_port, Participant, RosType, TransportConfig};
use sepmem::wire::msgs::{Header, PointCloud2, SurfaceMesh, Time};
use sepmem::wire::pointcloud2::encode_pointcloud2;
use sepmem::wire::{self, RosMessage};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

const PAYLOAD: usize = 192 << 20;

/// A `/proc/<pid>/status` value in MiB.
fn proc_mib(pid: u32, key: &str) -> f64 {
    let s = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap();
    let line = s.lines().find(|l| l.starts_with(key)).unwrap();
    line.split_whitespace()
        .nth(1)
        .unwrap()
        .parse::<f64>()
        .unwrap()
        / 1024.0
}

fn sphere_cloud(k: usize) -> Vec<u8> {
    let pts: Vec<Vec3> = (0..3000)
        .map(|i| {
            let (a, b) = (i as f64 * 0.618_034, i as f64 * 0.414_214);
            let (th, ph) = (
                (a.fract() * 2.0 - 1.0).acos(),
                b.fract() * std::f64::consts::TAU,
            );
            Vec3::new(th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos()) * 0.1
                + Vec3::new(0.001 * k as f64, 0.0, 1.0)
        })
        .collect();
    let header = Header {
        stamp: Time::from_nanos(1_000 + k as i64),
        frame_id: "mem".into(),
    };
    wire::encode(&encode_pointcloud2(&PointCloud::from_points(pts), header)).unwrap()
}

#[test]
fn a_payload_above_wire_max_bytes_never_grows_the_node() {
    if !std::path::Path::new("/proc/self/status").exists() {
        common::skipped(
            "a_payload_above_wire_max_bytes_never_grows_the_node",
            "no /proc",
        );
        return;
    }
    let port = free_loopback_port().unwrap();
    let mut node = Command::new(env!("CARGO_BIN_EXE_sepmem"))
        .args(["node", "--set"])
        .arg(format!(
            "node.transport.zenoh.listen=[\"tcp/127.0.0.1:{port}\"]"
        ))
        .args([
            "--set",
            "node.topics=[\"/mem/**\"]",
            "--set",
            "wire.max_bytes=4194304",
        ])
        .args(["--set", "node.transport.node_name=\"sepmem_memtest\""])
        .args(["--set", "pipeline.deadline_ms=0"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let pid = node.id();
    let rt = tokio::runtime::Runtime::new().unwrap();
    let outcome = rt.block_on(async {
        let h = Participant::open(&TransportConfig::loopback("mem_harness", None, &[port]))
            .await
            .unwrap();
        let meshes = Arc::new(AtomicUsize::new(0));
        let m2 = meshes.clone();
        let _sub = h
            .subscribe(
                "/mem/**",
                &RosType::new(SurfaceMesh::TYPE_NAME, SurfaceMesh::TYPE_HASH),
                move |_| {
                    m2.fetch_add(1, Ordering::Relaxed);
                },
            )
            .await
            .unwrap();
        let ty = RosType::new(PointCloud2::TYPE_NAME, PointCloud2::TYPE_HASH);
        let healthy = h
            .publisher("/mem/ok/points", &ty, Qos::DEFAULT_10)
            .await
            .unwrap();
        let blocking = Qos {
            reliability: Reliability::Reliable,
            durability: Durability::Volatile,
            keep_last: None,
        };
        let big = h.publisher("/mem/big/points", &ty, blocking).await.unwrap();
        // Until the node is up and meshing.
        let t0 = Instant::now();
        let mut k = 0;
        while meshes.load(Ordering::Relaxed) == 0 {
            assert!(t0.elapsed() < Duration::from_secs(60), "no first mesh");
            healthy.put(sphere_cloud(k)).await.unwrap();
            k += 1;
            tokio::time::sleep(Duration::from_millis(200)).await;
        }
        tokio::time::sleep(Duration::from_millis(500)).await;
        let before = proc_mib(pid, "VmHWM:");
        let payload = vec![7u8; PAYLOAD];
        for _ in 0..3 {
            big.put(payload.clone()).await.unwrap();
        }
        tokio::time::sleep(Duration::from_secs(2)).await;
        let n0 = meshes.load(Ordering::Relaxed);
        for _ in 0..10 {
            healthy.put(sphere_cloud(k)).await.unwrap();
            k += 1;
            tokio::time::sleep(Duration::from_millis(200)).await;
        }
        tokio::time::sleep(Duration::from_secs(1)).await;
        let after = proc_mib(pid, "VmHWM:");
        let rss = proc_mib(pid, "VmRSS:");
        (before, after, rss, meshes.load(Ordering::Relaxed) - n0)
    });
    Command::new("kill")
        .args(["-INT", &pid.to_string()])
        .status()
        .unwrap();
    let status = node.wait().unwrap();
    let (before, after, rss, new_meshes) = outcome;
    eprintln!(
        "node VmHWM {before:.1} MiB before, {after:.1} MiB after 3 × {} MiB payloads (VmRSS {rss:.1}); {new_meshes} meshes after",
        PAYLOAD >> 20
    );
    assert!(
        after - before < 64.0,
        "peak RSS grew {:.1} MiB",
        after - before
    );
    assert!(
        new_meshes >= 5,
        "the healthy stream stopped meshing: {new_meshes}"
    );
    assert!(status.success(), "node exit {status:?}");
}
