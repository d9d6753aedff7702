//! A short soak (issue 22): `sepmem bench-node --hostile` for 24 s with two
//! healthy streams (10 Hz × 3,000 points) next to the five hostile ones
//! (poisoned clouds, a 400-label bomb, label churn, oversized payloads,
//! malformed CDR). The command itself fails unless every hostile stream
//! was counted in `/diagnostics` under its own reason (read back by an
//! observer from the DiagnosticArray, not from the node's own summary) and
//! the node stopped without a panic (a panic in compute aborts the
//! process). Here the healthy streams must also keep meshing, and
//! `/diagnostics` must stay small although a new label arrives every frame.
//!
//! And a looped replay through the live node (`bench-node --bag`): the
//! committed turning-mug sequence, looped, with the fused model on (the
//! default): the node meshes it, takes none of its own `/model` clouds for
//! an input, and reports in `/diagnostics` a fused model that never
//! exceeds the cap the configuration states.
#![allow(clippy::unwrap_used)]

use std::process::Command;

#[test]
fn healthy_streams_keep_meshing_and_every_hostile_input_is_counted() {
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("soak.json");
    let out = Command::new(env!("CARGO_BIN_EXE_sepmem"))
        .args(["bench-node", "--hostile", "--streams", "2", "--rate", "10"])
        .args(["--points", "3000", "--duration", "24", "--warmup", "4"])
        .args(["--rss-every", "4", "--json"])
        .arg(&json)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    eprintln!("{stdout}{}", String::from_utf8_lossy(&out.stderr));
    assert!(
        out.status.success(),
        "bench-node --hostile failed: {:?}",
        out.status
    );
    let j: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    for s in j["healthy"].as_array().unwrap() {
        let meshed = s["meshed"].as_f64().unwrap();
        assert!(s["published"].as_u64().unwrap() >= 150, "{s}");
        // Measured while writing this test, on the 2-core development
        // machine at a load average of 17 (other builds), with the decoder
        // still stalling a thread on the poisoned cloud: 0.50. A starved
        // stream (the defects of issue 22) meshed under 0.05.
        assert!(meshed >= 0.25, "healthy stream meshed only {meshed}: {s}");
    }
    let kinds = j["hostile"]["kinds"].as_object().unwrap();
    assert_eq!(kinds.len(), 5);
    for (name, k) in kinds {
        let counted = k["count"].as_u64().unwrap() > 0 || k["stalled"].as_bool().unwrap();
        assert!(counted, "{name} not counted: {k}");
        assert!(k["sent"].as_u64().unwrap() > 0, "{name} never sent");
    }
    // A new label every frame on the same object: each new label took over
    // the tracker of the one before (a warm start, not a cold one), the old
    // label's status was freed, and the statuses stayed bounded
    // (pipeline.objects.max_tracked 64 per stream).
    assert!(
        kinds["churn"]["count"].as_u64().unwrap() >= 10,
        "{}",
        kinds["churn"]
    );
    // The healthy streams are whole ellipsoid surfaces, not one depth
    // image seen from their frame's origin: counted frame by frame.
    let not_an_image = j["reasons"]["not_an_image"].as_u64().unwrap();
    assert!(
        not_an_image >= 100,
        "not_an_image {not_an_image}: {}",
        j["reasons"]
    );
    let statuses = j["hostile"]["diagnostics_max_statuses"].as_u64().unwrap();
    assert!(statuses <= 1 + 7 * 64, "{statuses} statuses");
    let bytes = j["hostile"]["diagnostics_max_bytes"].as_u64().unwrap();
    assert!(bytes < 200_000, "/diagnostics grew to {bytes} bytes");
}

#[test]
fn a_looped_replay_keeps_the_fused_model_under_its_cap() {
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("loop.json");
    let bag = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/bags/synth_turn_mug.mcap"
    );
    let out = Command::new(env!("CARGO_BIN_EXE_sepmem"))
        .args(["bench-node", "--bag", bag, "--streams", "1", "--rate", "10"])
        .args([
            "--duration",
            "12",
            "--warmup",
            "2",
            "--rss-every",
            "2",
            "--json",
        ])
        .arg(&json)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    eprintln!("{stdout}{}", String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "bench-node --bag: {:?}", out.status);
    let j: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    // 12 s at 10 Hz loops the 30-frame bag four times.
    let meshed = j["healthy"][0]["meshed"].as_f64().unwrap();
    assert!(meshed >= 0.5, "meshed {meshed}: {j}");
    assert_eq!(j["input_streams"], 1, "{j}");
    assert!(j["own_outputs"].as_u64().unwrap() > 0, "{j}");
    // The synth clouds are depth images in the camera's frame.
    assert_eq!(j["reasons"]["not_an_image"], 0, "{}", j["reasons"]);
    // The cap stated in launch/sepmem.json5: max_voxels * 66 + (max_views
    // + 1) * 8 * view_side^2 at the defaults (60000, 12, 160).
    let cap = 60_000 * 66 + 13 * 8 * 160 * 160;
    let model = j["model_bytes_max"].as_u64().unwrap();
    assert!(
        model > 0 && model <= cap,
        "fused model {model} bytes, cap {cap}"
    );
}
