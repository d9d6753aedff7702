//! Tracking through views whose visible part changes (issue 20, deliver 4):
//! a box turning 180° in front of the depth camera goes edge-on half way,
//! one face vanishes, and the centroid of the visible points jumps by a
//! fraction of the box while the box itself turns 6° per frame. Aligned
//! from that centroid shift alone, ICP found no match within its trim, the
//! warm start lost the box (pose error 80°) and fell back to a cold start a
//! few frames later (seed 4: two cold frames, last-third volume IoU 0.009).
//! The tracker's further ICP starts (the last motion, rest; module
//! `pipeline::align`) keep it: the sequences must replay with the first
//! frame as the only cold one and a closed box over the last third.
//!
//! A smooth object's warm chain drifts instead, and its surface explains
//! ever fewer of the new points; `pipeline.icp_min_inliers` then restarts
//! the track cold: an ellipsoid turning or orbited by 180° must keep its
//! seen side and its whole-object F over the last third.
//!
//! Both run with `pipeline.model=null` (the model is on by default):
//! they test the tracker's alignment and its lost-track check, which the
//! fused model changes only through the surface it aligns to. The model's
//! own gain is another test: on a turning bottle and an orbited torus
//! `pipeline.model={}` raises the last third's whole-object F over the
//! frame-by-frame membrane. And an object
//! swapped for another on the same stream restarts the track and its
//! model within two frames, and the new object's F recovers within five.
#![allow(clippy::unwrap_used)]

mod common;

use common::sepmem_stdout as sepmem;

/// The number after `label` in `text`.
fn figure(text: &str, label: &str) -> f64 {
    let at = text
        .find(label)
        .unwrap_or_else(|| panic!("no `{label}` in {text}"));
    text[at + label.len()..]
        .split(|c: char| !(c.is_ascii_digit() || c == '.'))
        .next()
        .and_then(|w| w.parse().ok())
        .unwrap_or_else(|| panic!("no figure after `{label}` in {text}"))
}

/// `sepmem synth` with `args` into `dir/name.mcap`; its path.
fn synth(dir: &std::path::Path, name: &str, args: &[&str]) -> String {
    let bag = dir.join(format!("{name}.mcap"));
    let bag = bag.to_str().unwrap().to_string();
    let mut all = vec!["synth", "-q", "-o", &bag];
    all.extend_from_slice(args);
    sepmem(&all);
    bag
}

#[test]
fn a_smooth_object_whose_track_drifts_is_restarted_and_keeps_its_seen_side() {
    let tmp = tempfile::tempdir().unwrap();
    for (motion, seed) in [("turn", "4"), ("orbit", "7")] {
        let args = ["--shapes", "ellipsoid", "--motion", motion, "--seed", seed];
        let bag = synth(tmp.path(), motion, &args);
        let out = sepmem(&["replay", &bag, "-q", "--set", "pipeline.model=null"]);
        eprintln!("{motion}: {out}");
        let view = out
            .lines()
            .find(|l| l.starts_with("view /synth/ellipsoid/points"))
            .unwrap();
        let first = figure(view, "first third (10): F ");
        let last = figure(view, "last third (10): F ");
        let seen = figure(view, "seen side median ");
        // Measured: F 0.456 -> 0.465 (turn), 0.446 -> 0.498 (orbit); seen
        // side median 0.87, 0.92. Without the restart (icp_min_inliers
        // null): last third 0.349, 0.307; seen side 0.72, 0.75.
        assert!(
            last >= first - 0.02,
            "last third F {last} < first {first}: {view}"
        );
        assert!(seen >= 0.8, "seen side median {seen}: {view}");
    }
}

#[test]
fn a_box_turning_edge_on_stays_tracked() {
    let tmp = tempfile::tempdir().unwrap();
    for seed in ["3", "4"] {
        let args = [
            "--shapes",
            "rounded_box",
            "--motion",
            "turn",
            "--seed",
            seed,
        ];
        let bag = synth(tmp.path(), &format!("box{seed}"), &args);
        let out = sepmem(&["replay", &bag, "-q", "--set", "pipeline.model=null"]);
        eprintln!("seed {seed}: {out}");
        assert!(out.contains("30 frames ok (29 warm, 1 cold)"), "{out}");
        let view = out
            .lines()
            .find(|l| l.starts_with("view /synth/rounded_box/points"))
            .unwrap();
        let last = &view[view.find("last third").unwrap()..];
        // Measured 0.83 (seed 3: 0.75 with the centroid start alone, after
        // a cold restart; seed 4: 0.009).
        let iou = figure(last, "IoU ");
        assert!(iou >= 0.7, "last-third IoU {iou}: {view}");
    }
}

