//! The committed robot's-view sequences (issue 20): `sepmem synth` bags
//! under `tests/data/bags/robot_view` (made by `make_synth_bags.sh`, a
//! 480×360 depth camera at 1 m with Kinect noise): the capsule,
//! rounded box, bent tube and YCB banana turning 180° over 30 frames, the
//! bent tube and the YCB banana orbited by the camera, and three shapes
//! swapped on one stream.
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
//! Three mechanisms of the warm chain are checked against themselves
//! switched off: the refit (`pipeline.refit`: a surface that no longer
//! explains the frame while the fused model does is rebuilt cold on the
//! model, which is kept), the warm enclosure (`membrane.init.
//! warm_enclose`: a warm start first pushed out beyond the points outside
//! it, so a face that turns into view is met from outside) and the
//! registration on the fused model (`pipeline.model_icp`). So are the
//! curvature unbias of the published mesh (`membrane.step.unbias`) and the
//! opt-in rule that a sample facing away from every camera takes no force
//! from the points (`membrane.step.facing_away`), without which the unseen
//! side of the YCB banana collapses onto its seen shell.
//!
//! A bottle, a capsule and a can turning about a vertical axis are
//! completed as solids of revolution (`membrane.view.revolution`), and the
//! bottle's lobe beyond that solid is carved (`carve_delta`): both are
//! checked against themselves switched off. So is a turning ball's
//! completion as a sphere (`membrane.view.sphere`), and the opt-in bound on
//! the depth of a fused bent tube's unseen side (`membrane.view.back`).
//!
//! The background rebuild (`pipeline.rebuild`: a cold membrane on a copy of
//! the fused model, off the frame path, that a warm frame three frames later
//! starts from) is checked against itself switched off too, and so is the
//! refit in the background (`pipeline.refit.path`) against the refit in
//! the frame.
//!
//! These are floors under what holds now, not the acceptance
//! (last-third F ≥ 0.85, seen side ≥ 0.97, IoU ≥ 0.8 on every shape),
//! which sepmem does not reach yet.
#![allow(clippy::unwrap_used)]

mod common;

use common::{figure, sepmem_stdout as sepmem};
use sepmem::bag::Bag;
use sepmem::config::Config;
use sepmem::membrane::StopReason;
use sepmem::pipeline::engine::decode_sample;
use sepmem::pipeline::{Deadlines, Membranes, PathReason, StartPath, StreamKey, Tracker};
use sepmem::PointCloud;
use std::time::Instant;

/// `sepmem replay -q` of the committed bag `name`, with the defaults.
fn replay(name: &str) -> String {
    replay_with(name, &["-q"])
}

/// `sepmem replay` of the committed bag `name` with `args` added (without
/// `-q` in them: the per-frame table too).
fn replay_with(name: &str, args: &[&str]) -> String {
    let bag = common::data_dir().join(format!("bags/robot_view/{name}.mcap"));
    let mut all = vec!["replay", bag.to_str().unwrap()];
    all.extend_from_slice(args);
    let out = sepmem(&all);
    eprintln!("{name}: {out}");
    out
}

/// [`replay_with`] with the background rebuild off (`pipeline.rebuild`
/// null): the warm chain the older mechanisms were measured in.
fn without_rebuild(name: &str, args: &[&str]) -> String {
    let mut all = vec!["--set", "pipeline.rebuild=null"];
    all.extend_from_slice(args);
    replay_with(name, &all)
}

/// The registration on the fused model the opt-in mechanisms below were
/// measured under: before `pipeline.model_icp.refine` and `keep_normals`
/// became defaults (stop 64). The finer registration moves the warm chains
/// these tests compare (see each test for what it measured).
const COARSE_REGISTRATION: [&str; 2] = [
    "--set",
    "pipeline.model_icp={steps: 10, trim: 0.03, max_points: 500, normal_k: 20, refine: null, keep_normals: null}",
];

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
    // (max_views + 1) * 8 * view_side^2 = 60000, 12, 160 (in KiB): each
    // view an f32 image of the object and one of what else the camera saw.
    let stated = (60_000.0 * 66.0 + 13.0 * 8.0 * 160.0 * 160.0) / 1024.0;
    assert!((cap - stated).abs() < 0.1, "{name}: cap {cap} KiB: {model}");
    assert!(held > 0.0 && held <= cap, "{name}: {model}");
    // No view restarted the model: on these clean sequences it would be a
    // view that sees the model's own surface through (`model::views`).
    assert!(!model.contains("restarted"), "{name}: {model}");
}

/// The line of `out` that starts with `prefix`, from its first `mark` on.
fn part<'a>(out: &'a str, prefix: &str, mark: &str) -> &'a str {
    let l = line(out, prefix);
    l.find(mark)
        .map(|i| &l[i..])
        .unwrap_or_else(|| panic!("no `{mark}` in {l}"))
}

/// (last-third F, last-third volume IoU, largest volume ratio) of
/// `out`'s one stream.
fn closure(out: &str) -> (f64, f64, f64) {
    let last = part(out, "view ", "last third");
    (
        figure(last, "last third (10): F "),
        figure(last, "IoU "),
        figure(part(out, "score ", "volume ratio"), " max "),
    )
}

#[test]
fn every_committed_sequence_is_meshed_within_the_model_cap() {
    for name in ["turn_ycb_banana", "swap"] {
        assert_meshed_within_the_cap(name, &replay(name));
    }
}

#[test]
fn replay_names_the_frames_whose_view_restarted_the_model() {
    // The swap with the track never lost (`icp_min_inliers` null): no lost
    // track restarts the model. The bottle stands inside the box's volume,
    // so at frame 10 its view sees through little of the box's model (0.23
    // of the voxels it judges), but most of the box's model lies beside
    // the bottle's silhouette: the model restarts there
    // (`model::ObjectModel::integrate`). (Before the silhouette counted,
    // the mug's view restarted the box-and-bottle model at frame 20; on
    // the bottle's own model it sees through 0.47 of what it judges,
    // below `reset_share`, and the bottle's model lies within the mug's
    // silhouette: the default `icp_min_inliers` loses that track,
    // tests/tracking.rs.)
    let out = replay_with("swap", &["-q", "--set", "pipeline.icp_min_inliers=null"]);
    let model = line(&out, "model ");
    let frames = common::model_restarts(&out);
    assert!(frames.iter().any(|f| (10..=12).contains(f)), "{model}");
    assert!(model.contains("reset_share"), "{model}");
}

