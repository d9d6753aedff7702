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
//! model within two frames, and the new object's F recovers within five,
//! also when the new object's points fit the old one's surface well enough
//! that the track is not lost.
//! Close up (0.5-0.55 m, 13-22 k points a frame): a bent tube orbited
//! hides its middle end-on, and its far arm must stay part of the object
//! (the fused model's box holds it) rather than go as a detached group;
//! a turning can must be completed as a solid of revolution.
//! The capsule and bent tube are tests/robot_view.rs.
#![allow(clippy::unwrap_used)]

mod common;

use common::{figure, sepmem_stdout as sepmem};

/// `sepmem synth` with `args` into `dir/name.mcap`; its path.
fn synth(dir: &std::path::Path, name: &str, args: &[&str]) -> String {
    let bag = dir.join(format!("{name}.mcap"));
    let bag = bag.to_str().unwrap().to_string();
    let mut all = vec!["synth", "-q", "-o", &bag];
    all.extend_from_slice(args);
    sepmem(&all);
    bag
}

/// `sepmem replay -q` of `bag` on single views (`pipeline.model` null),
/// without the flying-pixel filter (`pipeline.flying` null).
fn single_view_replay(bag: &str) -> String {
    sepmem(&[
        "replay",
        bag,
        "-q",
        "--set",
        "pipeline.model=null",
        "--set",
        "pipeline.flying=null",
    ])
}

