//! The hostile streams of `sepmem bench-node --hostile` (the soak): what a
//! robot's network can carry besides healthy clouds, each one an attack the
//! node met in issue 22, with the `/diagnostics` reason it must be counted
//! under.
//!
//! * `poison`: the 133-byte PointCloud2 (width = height = 0, x y z and one
//!   INT8 field of count 4·10⁹, point_step 4·10⁹ + 12), 2 Hz → `invalid_layout`.
//! * `bomb`: 20 000 points in 400 labels of 50, 1 Hz → `objects_skipped`.
//! * `churn`: 2 000 points with a new label every frame, 10 Hz →
//!   `labels_reidentified` (each new label takes over the tracker of the
//!   one before, `pipeline.objects.reidentify`).
//! * `oversized`: alternately a message above zenoh's receive limit (dropped
//!   by zenoh while it arrives, never held whole; the node cannot count it)
//!   and a cloud just above `wire.max_bytes` that zenoh delivers, 1 Hz →
//!   `too_large`.
//! * `malformed`: healthy clouds truncated, with a bad encapsulation header
//!   or with forged lengths, 5 Hz → `malformed_cdr`.

use anyhow::{Context, Result};
use sepmem::cloud::{PointCloud, Vec3};
use sepmem::node::loopback::LoopbackNode;
use sepmem::node::reasons;
use sepmem::transport::attachment::now_ns;
use sepmem::transport::liveliness::Qos;
use sepmem::transport::{RosPublisher, RosType};
use sepmem::wire::msgs::{DiagnosticArray, Header, PointCloud2, PointField, Time};
use sepmem::wire::pointcloud2::encode_pointcloud2;
use sepmem::wire::{self, RosMessage};
use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};
use std::time::Duration;
use zenoh::bytes::ZBytes;

/// The hostile kinds and the reason each must be counted under.
pub const KINDS: [(&str, &str); 5] = [
    ("poison", reasons::INVALID_LAYOUT),
    ("bomb", reasons::OBJECTS_SKIPPED),
    ("churn", reasons::LABELS_REIDENTIFIED),
    ("oversized", reasons::TOO_LARGE),
    ("malformed", reasons::MALFORMED_CDR),
];

/// Makes the `k`-th message of a hostile stream. A fixed message is a
/// shared [`ZBytes`], put without a copy: the harness's own 8-9 MiB copies
/// would otherwise sit in the process's RSS next to the node's.
type Maker = Box<dyn FnMut(u64) -> ZBytes + Send>;

/// One hostile stream.
pub struct Hostile {
    /// Short name (`poison`, `bomb` …).
    pub name: &'static str,
    period: Duration,
    make: Maker,
}

/// The topic of a hostile stream.
pub fn topic(name: &str) -> String {
    format!("/bench/hostile/{name}/points")
}

fn header() -> Header {
    Header {
        stamp: Time::from_nanos(now_ns()),
        frame_id: "hostile".into(),
    }
}

/// Deterministic pseudo-random numbers (xorshift64*).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// `n` points on a sphere of radius `r` about `c`.
fn ball(rng: &mut Rng, c: Vec3, r: f64, n: usize) -> Vec<Vec3> {
    (0..n)
        .map(|_| {
            let z = 2.0 * rng.unit() - 1.0;
            let a = std::f64::consts::TAU * rng.unit();
            let s = (1.0 - z * z).sqrt();
            c + Vec3::new(s * a.cos(), s * a.sin(), z) * r
        })
        .collect()
}

fn labelled(points: Vec<Vec3>, labels: Vec<f32>) -> Result<Vec<u8>> {
    let mut cloud = PointCloud::from_points(points);
    cloud.set_attribute("label", labels)?;
    Ok(wire::encode(&encode_pointcloud2(&cloud, header()))?)
}