#[test]
fn the_carved_model_closes_the_box_capsule_and_bent_tube() {
    // (last-third F floor, last-third IoU floor, largest volume ratio
    // ceiling). Measured with the defaults (the carving, the warm
    // enclosure, the refit, the registration on the model, the background
    // rebuild, the revolved completion): box 0.887, 0.948, 1.18; capsule
    // 0.998, 0.976, 1.16; bent tube 0.755, 0.784, 1.43; orbited 0.890,
    // 0.917, 1.50. Before the revolved completion: capsule 0.687, 0.836,
    // 1.21, the others the same. Before the
    // rebuild: box 0.835, 0.939, 1.13; capsule 0.659, 0.813, 1.09; bent
    // tube 0.740, 0.631, 1.39; orbited 0.873, 0.899, 1.30. Without the
    // registration on the model: box 0.804, 0.926, 1.12; capsule 0.575, 0.851, 1.06; bent tube
    // 0.554, 0.560, 1.39; orbited 0.723, 0.564, 1.30. With the carving
    // alone: box 0.729, 0.881, 1.14; capsule 0.513, 0.702,
    // 1.11; bent tube 0.547, 0.611, 1.72; orbited 0.480, 0.566, 1.41.
    // Without the carving: box 0.420, 0.465, 1.38; capsule 0.471, 0.659,
    // 1.60; bent tube 0.308, 0.324, 4.14; orbited 0.295, 0.278, 6.37.
    for (name, f_min, iou_min, ratio_max) in [
        ("turn_rounded_box", 0.77, 0.88, 1.3),
        ("turn_capsule", 0.9, 0.93, 1.3),
        ("turn_bent_tube", 0.66, 0.55, 2.0),
        ("orbit_bent_tube", 0.8, 0.8, 1.6),
    ] {
        let out = replay(name);
        assert_meshed_within_the_cap(name, &out);
        let (f, iou, ratio) = closure(&out);
        assert!(f >= f_min, "{name}: last-third F {f}");
        assert!(iou >= iou_min, "{name}: last-third IoU {iou}");
        assert!(ratio <= ratio_max, "{name}: volume ratio up to {ratio}");
        // No phantom past the silhouette: the mesh's projection beyond the
        // true outline (one pixel of slack) stays under a tenth of the
        // silhouette in every frame. Measured: box 0.038, capsule 0.020,
        // bent tube 0.058, orbited 0.052 (the turning YCB banana, whose
        // cold membranes grow fins over its concave side: 0.176).
        let excess = figure(part(&out, "view ", "silhouette excess"), " max ");
        assert!(excess <= 0.1, "{name}: silhouette excess up to {excess}");
    }
}

#[test]
fn solids_of_revolution_are_completed_and_their_lobes_carved() {
    // (last-third F, last-third IoU, largest volume ratio), measured:
    // bottle 0.928, 0.954, 1.43; without the carving 0.871, 0.926, 1.96;
    // without the completion 0.665, 0.786, 2.14. Capsule 0.998, 0.976,
    // 1.16; without the completion 0.687, 0.836, 1.22.
    let bottle = replay("turn_bottle");
    assert_meshed_within_the_cap("turn_bottle", &bottle);
    let (f, iou, ratio) = closure(&bottle);
    assert!(
        f >= 0.8 && iou >= 0.9 && ratio <= 1.5,
        "bottle: {f} {iou} {ratio}"
    );
    let uncarved = replay_with(
        "turn_bottle",
        &["-q", "--set", "membrane.view.revolution.carve_delta=null"],
    );
    let (_, _, uncarved_ratio) = closure(&uncarved);
    assert!(
        ratio + 0.3 <= uncarved_ratio,
        "bottle's lobe: {ratio} vs {uncarved_ratio} uncarved"
    );
    let off = ["-q", "--set", "membrane.view.revolution=null"];
    let (f_off, _, _) = closure(&replay_with("turn_bottle", &off));
    assert!(
        f >= f_off + 0.1,
        "bottle: F {f} vs {f_off} without the completion"
    );
    let capsule = replay("turn_capsule");
    let (f, iou, ratio) = closure(&capsule);
    assert!(
        f >= 0.9 && iou >= 0.93 && ratio <= 1.3,
        "capsule: {f} {iou} {ratio}"
    );
    assert_turns_unseen_about_its_axis("turn_capsule", &capsule);
    let (f_off, _, _) = closure(&replay_with("turn_capsule", &off));
    assert!(
        f >= f_off + 0.15,
        "capsule: F {f} vs {f_off} without the completion"
    );
    // A can: its rings all alike, its axis passes through it as no view
    // saw through the axis. Measured: 0.821, 0.949, 1.31; without the
    // completion 0.656, 0.809, 1.26.
    let can = replay("turn_can");
    assert_meshed_within_the_cap("turn_can", &can);
    let (f, iou, ratio) = closure(&can);
    assert!(
        f >= 0.75 && iou >= 0.9 && ratio <= 1.4,
        "can: {f} {iou} {ratio}"
    );
    assert_turns_unseen_about_its_axis("turn_can", &can);
    let (f_off, iou_off, _) = closure(&replay_with("turn_can", &off));
    assert!(
        f >= f_off + 0.1 && iou >= iou_off + 0.08,
        "can: F {f} IoU {iou} vs {f_off} {iou_off} without the completion"
    );
}

