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

#[test]
fn a_box_turning_edge_on_stays_tracked() {
    let tmp = tempfile::tempdir().unwrap();
    for seed in ["3", "4"] {
        let bag = tmp.path().join(format!("box{seed}.mcap"));
        let bag = bag.to_str().unwrap();
        sepmem(&[
            "synth",
            "--shapes",
            "rounded_box",
            "--motion",
            "turn",
            "--seed",
            seed,
            "-q",
            "-o",
            bag,
        ]);
        let out = sepmem(&["replay", bag, "-q"]);
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
