//! `sepmem demo`: the README's first command. In one process, with no
//! router and no ROS install, it starts the live node and a bag player on
//! zenoh over loopback (rmw_zenoh keys, attachments and liveliness tokens),
//! replays the bundled sample bags (real mOSD tabletop objects recorded with
//! Python `rosbags`, and moving synthetic objects) with their recorded
//! timing, and writes what an outside subscriber received: the meshes (PLY)
//! and an output bag per input bag. It prints the publish→mesh-receipt
//! latency of every object frame and a final summary.

use super::node::print_summary;
use super::replay::percentile;
use anyhow::{bail, Context, Result};
use sepmem::bag::{Bag, BagWriter, Qos};
use sepmem::config::Config;
use sepmem::node::loopback::{inbox_lock, Inbox, LoopbackNode};
use sepmem::node::player::{self, PlayOptions};
use sepmem::transport::RosType;
use sepmem::wire::convert::trimesh_from_surface;
use sepmem::wire::msgs::{
    DiagnosticArray, FrameDiagnostics, MarkerArray, PointCloud2, SurfaceMesh,
};
use sepmem::wire::{self, RosMessage};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

const POINTCLOUD2: &str = "sensor_msgs/msg/PointCloud2";

/// The sample bags shipped in the repository, in demo order.
pub fn bundled_bags() -> Vec<PathBuf> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/bags");
    [
        "mosd_rosbags",
        "synth_ellipsoid.mcap",
        "synth_two_labelled.mcap",
    ]
    .iter()
    .map(|n| root.join(n))
    .filter(|p| p.exists())
    .collect()
}

fn ty<M: RosMessage>() -> RosType {
    RosType::new(M::TYPE_NAME, M::TYPE_HASH)
}

