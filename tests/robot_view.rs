//! The committed robot's-view sequences (issue 20): `sepmem synth` bags
//! under `tests/data/bags/robot_view` (made by `make_synth_bags.sh`, a
//! 480×360 depth camera at 1 m with Kinect noise): the capsule,
//! rounded box, bent tube and YCB banana turning 180° over 30 frames, the
//! bent tube orbited by the camera, and three shapes swapped on one stream.
//!
//! Every sequence replays with the defaults (the fused model on): every
//! frame meshed and the model under the cap the configuration states. The
//! fused model's carving (`model::Carving`: on the fused points the
//! membrane's inward force acts only in space the views saw empty) must
//! close the box, the capsule and the bent tube: last-third F and volume
//! IoU above floors, and no frame's mesh past 1.3 (box, capsule) or 2
//! (tube) times the true volume. Without the carving the
//! box's fused points crumpled the membrane from frame 18 on (last-third
//! F 0.420, IoU 0.465) and the tube's mesh reached 4–6× its volume.
//!
//! These are floors under what holds now, not the acceptance
//! (last-third F ≥ 0.85, seen side ≥ 0.97, IoU ≥ 0.8 on every shape),
//! which sepmem does not reach yet.
#![allow(clippy::unwrap_used)]

mod common;

use common::{figure, sepmem_stdout as sepmem};

/// `sepmem replay -q` of the committed bag `name`, with the defaults.
fn replay(name: &str) -> String {
    replay_with(name, &[])
}

/// `sepmem replay` of the committed bag `name` with `args` added.
fn replay_with(name: &str, args: &[&str]) -> String {
    let bag = common::data_dir().join(format!("bags/robot_view/{name}.mcap"));
    let mut all = vec!["replay", bag.to_str().unwrap()];
    all.extend_from_slice(if args.is_empty() { &["-q"] } else { args });
    let out = sepmem(&all);
    eprintln!("{name}: {out}");
    out
}

/// The line of `out` that starts with `prefix`.
fn line<'a>(out: &'a str, prefix: &str) -> &'a str {
    out.lines()
        .find(|l| l.starts_with(prefix))
        .unwrap_or_else(|| panic!("no `{prefix}` line in {out}"))
}

/// Every frame meshed, and the fused model within its stated cap.
fn assert_meshed_within_the_cap(name: &str, out: &str) {
    assert!(out.contains("30 frames ok"), "{name}: {out}");
    assert!(out.contains(" 0 failed"), "{name}: {out}");
    let model = line(out, "model ");
    let held = figure(model, "at most ");
    let cap = figure(model, "(cap ");
    // The cap of launch/sepmem.json5 at the defaults: max_voxels * 66 +
    // (max_views + 1) * 4 * view_side^2 = 60000, 12, 160 (in KiB).
    let stated = (60_000.0 * 66.0 + 13.0 * 4.0 * 160.0 * 160.0) / 1024.0;
    assert!((cap - stated).abs() < 0.1, "{name}: cap {cap} KiB: {model}");
    assert!(held > 0.0 && held <= cap, "{name}: {model}");
}

/// (last-third F, last-third volume IoU, largest volume ratio) of
/// `out`'s one stream.
fn closure(out: &str) -> (f64, f64, f64) {
    let view = line(out, "view ");
    let last = &view[view.find("last third").unwrap()..];
    let score = line(out, "score ");
    (
        figure(last, "last third (10): F "),
        figure(last, "IoU "),
        figure(&score[score.find("volume ratio").unwrap()..], " max "),
    )
}

#[test]
fn every_committed_sequence_is_meshed_within_the_model_cap() {
    for name in ["turn_ycb_banana", "swap"] {
        assert_meshed_within_the_cap(name, &replay(name));
    }
}

#[test]
fn the_carved_model_closes_the_box_capsule_and_bent_tube() {
    // (last-third F floor, last-third IoU floor, largest volume ratio
    // ceiling). Measured with the carving: box 0.729, 0.881, 1.14;
    // capsule 0.513, 0.702, 1.11; bent tube 0.547, 0.611, 1.72; orbited
    // 0.480, 0.566, 1.41. Without it: box 0.420, 0.465, 1.38; capsule
    // 0.471, 0.659, 1.60; bent tube 0.308, 0.324, 4.14; orbited 0.295,
    // 0.278, 6.37.
    for (name, f_min, iou_min, ratio_max) in [
        ("turn_rounded_box", 0.65, 0.8, 1.3),
        ("turn_capsule", 0.48, 0.65, 1.3),
        ("turn_bent_tube", 0.48, 0.5, 2.0),
        ("orbit_bent_tube", 0.42, 0.45, 2.0),
    ] {
        let out = replay(name);
        assert_meshed_within_the_cap(name, &out);
        let (f, iou, ratio) = closure(&out);
        assert!(f >= f_min, "{name}: last-third F {f}");
        assert!(iou >= iou_min, "{name}: last-third IoU {iou}");
        assert!(ratio <= ratio_max, "{name}: volume ratio up to {ratio}");
    }
}

#[test]
fn a_refit_keeps_the_model_where_only_the_surface_was_lost() {
    // `pipeline.refit`: the turning capsule's and the box's warm surfaces
    // lose a quarter of the points (frames 26 and 10), but the fused
    // model still explains them; the refit starts the membrane cold on the
    // model instead of restarting it from one view. Measured last-third F:
    // capsule 0.513 -> 0.585, box 0.729 -> 0.754 (IoU 0.881 -> 0.914).
    let refit = "pipeline.refit={min_model_inliers: 0.75}";
    for (name, gain) in [("turn_capsule", 0.04), ("turn_rounded_box", 0.0)] {
        let (off, ..) = closure(&replay(name));
        let out = replay_with(name, &["--set", refit]);
        assert!(out.contains(" refit("), "{name}: no refit frame: {out}");
        assert!(!out.contains("lost_track("), "{name}: lost track: {out}");
        assert_meshed_within_the_cap(name, &out);
        let (on, iou, ratio) = closure(&out);
        assert!(
            on >= off + gain,
            "{name}: last-third F {on} with, {off} without"
        );
        assert!(
            iou >= 0.75 && ratio <= 1.3,
            "{name}: IoU {iou}, volume ratio up to {ratio}"
        );
    }
}