/// A solid of revolution turning about its own axis shows the tracker no
/// turn: the tracked pose's rotation error grows with the turn, while the
/// true surface it places stays where it is (ADD-S). Measured, last third:
/// capsule 160° and 0.74 mm, can 83° and 1.07 mm.
fn assert_turns_unseen_about_its_axis(name: &str, out: &str) {
    let last = part(out, "view ", "last third");
    let (rot, adds) = (figure(last, " rot "), figure(last, " ADD-S "));
    assert!(
        rot > 45.0 && adds < 2.0,
        "{name}: {rot}° but ADD-S {adds} mm"
    );
}

#[test]
fn a_turning_ball_is_completed_as_a_sphere() {
    // Measured: last-third F 0.997, IoU 0.986, largest volume ratio 1.00;
    // without the completion 0.541, 0.653, 0.69 (the fused model holds the
    // cap the camera faces: the ball's spin cannot be registered).
    let ball = replay("turn_sphere");
    assert_meshed_within_the_cap("turn_sphere", &ball);
    let (f, iou, ratio) = closure(&ball);
    assert!(
        f >= 0.95 && iou >= 0.93 && (0.85..=1.15).contains(&ratio),
        "ball: {f} {iou} {ratio}"
    );
    let off = ["-q", "--set", "membrane.view.sphere=null"];
    let (f_off, _, ratio_off) = closure(&replay_with("turn_sphere", &off));
    assert!(
        f >= f_off + 0.3 && ratio_off < 0.85,
        "ball: F {f} vs {f_off} (volume {ratio_off}) without the completion"
    );
}

/// The share of the frames' visible points more than 3σ outside the mesh.
fn outside_share(out: &str) -> f64 {
    let counts = part(out, "view ", "outside by > 3 sigma ");
    figure(counts, "3 sigma ") / figure(counts, " of ")
}

#[test]
fn a_refit_keeps_the_model_where_only_the_surface_was_lost() {
    // `pipeline.refit`: the turning box's warm surface loses a quarter of
    // the points twice, but the fused model still explains them; the refit
    // starts the membrane cold on the model instead of restarting the
    // model from one view. Measured last-third F 0.722 -> 0.835, IoU 0.856
    // -> 0.939 (refit null -> the default; before the registration on the
    // model, 0.713 -> 0.804 and 0.856 -> 0.926).
    // Without the background rebuild, which keeps the box's surface close
    // enough that no refit is needed (cold frames after the first 2 -> 0).
    let name = "turn_rounded_box";
    let (off_f, off_iou, _) = closure(&without_rebuild(
        name,
        &["-q", "--set", "pipeline.refit=null"],
    ));
    let out = without_rebuild(name, &[]);
    assert!(out.contains(" refit("), "{name}: no refit frame: {out}");
    assert!(!out.contains("lost_track("), "{name}: lost track: {out}");
    assert_meshed_within_the_cap(name, &out);
    let (f, iou, _) = closure(&out);
    assert!(
        f >= off_f + 0.04,
        "{name}: last-third F {f} with, {off_f} without"
    );
    assert!(
        iou >= off_iou,
        "{name}: last-third IoU {iou} with, {off_iou} without"
    );
}

#[test]
fn the_warm_start_encloses_the_faces_that_turn_into_view() {
    // `membrane.init.warm_enclose`: without it the warm surface cut the
    // corner where a face turned into view. Measured share of the visible
    // points more than 3σ outside the mesh, without -> with: box 4.7 % ->
    // 1.4 %; last-third F 0.815 -> 0.835. (Before the registration on the
    // model, also the capsule, 2.0 % -> 0.4 %; registered on the model, no
    // capsule point lies 2δ outside its warm surface, and the enclosure
    // changes nothing there.)
    let name = "turn_rounded_box";
    let off = replay_with(name, &["-q", "--set", "membrane.init.warm_enclose=null"]);
    let on = replay(name);
    let (share_off, share_on) = (outside_share(&off), outside_share(&on));
    assert!(
        share_on < 0.5 * share_off,
        "{name}: {share_on} of the points outside with, {share_off} without"
    );
    let ((f_off, ..), (f_on, ..)) = (closure(&off), closure(&on));
    assert!(
        f_on >= f_off - 0.03,
        "{name}: last-third F {f_on} with, {f_off} without"
    );
}

#[test]
fn the_fused_completion_closes_the_orbited_bent_tube() {
    // `membrane.view.fused_completion` (opt-in): in the first frames the
    // fused points are completed as one view (mirrored), and the closure
    // the warm surface carries holds. Measured on the orbited tube, without
    // -> with: last-third IoU 0.899 -> 0.909, largest volume ratio 1.30 ->
    // 1.13. (Before the registration on the model it also closed the
    // turning tube, IoU 0.560 -> 0.688; registered, that tube loses with
    // it, 0.631 -> 0.421, hence the opt-in.)
    // Measured without the background rebuild; with it, the completion
    // costs the tube IoU (0.913 -> 0.833).
    // And without the flying-pixel filter (`pipeline.flying` null): on this
    // clean bag it drops a few points, which moves the warm chain (with
    // it, IoU 0.755 with the completion, 0.938 without).
    // Under the finer registration (the defaults since stop 64) it costs
    // the orbited tube IoU too (0.910 -> 0.666, measured with
    // pipeline.icp_steps 2); the figures here are under the coarse one.
    let name = "orbit_bent_tube";
    let base = [
        &["-q", "--set", "pipeline.flying=null"][..],
        &COARSE_REGISTRATION[..],
    ]
    .concat();
    let (_, iou_off, ratio_off) = closure(&without_rebuild(name, &base));
    let out = without_rebuild(
        name,
        &[&base[..], &["--set", "membrane.view.fused_completion={}"]].concat(),
    );
    let (_, iou, ratio) = closure(&out);
    assert!(
        iou >= iou_off - 0.02,
        "{name}: last-third IoU {iou} with, {iou_off} without"
    );
    assert!(
        ratio <= ratio_off - 0.08,
        "{name}: volume ratio up to {ratio} with, {ratio_off} without"
    );
}