/// The poisoned PointCloud2 of issue 22.
pub fn poisoned() -> Result<Vec<u8>> {
    let f = PointField::new;
    let msg = PointCloud2 {
        header: header(),
        height: 0,
        width: 0,
        fields: vec![
            f("x", 0, PointField::FLOAT32, 1),
            f("y", 4, PointField::FLOAT32, 1),
            f("z", 8, PointField::FLOAT32, 1),
            f("p", 12, PointField::INT8, 4_000_000_000),
        ],
        is_bigendian: false,
        point_step: 4_000_000_012,
        row_step: 0,
        data: Vec::new(),
        is_dense: true,
    };
    Ok(wire::encode(&msg)?)
}

/// 400 labels of 50 points (20 000 points).
fn label_bomb() -> Result<Vec<u8>> {
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    let (mut pts, mut labels) = (Vec::new(), Vec::new());
    for l in 1..=400u32 {
        let c = Vec3::new(f64::from(l % 20) * 0.1, f64::from(l / 20) * 0.1, 1.5);
        pts.extend(ball(&mut rng, c, 0.02, 50));
        labels.extend(std::iter::repeat_n(l as f32, 50));
    }
    labelled(pts, labels)
}

/// The messages of each hostile stream; `max_bytes` is `wire.max_bytes`,
/// `transport_limit` zenoh's receive limit the node sets from it, and
/// `healthy` one healthy cloud to mutate.
///
/// # Errors
/// When a message cannot be encoded.
pub fn streams(max_bytes: usize, transport_limit: usize, healthy: Vec<u8>) -> Result<Vec<Hostile>> {
    let poison = ZBytes::from(poisoned()?);
    let bomb = ZBytes::from(label_bomb()?);
    let mut rng = Rng(7);
    let churn_points = ball(&mut rng, Vec3::new(-0.5, 0.0, 1.2), 0.08, 2000);
    let big = ZBytes::from(vec![0u8; transport_limit + (1 << 20)]);
    let mut just_over =
        encode_pointcloud2(&PointCloud::from_points(vec![Vec3::zeros(); 4]), header());
    just_over.data = vec![0u8; max_bytes + 1024];
    let just_over = ZBytes::from(wire::encode(&just_over)?);
    let ms = Duration::from_millis;
    Ok(vec![
        Hostile {
            name: "poison",
            period: ms(500),
            make: Box::new(move |_| poison.clone()),
        },
        Hostile {
            name: "bomb",
            period: ms(1000),
            make: Box::new(move |_| bomb.clone()),
        },
        Hostile {
            name: "churn",
            period: ms(100),
            make: Box::new(move |k| {
                let labels = vec![(k % 1_000_000 + 1) as f32; churn_points.len()];
                ZBytes::from(labelled(churn_points.clone(), labels).unwrap_or_default())
            }),
        },
        Hostile {
            name: "oversized",
            period: ms(1000),
            make: Box::new(move |k| {
                if k % 2 == 0 {
                    big.clone()
                } else {
                    just_over.clone()
                }
            }),
        },
        Hostile {
            name: "malformed",
            period: ms(200),
            make: Box::new(move |k| ZBytes::from(malformed(&healthy, k, &mut rng))),
        },
    ])
}

/// A healthy message broken in one of three ways.
fn malformed(healthy: &[u8], k: u64, rng: &mut Rng) -> Vec<u8> {
    let mut b = healthy.to_vec();
    match k % 3 {
        // Truncated somewhere in the header or the fields.
        0 => b.truncate(4 + (rng.next() % 200) as usize),
        // An encapsulation this decoder does not speak (XCDR2).
        1 => b[1] = 0x07,
        // The frame_id length forged to 2 GiB.
        _ => b[12..16].copy_from_slice(&0x7fff_fff0u32.to_le_bytes()),
    }
    b
}

