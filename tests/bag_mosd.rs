//! Bags written by an independent tool (Python `rosbags`, script
//! `tests/python/make_mosd_bag.py`) from the real mOSD tabletop objects:
//! read them with sepmem's bag reader (MCAP and sqlite3) and PointCloud2
//! decoder, and check every count and coordinate against the source PCDs.
#![allow(clippy::unwrap_used)]

mod common;

use std::collections::BTreeMap;
use std::path::Path;

use sepmem::bag::{Bag, Storage};
use sepmem::wire::decode;
use sepmem::wire::msgs::{PointCloud2, RosMessage};
use sepmem::wire::pointcloud2::{decode_pointcloud2, split_by_label, WireConfig};

const FRAMES: usize = 3;
const STRIDE: usize = 4;
const DB3_STRIDE: usize = 8;
const STEP_M: f64 = 0.005;

/// `(x, y, z, rgba)` of a binary `x y z rgba` PCD.
fn read_pcd(path: &Path) -> Vec<SourcePoint> {
    let raw = std::fs::read(path).unwrap();
    let marker = b"DATA binary\n";
    let end = raw.windows(marker.len()).position(|w| w == marker).unwrap() + marker.len();
    let head = std::str::from_utf8(&raw[..end]).unwrap();
    assert!(head.contains("FIELDS x y z rgba"), "{}", path.display());
    let n: usize = head
        .lines()
        .find_map(|l| l.strip_prefix("POINTS "))
        .unwrap()
        .trim()
        .parse()
        .unwrap();
    raw[end..end + 16 * n]
        .chunks_exact(16)
        .map(|c| {
            let f = |i: usize| f32::from_le_bytes(c[i..i + 4].try_into().unwrap());
            (
                [f(0), f(4), f(8)],
                u32::from_le_bytes(c[12..16].try_into().unwrap()),
            )
        })
        .collect()
}

/// `(x, y, z)` and packed `rgba` of one source point.
type SourcePoint = ([f32; 3], u32);
/// scene → [(label, points)].
type Scenes = BTreeMap<String, Vec<(i64, Vec<SourcePoint>)>>;

/// scene → [(label, points)] from the shared dataset.
fn source_objects(datasets: &Path) -> Scenes {
    let dir = datasets.join("mosd_tabletop_segmentation/extracted_objects");
    let mut out = Scenes::new();
    let mut files: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "pcd"))
        .collect();
    files.sort();
    for p in files {
        let name = p.file_name().unwrap().to_str().unwrap().to_string();
        let mut parts = name.split('_');
        let scene = parts.next().unwrap().to_string();
        let label: i64 = parts
            .next()
            .unwrap()
            .trim_start_matches("label")
            .parse()
            .unwrap();
        out.entry(scene).or_default().push((label, read_pcd(&p)));
    }
    out
}