/// (last-third F, last-third rotation error in degrees, last-third ADD-S
/// in mm) of `out`'s one stream.
fn tracked(out: &str) -> (f64, f64, f64) {
    let last = part(out, "view ", "last third");
    (
        figure(last, "last third (10): F "),
        figure(last, " rot "),
        figure(last, " ADD-S "),
    )
}

#[test]
fn registering_on_the_fused_model_stops_the_bent_tube_drifting() {
    // `pipeline.model_icp`: each frame's motion, found on the previous
    // surface, is refined on the fused model's points. Measured, null ->
    // the default: turning tube last-third F 0.554 -> 0.740, rotation
    // error 30.9° -> 11.0°; orbited 0.723 -> 0.873, 8.3° -> 2.3°. Since
    // (30c89a2): turning 0.611 -> 0.837, 23.5° -> 6.3°, ADD-S 5.98 -> 1.62
    // mm; orbited 0.708 -> 0.904, 10.4° -> 2.7°, 2.46 -> 0.75 mm. The
    // tube is about 0.2 m long: τ (1 %) is about 2 mm.
    for name in ["turn_bent_tube", "orbit_bent_tube"] {
        let off = replay_with(name, &["-q", "--set", "pipeline.model_icp=null"]);
        let ((f_off, rot_off, adds_off), (f, rot, adds)) = (tracked(&off), tracked(&replay(name)));
        assert!(
            f >= f_off + 0.08,
            "{name}: last-third F {f} with, {f_off} without"
        );
        assert!(
            rot <= 0.6 * rot_off,
            "{name}: last-third rotation error {rot}° with, {rot_off}° without"
        );
        assert!(
            adds <= 2.5 && adds <= 0.7 * adds_off,
            "{name}: last-third ADD-S {adds} mm with, {adds_off} mm without"
        );
    }
}

#[test]
fn a_pose_the_frames_view_contradicts_gives_way_to_the_last_motion() {
    // `pipeline.pose_check`: end-on at frame 17 the turning YCB banana's
    // registration fits its few points with a pose that puts 107 of the
    // 161 model voxels the view can judge where the camera saw empty
    // space; the last frame's motion puts none there and 61 on the seen
    // surface, and replaces it. Measured, null -> the default: last-third
    // F 0.482 -> 0.588, rotation error 20.1° -> 10.2°, ADD-S 10.1 -> 5.0
    // mm, volume IoU 0.469 -> 0.657.
    let name = "turn_ycb_banana";
    let off = replay_with(name, &["-q", "--set", "pipeline.pose_check=null"]);
    let on = replay(name);
    let ((f_off, rot_off, adds_off), (f, rot, adds)) = (tracked(&off), tracked(&on));
    assert!(f >= f_off + 0.05, "last-third F {f} with, {f_off} without");
    assert!(
        rot <= 0.7 * rot_off && adds <= 0.7 * adds_off,
        "last-third rotation error {rot}° and ADD-S {adds} mm with, {rot_off}° and {adds_off} mm without"
    );
    let iou = |out: &str| closure(out).1;
    assert!(
        iou(&on) >= iou(&off) + 0.1,
        "last-third IoU {} with, {} without",
        iou(&on),
        iou(&off)
    );
}

#[test]
fn the_published_mesh_loses_the_centrings_curvature_bias() {
    // `membrane.step.unbias`: each published vertex moves out by the
    // median offset of the centring's disc on a curved surface (membrane/
    // unbias.rs). The tracking is the same with and without it, so the
    // figures differ by that move alone. Measured seen-side median, null ->
    // the default: capsule 0.901 -> 0.959, box 0.897 -> 0.924; last-third F
    // 0.999 -> 0.997, 0.869 -> 0.894. The capsule's F is 1 up to the
    // spread a small change gives (a start of the background rebuilds one
    // frame later moved single sequences by ±0.1): F may be lower by
    // `F_SPREAD` at most.
    // Both without `pipeline.snap`, which moves the seen side's vertices
    // again (`the_published_seen_side_lies_on_the_frames_points`).
    const F_SPREAD: f64 = 0.005;
    for name in ["turn_capsule", "turn_rounded_box"] {
        let no_snap = ["-q", "--set", "pipeline.snap=null"];
        let off = replay_with(
            name,
            &[&no_snap[..], &["--set", "membrane.step.unbias=null"]].concat(),
        );
        let on = replay_with(name, &no_snap);
        let seen = |out: &str| figure(line(out, "view "), "seen side median ");
        let (seen_off, seen_on) = (seen(&off), seen(&on));
        assert!(
            seen_on >= seen_off + 0.015,
            "{name}: seen side {seen_on} with, {seen_off} without"
        );
        let ((f_off, ..), (f_on, ..)) = (closure(&off), closure(&on));
        assert!(
            f_on >= f_off - F_SPREAD,
            "{name}: last-third F {f_on} with, {f_off} without"
        );
    }
}

#[test]
fn the_published_seen_side_lies_on_the_frames_points() {
    // `pipeline.snap`: the published mesh's vertices that face the camera
    // move along their rays onto a quadric of the frame's points. The
    // tracking is the same with and without it, so the figures differ by
    // that move alone. Measured, null -> the default: seen-side median box
    // 0.924 -> 0.942, bent tube 0.855 -> 0.899; visible points more than 3σ
    // outside 0.53 % -> 0.45 %, 0.34 % -> 0.33 % (the move across a grazed
    // surface is capped, `max_slide`); last-third F 0.894 -> 0.896, 0.827 ->
    // 0.832. Under the finer model registration (stop 64, measured with
    // pipeline.icp_steps 2) the tube's points outside went 0.339 % ->
    // 0.350 %: within OUT_SPREAD.
    const F_SPREAD: f64 = 0.005;
    const OUT_SPREAD: f64 = 0.0003;
    for name in ["turn_rounded_box", "turn_bent_tube"] {
        let off = replay_with(name, &["-q", "--set", "pipeline.snap=null"]);
        let on = replay(name);
        let seen = |out: &str| figure(line(out, "view "), "seen side median ");
        let (seen_off, seen_on) = (seen(&off), seen(&on));
        assert!(
            seen_on >= seen_off + 0.015,
            "{name}: seen side {seen_on} with, {seen_off} without"
        );
        let (out_off, out_on) = (outside_share(&off), outside_share(&on));
        assert!(
            out_on <= out_off + OUT_SPREAD,
            "{name}: points > 3σ outside {out_on} with, {out_off} without"
        );
        let ((f_off, ..), (f_on, ..)) = (closure(&off), closure(&on));
        assert!(
            f_on >= f_off - F_SPREAD,
            "{name}: last-third F {f_on} with, {f_off} without"
        );
    }
}