#[test]
fn a_smooth_object_whose_track_drifts_is_restarted_and_keeps_its_seen_side() {
    let tmp = tempfile::tempdir().unwrap();
    for (motion, seed) in [("turn", "4"), ("orbit", "7")] {
        let args = ["--shapes", "ellipsoid", "--motion", motion, "--seed", seed];
        let bag = synth(tmp.path(), motion, &args);
        // Measured, as here, without the flying-pixel filter
        // (`pipeline.flying` null). With it, the turn drops 7 points a
        // frame (outliers behind the surface, mostly) and its last third
        // falls to 0.395 against a first third of 0.458 (seen side median
        // 0.68): the track drifts without the restart this test is about;
        // the orbit scores as without.
        let out = single_view_replay(&bag);
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
        // Measured, as here, without the flying-pixel filter
        // (`pipeline.flying` null). With it (14 points a frame dropped),
        // both seeds restart once more (28 warm, 2 cold), last-third IoU
        // 0.756 and 0.761 (seen side 0.937, 0.939 against 0.893, 0.883).
        let out = single_view_replay(&bag);
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

/// `sepmem replay -q` of `shape` under `motion`, `distance` m from the
/// default camera (640x480, Kinect noise, no outliers, `--mesh-res 32`,
/// `seed`): the summary, once it has met the first frame as its only cold
/// one, and the last third's whole-object F.
fn close_up(shape: &str, motion: &str, distance: &str, seed: &str) -> (String, f64) {
    let tmp = tempfile::tempdir().unwrap();
    let args = [
        "--shapes",
        shape,
        "--motion",
        motion,
        "--distance",
        distance,
        "--mesh-res",
        "32",
        "--noise",
        "kinect",
        "--outliers",
        "0",
        "--seed",
        seed,
    ];
    let bag = synth(tmp.path(), shape, &args);
    let out = sepmem(&["replay", &bag, "-q"]);
    eprintln!("{out}");
    assert!(out.contains("30 frames ok (29 warm, 1 cold)"), "{out}");
    let view = format!("view /synth/{shape}/points");
    let view = out.lines().find(|l| l.starts_with(&view)).unwrap();
    let last = figure(view, "last third (10): F ");
    (out, last)
}

#[test]
fn a_tube_that_hides_its_middle_close_up_keeps_its_far_arm() {
    // The camera orbits the bent tube at 0.5 m (6.7 k points a frame). End
    // on, at frame 16, the tube hides its middle and its far arm lies more
    // than the near arm's box diagonal behind it: the detached-group filter
    // (src/detached.rs) dropped it (1 813 of 4 181 points), the cloud's
    // size fell by 73 % and the frame restarted cold with a new model
    // (27 warm, 3 cold; last-third F 0.657).
    // The fused model's box holds the far arm, so it stays.
    let (out, last) = close_up("bent_tube", "orbit", "0.5", "22");
    assert!(
        !out.contains("detached:"),
        "points dropped as detached: {out}"
    );
    // Measured 0.974 (0.657 when the far arm went).
    assert!(last >= 0.9, "last-third F {last}: {out}");
}

#[test]
fn a_can_close_up_is_completed_as_a_solid_of_revolution() {
    // A can turning 0.55 m from the camera (13-22 k points a frame). The
    // revolved profile of its fused points lies up to a voxel beyond the
    // silhouettes the views saw, and counted as contradicted there (15-30 %
    // of the revolved points, above `max_contradicted` 0.1): the can was
    // never completed (last-third F 0.662). Judged a fused point's
    // spacing beside the silhouette (src/model/views.rs, is_free_beyond),
    // it is: measured 0.962.
    let (out, last) = close_up("can", "turn", "0.55", "41");
    assert!(last >= 0.9, "last-third F {last}: {out}");
}

#[test]
fn a_capsule_orbited_close_up_keeps_its_track() {
    // The camera orbits a capsule 0.55 m away (seed 32). Registered on the
    // fused model with 10 steps on 500 of the frame's points, the track
    // slipped at frame 26 and the last third scored 0.878. Three more
    // steps on 1 000 points (pipeline.model_icp.refine) hold it: measured
    // 0.989.
    let (out, last) = close_up("capsule", "orbit", "0.55", "32");
    assert!(last >= 0.95, "last-third F {last}: {out}");
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
        // Measured: bottle 0.265 -> 0.594, torus 0.396 -> 0.479 (null ->
        // {}, the model's defaults and its carving).
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
    // Three shapes follow one another on one stream (the committed
    // `robot_view/swap.mcap`, `synth --motion swap`: equal shares, so the
    // swaps are at frames 10 and 20 of 30). The acceptance: the model is
    // reset within 2 frames of a swap (a cold start restarts it) and the
    // new object's F recovers within 5 frames; with and without the fused
    // model.
    let bag = common::data_dir().join("bags/robot_view/swap.mcap");
    for model in ["null", "{}"] {
        let set = format!("pipeline.model={model}");
        let out = sepmem(&[
            "replay",
            bag.to_str().unwrap(),
            "--set",
            &set,
            "--compare-cold",
        ]);
        assert_swap_recovers(&out);
    }
}

#[test]
fn a_swap_the_track_does_not_lose_restarts_the_model() {
    // A capsule, then a bent tube of the same size in its place from frame
    // 10, then a bottle from frame 20. The tube's points lie on the
    // capsule's surface closely enough that its track is not lost (the
    // previous surface still explains enough of them), and the tube
    // inherited the capsule's model and surface: F 0.21-0.27 over frames
    // 10-16. Its view sees past its own silhouette where the capsule's
    // model lies, which restarts the model (`contradicted`): the frame
    // starts warm, and the next one from the hastened rebuild of the new
    // model; the bottle's swap loses the track.
    let tmp = tempfile::tempdir().unwrap();
    let bag = synth(
        tmp.path(),
        "swap_tube",
        &[
            "--shapes",
            "capsule,bent_tube,bottle",
            "--motion",
            "swap",
            "--seed",
            "5",
        ],
    );
    let out = sepmem(&["replay", &bag, "--compare-cold"]);
    assert_swap_recovers(&out);
    let rows: Vec<&str> = out.lines().filter(|l| l.starts_with("/synth/")).collect();
    let at = (10..=12).find(|&f| rows[f].contains("contradicted("));
    let Some(at) = at else {
        panic!("no contradicted frame within 2 frames of the swap: {out}")
    };
    // That frame starts warm (no cold start's latency), and the next from
    // the rebuild of the new model it hastened.
    assert!(rows[at].contains(" warm "), "{out}");
    assert!(rows[at + 1].contains("rebuilt(1)"), "{out}");
}

#[test]
fn without_the_rebuild_a_contradicted_frame_starts_cold() {
    // The committed swap with the track never lost (`icp_min_inliers`
    // null): the bottle's view contradicts the box's model at frame 10.
    // With the rebuild (the default) that frame starts warm and the next
    // adopts the new model's rebuild; without it, no rebuild would replace
    // the box's surface, so the frame starts cold.
    let bag = common::data_dir().join("bags/robot_view/swap.mcap");
    let bag = bag.to_str().unwrap();
    let no_icp_loss = "pipeline.icp_min_inliers=null";
    for (rebuild, path) in [("{}", " warm "), ("null", " cold ")] {
        let set = format!("pipeline.rebuild={rebuild}");
        let out = sepmem(&["replay", bag, "--set", no_icp_loss, "--set", &set]);
        let rows: Vec<&str> = out.lines().filter(|l| l.starts_with("/synth/")).collect();
        let at = (10..=12).find(|&f| rows[f].contains("contradicted("));
        let Some(at) = at else {
            panic!("rebuild {rebuild}: no contradicted frame in 10..=12: {out}")
        };
        assert!(rows[at].contains(path), "rebuild {rebuild}: {out}");
    }
}

/// F_cold of warm frame `frame` in `out`'s table (`--compare-cold`).
fn cold_f(out: &str, frame: usize) -> f64 {
    let row = out
        .lines()
        .filter(|l| l.starts_with("/synth/"))
        .nth(frame)
        .unwrap();
    let header = out.lines().find(|l| l.starts_with("stream")).unwrap();
    let at = header
        .split_whitespace()
        .position(|c| c == "F_cold")
        .unwrap();
    row.split_whitespace().nth(at).unwrap().parse().unwrap()
}

/// The acceptance of [`a_swapped_object_restarts_the_track_and_recovers`]
/// on one replay's table.
fn assert_swap_recovers(out: &str) {
    let rows = frame_rows(out);
    assert_eq!(rows.len(), 30, "{out}");
    let restarted = common::model_restarts(out);
    for swap in [10, 20] {
        // Reset: a cold frame (a lost track restarts the model), or a
        // tracked frame whose view contradicted the model.
        let reset = (swap..=swap + 2).find(|&f| rows[f].0 == "cold" || restarted.contains(&f));
        let Some(reset) = reset else {
            panic!("no model reset within 2 frames of the swap at {swap}: {out}")
        };
        // Recovered: five frames on, F is back to the restart's (or the
        // next frame's, when a contradicted frame starts warm and the
        // rebuild it hastened brings the new object's cold surface there),
        // or at least what a cold start of that frame gets (the new object
        // is tracked as well as restarting it there would). Measured: both
        // swaps restart at the swap frame itself (with the model: F 0.567
        // then 0.847 five frames on, 0.559 then 0.502 against 0.366 cold;
        // without: 0.337 then 0.347, 0.401 then 0.451). The mug's restart
        // is completed as a solid of revolution (its rings all alike, its
        // axis unseen through) until its handle turns into view.
        let start = match rows[reset].0.as_str() {
            "cold" => rows[reset].1,
            _ => rows[reset].1.max(rows[reset + 1].1),
        };
        let later = rows[swap + 5].1;
        let cold = cold_f(out, swap + 5);
        assert!(
            later >= (start - 0.02).min(cold),
            "swap at {swap}: F {start} at the restart, {later} five frames on \
             ({cold} cold): {out}"
        );
        // No restart while it recovers: the new object is tracked. (Later,
        // the fused mug's track can still drift and restart: with the
        // carving, frame 28 lost track after the mug's rotation error had
        // grown to 12°.)
        let cold = (reset + 1..=swap + 5)
            .filter(|&f| rows[f].0 == "cold")
            .count();
        assert_eq!(cold, 0, "swap at {swap}: {out}");
    }
}