fn check_bag_against_sources(bag: &Bag, frames: usize, stride: usize, scenes: Option<&[&str]>) {
    let msgs = bag.read(&[]).unwrap();
    assert_eq!(msgs.len() as u64, bag.message_count());
    // Time order.
    assert!(msgs.windows(2).all(|w| w[0].log_time <= w[1].log_time));
    let Some(datasets) = common::shared_datasets("bag_mosd::check_bag_against_sources") else {
        // Without the sources, still decode every cloud.
        for m in &msgs {
            let pc = decode::<PointCloud2>(&m.data).unwrap();
            decode_pointcloud2(&pc, &WireConfig::default()).unwrap();
        }
        return;
    };
    let sources = source_objects(&datasets);
    let scene_names: Vec<String> = match scenes {
        Some(s) => s.iter().map(|s| s.to_string()).collect(),
        None => sources.keys().cloned().collect(),
    };
    assert_eq!(bag.topics.len(), scene_names.len());
    let mut frame_of: BTreeMap<String, usize> = BTreeMap::new();
    for m in &msgs {
        assert_eq!(m.type_name, PointCloud2::TYPE_NAME);
        let scene = m
            .topic
            .trim_start_matches("/mosd/")
            .trim_end_matches("/points");
        let k = *frame_of
            .entry(m.topic.clone())
            .and_modify(|k| *k += 1)
            .or_insert(0);
        let pc = decode::<PointCloud2>(&m.data).unwrap();
        assert_eq!(pc.header.stamp.to_nanos() as u64, m.log_time);
        let d = decode_pointcloud2(&pc, &WireConfig::default()).unwrap();
        assert_eq!(d.dropped_non_finite, 0);
        let parts = split_by_label(&d.cloud, "label").unwrap();
        let objects = &sources[scene];
        assert_eq!(parts.len(), objects.len(), "{}: labels", m.topic);
        for (label, src) in objects {
            let part = &parts[label];
            let expect: Vec<&SourcePoint> = src.iter().skip(k).step_by(stride).collect();
            assert_eq!(
                part.len(),
                expect.len(),
                "{} frame {k} label {label}",
                m.topic
            );
            for (i, (p, rgba)) in expect.iter().enumerate() {
                let got = part.points[i];
                assert_eq!(got.x as f32, p[0] + (k as f64 * STEP_M) as f32);
                assert_eq!(got.y as f32, p[1]);
                assert_eq!(got.z as f32, p[2]);
                let r = ((rgba >> 16) & 0xff) as f32 / 255.0;
                assert_eq!(part.attribute("r").unwrap()[i], r);
            }
        }
    }
    for s in &scene_names {
        assert_eq!(frame_of[&format!("/mosd/{s}/points")], frames - 1, "{s}");
    }
}

#[test]
fn mosd_mcap_bag_from_rosbags_matches_the_source_pcds() {
    let dir = common::data_dir().join("bags/mosd_rosbags");
    let bag = Bag::open(&dir).unwrap();
    assert_eq!(bag.storage, Storage::Mcap);
    assert_eq!(bag.topics.len(), 4);
    for t in &bag.topics {
        assert_eq!(t.type_name, PointCloud2::TYPE_NAME);
        assert_eq!(t.message_count, FRAMES as u64);
    }
    check_bag_against_sources(&bag, FRAMES, STRIDE, None);
    // The bare .mcap file opens too, with the same content.
    let file = Bag::open(&dir.join("mosd_rosbags.mcap")).unwrap();
    assert_eq!(file.topics, bag.topics);
    // Topic filter.
    let one = bag.read(&["/mosd/test31/points"]).unwrap();
    assert_eq!(one.len(), FRAMES);
}

#[test]
fn mosd_db3_bag_from_rosbags_matches_the_source_pcds() {
    let dir = common::data_dir().join("bags/mosd_rosbags_db3");
    let bag = Bag::open(&dir).unwrap();
    assert_eq!(bag.storage, Storage::Sqlite3);
    assert_eq!(bag.topics.len(), 1);
    assert_eq!(
        bag.topics[0].type_hash,
        PointCloud2::TYPE_HASH,
        "rosbags stores the RIHS01 hash in the db3 topics table"
    );
    check_bag_against_sources(&bag, 2, DB3_STRIDE, Some(&["test31"]));
    let file = Bag::open(&dir.join("mosd_rosbags_db3.db3")).unwrap();
    assert_eq!(file.read(&[]).unwrap(), bag.read(&[]).unwrap());
}

#[test]
fn non_bags_are_typed_errors() {
    let tmp = tempfile::tempdir().unwrap();
    assert!(matches!(
        Bag::open(tmp.path()),
        Err(sepmem::bag::BagError::NotABag { .. })
    ));
    let junk = tmp.path().join("junk.mcap");
    std::fs::write(&junk, b"not an mcap file at all").unwrap();
    assert!(matches!(
        Bag::open(&junk),
        Err(sepmem::bag::BagError::Mcap { .. })
    ));
    let junk = tmp.path().join("junk.db3");
    std::fs::write(&junk, b"not sqlite").unwrap();
    assert!(matches!(
        Bag::open(&junk),
        Err(sepmem::bag::BagError::Sqlite { .. })
    ));
}