/// The smallest volume ratio over `out`'s frames (mesh over true volume).
fn smallest_volume(out: &str) -> f64 {
    figure(part(out, "score ", "volume ratio"), "min ")
}

#[test]
fn facing_away_keeps_the_unseen_side_from_collapsing_onto_the_seen_shell() {
    // `membrane.step.facing_away` (opt-in): a sample whose normal faces
    // away from every camera that saw the points does not search, so the
    // seen shell no longer pulls the unseen side onto itself from behind.
    // Measured, the default (null) -> {}: smallest volume ratio over the 30
    // frames 0.01 -> 0.20 (frames 0-14 were a flat sheet, IoU 0.02-0.07),
    // last-third volume IoU 0.473 -> 0.652.
    // Measured without the background rebuild: its cold membranes take
    // the rule only past cold_max_cos, and with it the banana's smallest
    // volume ratio is 0.04 (-0.01 without the rule).
    // Under the finer registration (the defaults since stop 64) the rule
    // lifts it less, 0.02 -> 0.11 (measured with pipeline.icp_steps 2);
    // the figures here are under the coarse one, and without
    // `pipeline.pose_check` (which replaces the registered pose at frame
    // 17 of this banana, a later mechanism).
    let name = "turn_ycb_banana";
    let coarse = &[
        &COARSE_REGISTRATION[..],
        &["--set", "pipeline.pose_check=null"],
    ]
    .concat()[..];
    let off = without_rebuild(name, &[&["-q"], coarse].concat());
    let rule = ["-q", "--set", "membrane.step.facing_away={}"];
    let on = without_rebuild(name, &[&rule[..], coarse].concat());
    let (v_off, v_on) = (smallest_volume(&off), smallest_volume(&on));
    assert!(
        v_on >= 0.15 && v_on >= v_off + 0.1,
        "{name}: smallest volume ratio {v_on} with, {v_off} without"
    );
    let ((.., iou_off, _), (.., iou_on, _)) = (closure(&off), closure(&on));
    assert!(
        iou_on >= iou_off + 0.1,
        "{name}: last-third IoU {iou_on} with, {iou_off} without"
    );
}

#[test]
fn the_back_bound_ends_the_fused_tubes_unseen_lobe() {
    // `membrane.view.back` (opt-in) on the fused model: nothing of the
    // object lies deeper along the latest view than its fused points'
    // seen extent, and the inward force pulls the unseen side in beyond
    // that. Before it applied to fused clouds it changed nothing there.
    // Measured, null -> { extent: 1.0 }: largest volume ratio 1.48 -> 1.16
    // (the first frames' lobe behind the tube), last-third F 0.832 ->
    // 0.819, visible points > 3σ outside 0.33 % -> 1.3 % (the bound cuts
    // the tube where it is deeper than wide). Measured, as here, with every
    // voxel of the model counted (`pipeline.model.confirm` null): with the
    // confirmation the bound costs more (F 0.827 -> 0.768, IoU 0.894 ->
    // 0.683), which is one more reason it stays opt-in. And without the
    // flying-pixel filter, which on this clean bag drops a dozen points and
    // moves the warm chain (`pipeline.flying` null; with it, F 0.780 / IoU
    // 0.767 with the bound, 0.791 / 0.878 without).
    // Under the finer registration (the defaults since stop 64): largest
    // volume ratio 1.61 -> 1.34, last-third F 0.744 -> 0.812, IoU 0.849 ->
    // 0.742 (the bound cuts the tube's far arm; measured with
    // pipeline.icp_steps 2); the figures here are under the coarse one.
    let name = "turn_bent_tube";
    let every = [
        &[
            "-q",
            "--set",
            "pipeline.model.confirm=null",
            "--set",
            "pipeline.flying=null",
        ][..],
        &COARSE_REGISTRATION[..],
    ]
    .concat();
    let off = replay_with(name, &every);
    let on = replay_with(
        name,
        &[&every[..], &["--set", "membrane.view.back={extent: 1.0}"]].concat(),
    );
    let ((f_off, iou_off, v_off), (f_on, iou_on, v_on)) = (closure(&off), closure(&on));
    assert!(
        v_on <= v_off - 0.15 && v_on < 1.3,
        "{name}: largest volume ratio {v_on} with, {v_off} without"
    );
    assert!(
        f_on >= f_off - 0.05 && iou_on >= iou_off - 0.05,
        "{name}: last-third F {f_on} / IoU {iou_on} with, {f_off} / {iou_off} without"
    );
}

/// Frames after the first that started cold, from the per-frame table.
fn cold_frames(out: &str) -> usize {
    out.lines()
        .filter(|l| l.starts_with('/') && l.split_whitespace().nth(3) == Some("cold"))
        .count()
        .saturating_sub(1)
}