/// The whole-object F of the first and last thirds of `bag`'s one stream,
/// replayed with `sets`.
fn thirds(bag: &str, sets: &[&str]) -> (f64, f64) {
    let mut args = vec!["replay", bag, "-q"];
    for s in sets {
        args.extend(["--set", s]);
    }
    let out = sepmem(&args);
    let view = out.lines().find(|l| l.starts_with("view ")).unwrap();
    eprintln!("{sets:?}: {view}");
    (
        figure(view, "first third (10): F "),
        figure(view, "last third (10): F "),
    )
}

#[test]
fn the_fused_model_raises_the_last_third() {
    let tmp = tempfile::tempdir().unwrap();
    for (shape, motion, seed) in [("bottle", "turn", "4"), ("torus", "orbit", "7")] {
        let args = ["--shapes", shape, "--motion", motion, "--seed", seed];
        let bag = synth(tmp.path(), shape, &args);
        let (_, on) = thirds(&bag, &["pipeline.model={}"]);
        let (_, off) = thirds(&bag, &["pipeline.model=null"]);
        // Measured: bottle 0.265 -> 0.358, torus 0.396 -> 0.483 (null ->
        // {}, the model's defaults).
        assert!(
            on >= off + 0.04,
            "{shape} {motion}: last third F {on} with the model, {off} without"
        );
    }
}

/// Per-frame (path, F) of `out`'s table (the replay without `-q`).
fn frame_rows(out: &str) -> Vec<(String, f64)> {
    out.lines()
        .filter(|l| l.starts_with("/synth/"))
        .map(|l| {
            let cols: Vec<&str> = l.split_whitespace().collect();
            (cols[3].to_string(), cols[8].parse().unwrap())
        })
        .collect()
}

#[test]
fn a_swapped_object_restarts_the_track_and_recovers() {
    // Three shapes follow one another on one stream (`synth --motion swap`:
    // equal shares, so the swaps are at frames 10 and 20 of 30). The
    // acceptance: the model is reset within 2 frames of a swap (a cold
    // start restarts it) and the new object's F recovers within 5 frames;
    // with and without the fused model.
    let tmp = tempfile::tempdir().unwrap();
    let args = [
        "--shapes",
        "rounded_box,bottle,mug",
        "--motion",
        "swap",
        "--seed",
        "4",
    ];
    let bag = synth(tmp.path(), "swap", &args);
    for model in ["null", "{}"] {
        let set = format!("pipeline.model={model}");
        let out = sepmem(&["replay", &bag, "--set", &set]);
        assert_swap_recovers(&out);
    }
}

/// The acceptance of [`a_swapped_object_restarts_the_track_and_recovers`]
/// on one replay's table.
fn assert_swap_recovers(out: &str) {
    let rows = frame_rows(out);
    assert_eq!(rows.len(), 30, "{out}");
    for swap in [10, 20] {
        let reset = (swap..=swap + 2).find(|&f| rows[f].0 == "cold");
        let Some(reset) = reset else {
            panic!("no cold restart within 2 frames of the swap at {swap}: {out}")
        };
        // Measured: both swaps restart at the swap frame itself (with the
        // model: F 0.356 then 0.382 five frames on, 0.377 then 0.440;
        // without: 0.356 then 0.377, 0.385 then 0.447).
        let (start, later) = (rows[reset].1, rows[swap + 5].1);
        assert!(
            later >= start - 0.02,
            "swap at {swap}: F {start} at the restart, {later} five frames on: {out}"
        );
        // No restart between the swaps once recovered: the new object is tracked.
        let cold = (reset + 1..swap + 10)
            .filter(|&f| rows[f].0 == "cold")
            .count();
        assert_eq!(cold, 0, "swap at {swap}: {out}");
    }
}

/// The capsule and banana-like bent tube (`sepmem synth` shapes),
/// turning by 180° over 12 frames with the defaults: the track holds and
/// the whole-object F of the last third does not fall below the first's.
#[test]
fn a_turning_capsule_and_bent_tube_are_tracked() {
    let tmp = tempfile::tempdir().unwrap();
    for shape in ["capsule", "bent_tube"] {
        let args = ["--shapes", shape, "--motion", "turn", "--seed", "4"];
        let bag = synth(
            tmp.path(),
            shape,
            &[&args[..], &["--frames", "12"]].concat(),
        );
        let out = sepmem(&["replay", &bag, "-q"]);
        eprintln!("{shape}: {out}");
        let view = out.lines().find(|l| l.starts_with("view ")).unwrap();
        let first = figure(view, "first third (4): F ");
        let last = figure(view, "last third (4): F ");
        // Measured: capsule 0.407 -> 0.430, bent tube 0.311 -> 0.387 (the
        // model's voxels cost the capsule's first frame 0.08 against the raw
        // view: 0.438 -> 0.354 on the 30-frame turn).
        assert!(last >= 0.3, "{shape}: last third F {last}");
        assert!(last >= first - 0.02, "{shape}: F {first} -> {last}");
    }
}