/// Publish the hostile streams until `end_ns`; each task returns its
/// publisher (to undeclare) and how many messages it sent.
///
/// # Errors
/// When a publisher cannot be declared.
pub async fn spawn(
    node: &LoopbackNode,
    hostile: Vec<Hostile>,
    end_ns: i64,
) -> Result<Vec<(&'static str, tokio::task::JoinHandle<(RosPublisher, u64)>)>> {
    let ty = RosType::new(PointCloud2::TYPE_NAME, PointCloud2::TYPE_HASH);
    let mut tasks = Vec::new();
    for mut h in hostile {
        let p = node
            .harness
            .publisher(&topic(h.name), &ty, Qos::SENSOR_DATA)
            .await
            .with_context(|| format!("declaring the {} publisher", h.name))?;
        tasks.push((
            h.name,
            tokio::spawn(async move {
                let mut tick = tokio::time::interval(h.period);
                tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
                let mut k = 0u64;
                while now_ns() < end_ns {
                    tick.tick().await;
                    if p.put((h.make)(k)).await.is_ok() {
                        k += 1;
                    }
                }
                (p, k)
            }),
        ));
    }
    Ok(tasks)
}

/// What the observer saw on `/diagnostics`.
#[derive(Debug, Default, Clone)]
pub struct DiagSeen {
    /// Arrays received.
    pub arrays: u64,
    /// Largest array (bytes).
    pub max_bytes: usize,
    /// Most statuses in one array.
    pub max_statuses: usize,
    /// The node status's values of the last array.
    pub node_values: BTreeMap<String, String>,
    /// Per hostile topic, the highest level seen and a message at it.
    pub worst: BTreeMap<String, (u8, String)>,
    /// The fused models' bytes (`model_bytes`) summed over the objects of
    /// the last array.
    pub model_bytes_now: usize,
    /// The largest one object's fused model reported over the run.
    pub model_bytes_max: usize,
    /// The statuses of the healthy streams' objects (every topic but the
    /// hostile ones), counted by level: OK, WARN, ERROR, STALE.
    pub healthy_levels: [u64; 4],
}

/// Watch the node's `/diagnostics`.
///
/// # Errors
/// When the subscription cannot be declared.
pub async fn watch_diagnostics(
    node: &LoopbackNode,
    topic_name: &str,
) -> Result<(zenoh::pubsub::Subscriber<()>, Arc<Mutex<DiagSeen>>)> {
    let seen: Arc<Mutex<DiagSeen>> = Arc::default();
    let s2 = seen.clone();
    let sub = node
        .harness
        .subscribe(
            topic_name,
            &RosType::new(DiagnosticArray::TYPE_NAME, DiagnosticArray::TYPE_HASH),
            move |s| {
                let Ok(a) = wire::decode::<DiagnosticArray>(&s.payload) else {
                    return;
                };
                let Ok(mut seen) = s2.lock() else { return };
                seen.arrays += 1;
                seen.max_bytes = seen.max_bytes.max(s.payload.len());
                seen.max_statuses = seen.max_statuses.max(a.status.len());
                let models: Vec<usize> = a
                    .status
                    .iter()
                    .flat_map(|st| &st.values)
                    .filter(|kv| kv.key == "model_bytes")
                    .filter_map(|kv| kv.value.parse().ok())
                    .collect();
                seen.model_bytes_now = models.iter().sum();
                seen.model_bytes_max = models.into_iter().fold(seen.model_bytes_max, usize::max);
                for st in &a.status {
                    if st.name.ends_with(": node") {
                        seen.node_values = st
                            .values
                            .iter()
                            .map(|kv| (kv.key.clone(), kv.value.clone()))
                            .collect();
                    } else if let Some(t) = st.values.iter().find(|kv| kv.key == "topic") {
                        let hostile = t.value.starts_with("/bench/hostile/");
                        if let (false, Some(n)) =
                            (hostile, seen.healthy_levels.get_mut(usize::from(st.level)))
                        {
                            *n += 1;
                        }
                        if hostile {
                            let w = seen
                                .worst
                                .entry(t.value.clone())
                                .or_insert((0, String::new()));
                            if st.level > w.0 && st.level != 3 {
                                *w = (st.level, st.message.clone());
                            }
                        }
                    }
                }
            },
        )
        .await?;
    Ok((sub, seen))
}