#[test]
fn the_background_rebuild_restarts_the_warm_chain_from_a_cold_membrane_on_the_model() {
    // `pipeline.rebuild`: the warm chain keeps the pole axis, grid and folds
    // of its first cold start; a cold membrane on the fused model, run in
    // the background and adopted three frames later, does not. Measured
    // (null -> the default): box last-third F 0.859 -> 0.892, cold frames
    // after the first 2 -> 0 (its refits are no longer needed), points
    // more than 3σ outside 1.26 % -> 0.53 %; bent tube last-third IoU
    // 0.632 -> 0.783, points outside 3.3 % -> 1.7 %. With the finer model
    // registration (`pipeline.model_icp.refine`, the default since stop
    // 64) the warm chain alone holds the box better and the rebuild adds
    // less: F 0.897 -> 0.904, points outside 0.65 % -> 0.52 %; the figures
    // here are under the coarse registration.
    for name in ["turn_rounded_box", "turn_bent_tube"] {
        let off = without_rebuild(name, &COARSE_REGISTRATION);
        let on = replay_with(name, &COARSE_REGISTRATION);
        assert!(!off.contains(" rebuilt("), "{name}: rebuilt with null");
        assert!(on.contains(" rebuilt(3)"), "{name}: no rebuilt frame");
        assert_meshed_within_the_cap(name, &on);
        let ((f0, iou0, _), (f1, iou1, _)) = (closure(&off), closure(&on));
        assert!(
            outside_share(&on) <= 0.75 * outside_share(&off),
            "{name}: {} of the points outside with, {} without",
            outside_share(&on),
            outside_share(&off)
        );
        assert!(
            cold_frames(&on) <= cold_frames(&off),
            "{name}: {} cold frames with, {} without",
            cold_frames(&on),
            cold_frames(&off)
        );
        if name == "turn_rounded_box" {
            assert!(
                f1 >= f0 + 0.02,
                "{name}: last-third F {f1} with, {f0} without"
            );
        } else {
            assert!(
                iou1 >= iou0 + 0.08,
                "{name}: last-third IoU {iou1} with, {iou0} without"
            );
        }
    }
}

/// The seen side's share of the last third (the `view` line).
fn last_third_seen(out: &str) -> f64 {
    figure(part(out, "view ", "last third"), "seen side ")
}

#[test]
fn a_rebuild_that_fits_the_frame_worse_than_the_warm_start_is_refused() {
    // `pipeline.rebuild.max_misfit`: late in the turn the bottle's warm
    // chain has converged, and a cold membrane on its model can fit the
    // frame worse. Measured when the default became 2 (3 -> 2, with
    // `pipeline.model.confirm` and `pipeline.flying` null): last-third F
    // 0.926 -> 0.969, seen side 0.888 -> 0.941, adopted rebuilds 9 -> 6.
    // Since the revolved completion is judged a fused point's spacing
    // beside the silhouettes (stop 63), the bottle's rebuilds fit within 2
    // times there (both settings adopt 9, F 0.912). With the defaults one
    // still fits worse: adopted 9 -> 8, last-third F 0.933 -> 0.937, seen
    // side 0.930 -> 0.937.
    // Under the finer registration (the defaults since stop 64) both adopt
    // 9: the figures here are under the coarse one.
    let name = "turn_bottle";
    let coarse = &COARSE_REGISTRATION[..];
    let lenient = replay_with(
        name,
        &[coarse, &["--set", "pipeline.rebuild.max_misfit=3.0"]].concat(),
    );
    let strict = replay_with(name, coarse);
    let adopted = |out: &str| out.matches(" rebuilt(").count();
    assert!(
        adopted(&strict) < adopted(&lenient),
        "{name}: {} rebuilds adopted at 2, {} at 3",
        adopted(&strict),
        adopted(&lenient)
    );
    let ((f3, _, _), (f2, _, _)) = (closure(&lenient), closure(&strict));
    assert!(f2 >= f3, "{name}: last-third F {f2} at 2, {f3} at 3");
    let (s3, s2) = (last_third_seen(&lenient), last_third_seen(&strict));
    assert!(
        s2 >= s3,
        "{name}: last-third seen side {s2} at 2, {s3} at 3"
    );
}

/// Frames whose surface failed the frame but the fused model did not, and
/// that started warm (`refit(…)` on a warm row of the per-frame table).
fn warm_refits(out: &str) -> usize {
    out.lines()
        .filter(|l| l.starts_with('/'))
        .map(|l| l.split_whitespace().collect::<Vec<_>>())
        .filter(|w| w.get(3) == Some(&"warm") && w.get(4).is_some_and(|r| r.starts_with("refit(")))
        .count()
}

#[test]
fn a_refit_in_the_background_keeps_the_orbited_banana_warm_and_its_model() {
    // `pipeline.refit.path`: the orbited YCB banana's warm surface fails
    // the frame at an end-on view while the fused model explains it. A
    // refit in the frame ("cold") then fails the next frame too, so the
    // track is lost and the model restarts from one end-on view; in the
    // background the frame stays warm, the model is kept, and the next
    // frame adopts a rebuild on it. Measured ("cold" -> the default): cold
    // frames after the first 2 -> 0, last-third F 0.573 -> 0.722, IoU 0.200
    // -> 0.587.
    let name = "orbit_ycb_banana";
    let cold = replay_with(name, &["--set", "pipeline.refit.path=cold"]);
    let on = replay_with(name, &[]);
    assert_meshed_within_the_cap(name, &on);
    assert!(cold_frames(&cold) >= 1, "{name}: no cold refit: {cold}");
    assert_eq!(cold_frames(&on), 0, "{name}: cold frames: {on}");
    assert!(warm_refits(&on) >= 1, "{name}: no warm refit: {on}");
    assert!(
        on.contains(" rebuilt(1)"),
        "{name}: no refit rebuild adopted"
    );
    // Replay (no deadline) waits for each rebuild it adopts, and tells
    // those waits apart from the warm frames' own latency.
    let adopted = on.lines().filter(|l| l.contains(" rebuilt(")).count();
    let summary = line(&on, "summary: ");
    // A frame waits for each rebuild that is due, adopts it or refuses it
    // (`max_misfit`).
    let at = summary
        .find(" waited for a rebuild (adopted or refused), ")
        .unwrap_or_else(|| panic!("no waits: {summary}"));
    let waited: usize = summary[..at]
        .rsplit(' ')
        .next()
        .and_then(|w| w.parse().ok())
        .unwrap_or_else(|| panic!("no count of waits: {summary}"));
    assert!(
        waited >= adopted,
        "{adopted} adopted, {waited} waited: {summary}"
    );
    let after = |label: &str| &summary[summary.find(label).unwrap()..];
    let with = figure(after("warm frames: "), " max ");
    let without = figure(after("without the waits: "), " max ");
    assert!(without <= with, "{summary}");
    let ((f0, iou0, _), (f1, iou1, _)) = (closure(&cold), closure(&on));
    assert!(
        f1 >= f0 + 0.08,
        "{name}: last-third F {f1} in the background, {f0} in the frame"
    );
    // With the finer model registration (stop 64, measured with
    // pipeline.icp_steps 2): IoU 0.400 -> 0.577.
    assert!(
        iou1 >= iou0 + 0.15,
        "{name}: last-third IoU {iou1} in the background, {iou0} in the frame"
    );
}