/// Output subscriptions of the observer: (type name, inbox).
struct Observed {
    _subs: Vec<zenoh::pubsub::Subscriber<()>>,
    inboxes: Vec<(&'static str, Inbox)>,
}

impl Observed {
    fn mesh_count(&self) -> usize {
        self.inboxes
            .iter()
            .find(|(t, _)| *t == SurfaceMesh::TYPE_NAME)
            .map_or(0, |(_, i)| inbox_lock(i).len())
    }
}

/// Run the demo, writing into `out`; `rate` scales the recorded timing.
pub fn run(out: &Path, cfg: &Config, rate: f64) -> Result<()> {
    let bags = bundled_bags();
    if bags.is_empty() {
        bail!("no bundled sample bag found under tests/data/bags (run from a sepmem checkout)");
    }
    let mut topics = Vec::new();
    let mut loaded = Vec::new();
    for path in &bags {
        let bag = Bag::open(path).with_context(|| format!("opening {}", path.display()))?;
        let clouds: Vec<String> = bag
            .topics
            .iter()
            .filter(|t| t.type_name == POINTCLOUD2)
            .map(|t| t.name.clone())
            .collect();
        topics.extend(clouds.iter().cloned());
        let l = player::load(path, &clouds)?;
        loaded.push((path.clone(), l));
    }
    topics.sort();
    topics.dedup();
    let mut node_cfg = cfg.node.clone();
    node_cfg.topics = topics;
    let backend = Arc::new(cfg.pipeline_backend()?);
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("starting tokio")?;
    rt.block_on(async move {
        let t0 = std::time::Instant::now();
        let node = LoopbackNode::start(&node_cfg, backend).await?;
        let mut subs = Vec::new();
        let mut inboxes = Vec::new();
        for (name, t) in [
            (SurfaceMesh::TYPE_NAME, ty::<SurfaceMesh>()),
            (MarkerArray::TYPE_NAME, ty::<MarkerArray>()),
            (FrameDiagnostics::TYPE_NAME, ty::<FrameDiagnostics>()),
        ] {
            let (s, i) = node.collect("/**", &t).await?;
            subs.push(s);
            inboxes.push((name, i));
        }
        let (s, i) = node.collect_diagnostics().await?;
        subs.push(s);
        inboxes.push((DiagnosticArray::TYPE_NAME, i));
        let observed = Observed {
            _subs: subs,
            inboxes,
        };
        if !node.wait_ready(Duration::from_secs(15)).await {
            bail!("the node did not come up on loopback within 15 s");
        }
        println!(
            "node up on zenoh loopback (rmw_zenoh keys, domain 0) in {:.1} s; replaying {} bag(s) at rate {rate}",
            t0.elapsed().as_secs_f64(),
            loaded.len()
        );
        let mut all_lat = Vec::new();
        let mut total_frames = 0usize;
        for (path, bag) in &loaded {
            let name = path
                .file_stem()
                .and_then(|n| n.to_str())
                .unwrap_or("bag")
                .to_string();
            let dir = out.join(&name);
            let meshes_dir = dir.join("meshes");
            std::fs::create_dir_all(&meshes_dir)
                .with_context(|| format!("creating {}", meshes_dir.display()))?;
            println!("== {} → {}", path.display(), dir.display());
            let before = observed.mesh_count();
            let opts = PlayOptions {
                rate,
                record_times: true,
                ..PlayOptions::default()
            };
            let played = player::play(&node.harness, bag, &opts, || false).await?;
            // Drain: wait until no new mesh arrived for 0.75 s (at most 20 s).
            let mut last = observed.mesh_count();
            let mut quiet = 0;
            for _ in 0..400 {
                tokio::time::sleep(Duration::from_millis(50)).await;
                let n = observed.mesh_count();
                if n == last && n > before {
                    quiet += 1;
                    if quiet >= 15 {
                        break;
                    }
                } else {
                    quiet = 0;
                }
                last = n;
            }
            // Input (topic, stamp) → put time.
            let mut put_at: HashMap<(String, i64), i64> = HashMap::new();
            for (i, t) in &played.put_times {
                if let Some(m) = bag.messages.get(*i) {
                    if let Ok(pc) = wire::decode::<PointCloud2>(&m.data) {
                        put_at.insert((m.topic.clone(), pc.header.stamp.to_nanos()), *t);
                    }
                }
            }
            let frames = write_outputs(&observed, &dir, &name, &put_at, &mut all_lat)?;
            total_frames += frames;
        }
        drop(observed);
        let summary = node.stop().await?;
        println!("\nnode summary (receipt → publish latency inside the node):");
        print_summary(&summary);
        all_lat.sort_by(f64::total_cmp);
        println!(
            "\ndemo: {} object frames received over zenoh; publish→mesh-receipt latency ms p50 {:.1} p95 {:.1} max {:.1}; {:.1} s in all. Outputs in {}",
            total_frames,
            percentile(&all_lat, 0.5),
            percentile(&all_lat, 0.95),
            all_lat.last().copied().unwrap_or(f64::NAN),
            t0.elapsed().as_secs_f64(),
            out.display()
        );
        anyhow::Ok(())
    })
}

/// Take everything the observer received for one bag: meshes to PLY, all
/// outputs to `<dir>/<name>_sepmem.mcap`; print one line per object frame.
/// Returns the number of meshes.
fn write_outputs(
    observed: &Observed,
    dir: &Path,
    name: &str,
    put_at: &HashMap<(String, i64), i64>,
    lat: &mut Vec<f64>,
) -> Result<usize> {
    let bag_path = dir.join(format!("{name}_sepmem.mcap"));
    let mut writer = BagWriter::create(&bag_path)
        .with_context(|| format!("creating output bag {}", bag_path.display()))?;
    let mut frames = 0;
    let mut index: HashMap<String, usize> = HashMap::new();
    println!(
        "{:<34} {:>5} {:>6} {:<5} {:>4} {:>6} {:<11} {:>9}",
        "stream", "frame", "verts", "path", "it", "eta_g", "quality", "latency"
    );
    for (type_name, inbox) in &observed.inboxes {
        let samples = std::mem::take(&mut *inbox_lock(inbox));
        for s in samples {
            let Ok(topic) = &s.topic else { continue };
            writer.add_topic(topic, type_name, Qos::default())?;
            let t = u64::try_from(s.received_ns).unwrap_or(0);
            writer.write_raw(topic, t, t, &s.payload)?;
            if *type_name != SurfaceMesh::TYPE_NAME {
                continue;
            }
            let msg = match wire::decode::<SurfaceMesh>(&s.payload) {
                Ok(m) => m,
                Err(e) => {
                    println!("undecodable mesh on {topic}: {e}");
                    continue;
                }
            };
            let input_topic = msg.stream_id.split('#').next().unwrap_or("").to_string();
            let latency = put_at
                .get(&(input_topic, msg.header.stamp.to_nanos()))
                .map(|p| (s.received_ns - p) as f64 * 1e-6);
            if let Some(l) = latency {
                lat.push(l);
            }
            let k = index.entry(msg.stream_id.clone()).or_default();
            let mesh = trimesh_from_surface(&msg)?;
            let file = format!(
                "{}_{:04}.ply",
                msg.stream_id
                    .trim_start_matches('/')
                    .replace(['/', '#'], "_"),
                k
            );
            sepmem::io::save_mesh(dir.join("meshes").join(file), &mesh)?;
            println!(
                "{:<34} {:>5} {:>6} {:<5} {:>4} {:>6.3} {:<11} {:>9}",
                msg.stream_id,
                k,
                msg.vertices.len(),
                if msg.warm_start { "warm" } else { "cold" },
                msg.iterations,
                msg.global_separability,
                quality_name(msg.quality),
                latency.map_or_else(|| "-".to_string(), |l| format!("{l:.1} ms"))
            );
            *k += 1;
            frames += 1;
        }
    }
    let s = writer.finish()?;
    println!(
        "{frames} meshes → {} ; bag {} ({} topics)",
        dir.join("meshes").display(),
        s.mcap_path.display(),
        s.counts.len()
    );
    Ok(frames)
}

/// The name of a `SurfaceMesh.quality` value, for the table.
fn quality_name(q: u8) -> &'static str {
    match q {
        SurfaceMesh::FITTED => "fitted",
        SurfaceMesh::UNCONVERGED => "UNCONVERGED",
        SurfaceMesh::UNFITTED => "UNFITTED",
        SurfaceMesh::HELD => "held",
        _ => "?",
    }
}