/// The default configuration, its membranes, and the clouds of `topic` in
/// the committed robot-view bag `name`, decoded as the node decodes them.
fn frames_of(name: &str, topic: &str) -> (Config, Membranes, Vec<PointCloud>) {
    let path = common::data_dir().join(format!("bags/robot_view/{name}.mcap"));
    let bag = Bag::open(&path).unwrap();
    let cfg = Config::load(None, &[]).unwrap();
    let membranes = Membranes::new(&cfg.membrane, &cfg.pipeline).unwrap();
    let clouds = bag
        .read(&[topic])
        .unwrap()
        .into_iter()
        .map(|m| {
            let sample = decode_sample(topic, &m.data, &cfg.wire, &cfg.pipeline).unwrap();
            sample.streams.into_iter().next().unwrap().cloud
        })
        .collect();
    (cfg, membranes, clouds)
}

#[test]
fn a_refit_keeps_its_rebuild_when_frames_do_not_wait_for_it() {
    // With a deadline (the live node) a frame adopts the stream's rebuild
    // only once it is done. Replacing the rebuild in flight at every refit
    // frame starved the refits: `sepmem replay --realtime` of the orbited
    // YCB banana refitted 18 frames in a row from frame 12 and adopted
    // none. Here each frame has a deadline (a minute away: its iterations
    // are not cut, and it never waits for the rebuild), and a refit that
    // follows a refit keeps the rebuild in flight. A rebuild, a cold
    // membrane of tens of iterations, takes longer than a warm frame of
    // four, so refits follow one another at the banana's end-on views.
    // A rebuild still not done `starved_frames` after it was due (the
    // refit made it due the next frame) is starved and restarts, from this
    // frame, at a higher priority: on a machine busy with other tests.
    let topic = "/synth/YcbBanana/points";
    let (cfg, membranes, clouds) = frames_of("orbit_ycb_banana", topic);
    let rebuild = cfg.pipeline.rebuild.as_ref().unwrap();
    let starved = rebuild.starved_frames.map_or(u64::MAX, |n| n.get() as u64);
    let mut tracker = Tracker::new(StreamKey::topic(topic));
    let (mut last, mut kept) = (None, 0);
    for cloud in &clouds {
        let deadlines = Deadlines::after(Instant::now(), 60_000.0, 60_000.0);
        let r = tracker
            .process_by(cloud, &membranes, &cfg.pipeline, deadlines)
            .unwrap();
        let refit = matches!(r.reason, PathReason::Refit { .. });
        let started = tracker.rebuild_started();
        if let (true, Some(before)) = (refit, last) {
            if started == Some(before) {
                kept += 1;
            } else {
                let due = before + 1;
                assert!(
                    r.frame >= due + starved,
                    "frame {}: rebuild of {before} replaced",
                    r.frame
                );
                assert_eq!(
                    started,
                    Some(r.frame),
                    "frame {}: starved, not restarted",
                    r.frame
                );
            }
        }
        last = started.filter(|_| refit);
    }
    assert!(kept >= 1, "no refit followed a refit");
}

#[test]
fn a_cold_frame_starts_a_rebuild_only_when_its_deadline_cut_it_short() {
    // A cold frame's membrane ran on the points a rebuild would get (its
    // own after a restart, the fused model's on a refit): a rebuild started
    // there would repeat it. It starts at the next warm frame instead,
    // unless the cold frame's deadline stopped its membrane early; then the
    // rebuild, which has no deadline, finishes what the frame could not.
    let topic = "/synth/capsule/points";
    let (cfg, membranes, clouds) = frames_of("turn_capsule", topic);
    let run = |deadlines: Deadlines| {
        let mut tracker = Tracker::new(StreamKey::topic(topic));
        let first = tracker
            .process_by(&clouds[0], &membranes, &cfg.pipeline, deadlines)
            .unwrap();
        let after_cold = tracker.rebuild_started();
        let none = Deadlines::default();
        let second = tracker
            .process_by(&clouds[1], &membranes, &cfg.pipeline, none)
            .unwrap();
        (first, after_cold, second.path, tracker.rebuild_started())
    };
    // No deadline: the cold frame runs to its end and starts no rebuild;
    // the warm frame after it starts one.
    let (first, after_cold, path, after_warm) = run(Deadlines::default());
    assert_eq!(first.path, StartPath::Cold);
    assert_ne!(first.reconstruction.report.stop, StopReason::Deadline);
    assert_eq!(
        after_cold, None,
        "a rebuild started after a full cold frame"
    );
    assert_eq!(path, StartPath::Warm);
    assert_eq!(after_warm, Some(1));
    // A cold deadline already passed: the membrane stops at it, and the
    // cold frame starts the rebuild.
    let cut = Deadlines::after(Instant::now(), 60_000.0, 1e-6);
    let (first, after_cold, _, _) = run(cut);
    assert_eq!(first.path, StartPath::Cold);
    assert_eq!(first.reconstruction.report.stop, StopReason::Deadline);
    assert_eq!(after_cold, Some(0), "no rebuild after a cut cold frame");
}

#[test]
fn a_shape_prior_that_switches_hastens_a_rebuild_on_that_frame() {
    // A shape prior that takes or drops a frame's points (the revolution's
    // or the sphere's completion) leaves the warm surface evolved under the
    // other prior: a bowl that first shows the camera its outside is a ball
    // until its rim turns into view. Such a frame replaces the rebuild in
    // flight by one on its own model, and the next frame adopts it (a
    // turning bowl's last-third F 0.470 -> 0.552 in
    // benches/robot_view_eval.sh). Here the mug that the swap brings in is
    // completed as a solid of revolution until its handle turns into view.
    let topic = "/synth/rounded_box_then_bottle_then_mug/points";
    let (cfg, membranes, clouds) = frames_of("swap", topic);
    let mut tracker = Tracker::new(StreamKey::topic(topic));
    let (mut was_completed, mut switch) = (false, None);
    for cloud in &clouds {
        let r = tracker
            .process_by(cloud, &membranes, &cfg.pipeline, Deadlines::default())
            .unwrap();
        if switch == Some(r.frame - 1) {
            assert_eq!(
                r.reason,
                PathReason::Rebuilt { age: 1 },
                "frame {}",
                r.frame
            );
            return;
        }
        let completed = r.reconstruction.report.points_completed > 0;
        if r.path == StartPath::Warm && completed != was_completed {
            assert_eq!(
                tracker.rebuild_started(),
                Some(r.frame),
                "frame {}",
                r.frame
            );
            switch = Some(r.frame);
        }
        was_completed = completed;
    }
    panic!("no warm frame switched its completion (last {switch:?})");
}

#[test]
fn a_one_thread_replay_gives_the_same_scores_and_ends() {
    // `sepmem replay` makes its main thread, which runs the frames, the
    // first worker of rayon's global pool. With one thread that worker is
    // the only one: work handed to the global pool from another thread
    // would wait for it forever. The background rebuilds run on pools of
    // their own; the replay must end, and give what the default threads
    // give (the membrane is deterministic at any thread count).
    let name = "turn_capsule";
    let bag = common::data_dir().join(format!("bags/robot_view/{name}.mcap"));
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_sepmem"))
        .args(["replay", bag.to_str().unwrap(), "-q"])
        .env("RAYON_NUM_THREADS", "1")
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let limit = Instant::now() + std::time::Duration::from_secs(300);
    while child.try_wait().unwrap().is_none() {
        if Instant::now() > limit {
            child.kill().unwrap();
            panic!("a one-thread replay of {name} did not end in 300 s");
        }
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success());
    let one = String::from_utf8_lossy(&out.stdout).to_string();
    let scores = |out: &str| {
        let lines: Vec<String> = out
            .lines()
            .filter(|l| l.starts_with("score ") || l.starts_with("view "))
            .map(str::to_string)
            .collect();
        assert_eq!(lines.len(), 2, "{out}");
        lines
    };
    assert!(one.contains("30 frames ok"), "{one}");
    assert_eq!(scores(&one), scores(&replay(name)));
}

/// The per-frame rows of `out`'s table (stream `topic`), without the
/// columns a frame's input changes even when its meshes do not: the
/// input's point count and the latency.
fn frame_scores(out: &str, topic: &str) -> Vec<String> {
    out.lines()
        .filter(|l| l.starts_with(topic))
        .map(|l| {
            let cols: Vec<&str> = l.split_whitespace().collect();
            let kept = cols.iter().enumerate().filter(|(i, _)| ![2, 7].contains(i));
            kept.map(|(_, c)| *c).collect::<Vec<_>>().join(" ")
        })
        .collect()
}

#[test]
fn a_patch_bled_onto_the_background_is_dropped_before_tracking() {
    // The committed turning capsule's first 10 frames, each with a 10 cm
    // patch of 300 points 0.6 m behind the object on the same stream (a
    // mask that bled onto the wall; tests/python/add_detached.py, written
    // with the Python rosbags package). The patch is detached from the
    // capsule's body (`membrane.prepare.detached`): the tracker drops it
    // before tracking and fusing, so every frame scores as the clean
    // sequence's does. Kept, the membrane wrapped capsule and patch in one
    // surface: F 0.069, seen side 0.138 over the last four frames.
    let topic = "/synth/capsule/points";
    let with = replay_with("turn_capsule_detached", &[]);
    assert!(
        with.contains("detached: 3000 points dropped in 10 frames"),
        "{with}"
    );
    let clean = replay_with("turn_capsule", &[]);
    let ten = frame_scores(&with, topic);
    assert_eq!(ten.len(), 10, "{with}");
    assert_eq!(ten, frame_scores(&clean, topic)[..10]);
    let kept = replay_with(
        "turn_capsule_detached",
        &["-q", "--set", "membrane.prepare.detached=null"],
    );
    let f = |out: &str| figure(part(out, "view ", "last third"), "last third (4): F ");
    assert!(f(&kept) < 0.5 * f(&with), "{kept}");
}

#[test]
fn a_real_sensors_outliers_do_not_pile_up_in_the_model() {
    // The committed turning capsule with the Kinect model's 1 % outliers and
    // flying pixels on 30 % of its depth edges. Both fall into new voxels
    // every frame; counted in the fused points, they piled up around the
    // capsule. An earlier frame's voxel counts only once hit twice, or
    // while it touches one that was (`pipeline.model.confirm`): last-third F
    // 0.661, against 0.372 counting every voxel (without the faults: 0.994).
    // Measured, as here, without the flying-pixel filter
    // (`pipeline.flying` null), which drops most flying pixels before they
    // reach the model (tests/flying_pixels.rs): with it, 0.985 against
    // 0.869.
    let name = "turn_capsule_faults";
    let no_filter = ["-q", "--set", "pipeline.flying=null"];
    let with = replay_with(name, &no_filter);
    assert_meshed_within_the_cap(name, &with);
    let every = replay_with(
        name,
        &[&no_filter[..], &["--set", "pipeline.model.confirm=null"]].concat(),
    );
    let (f, f_every) = (closure(&with).0, closure(&every).0);
    assert!(f >= 0.6 && f >= f_every + 0.2, "F {f} against {f_every}");
}
