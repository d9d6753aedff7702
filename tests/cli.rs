//! The `sepmem reconstruct`, `filter`, `eval` and `replay` subcommands, run
//! as the built binary on files written to a temporary folder: the
//! reconstruction is scored against the ground truth by `eval`, the filter's
//! PLY is read back, a replay of a committed bag is repeated.
#![allow(clippy::unwrap_used)]

use sepmem::cloud::{Attribute, PointCloud, Vec3};
use std::path::Path;
use std::process::{Command, Output};

fn sepmem(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_sepmem"))
        .args(args)
        .env("RUST_BACKTRACE", "0")
        .output()
        .expect("running sepmem")
}

fn text(o: &Output) -> String {
    format!(
        "status {:?}\nstdout:\n{}\nstderr:\n{}",
        o.status,
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

fn p(path: &Path) -> &str {
    path.to_str().unwrap()
}

/// 4,000 points on the ellipsoid shape, plus 5 % scattered outliers and a
/// NaN point, all mapped by `x ↦ scale·x + offset` (the ground truth too).
fn ellipsoid_scan(
    dir: &Path,
    scale: f64,
    offset: Vec3,
) -> (std::path::PathBuf, std::path::PathBuf) {
    let mut shape = sepmem::shapes::ellipsoid(64).unwrap();
    for v in &mut shape.mesh.vertices {
        *v = *v * scale + offset;
    }
    let gt = dir.join("gt.ply");
    sepmem::io::save_mesh(&gt, &shape.mesh).unwrap();
    let s = sepmem::metrics::sample_surface(&shape.mesh, 4000, 7).unwrap();
    let mut pts = s.points.clone();
    // Deterministic scattered outliers in the enlarged bounding box.
    let mut x = 0x2545_f491_4f6c_dd1du64;
    let mut rnd = || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        (x >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    for _ in 0..200 {
        pts.push(Vec3::new(1.2 * rnd(), 1.2 * rnd(), 1.2 * rnd()) * scale + offset);
    }
    pts.push(Vec3::new(f64::NAN, 0.0, 0.0));
    let cloud_path = dir.join("scan.ply");
    let cloud = PointCloud::from_points(pts);
    sepmem::io::save_cloud(&cloud_path, &cloud).unwrap();
    (cloud_path, gt)
}

/// Reconstruct `scan`, check the output mesh (watertight, outward) and
/// return its F-score against `gt` (by `sepmem eval`) and the summary line.
fn reconstruct_and_score(dir: &Path, scan: &Path, gt: &Path) -> (f64, String) {
    let mesh = dir.join("mesh.ply");
    let o = sepmem(&["reconstruct", p(scan), "-o", p(&mesh)]);
    assert!(o.status.success(), "{}", text(&o));
    let line = String::from_utf8_lossy(&o.stdout).to_string();
    let loaded = sepmem::io::load_mesh(&mesh).unwrap();
    assert!(loaded.mesh.topology().is_watertight());
    assert!(loaded.mesh.signed_volume() > 0.0);
    let o = sepmem(&[
        "eval",
        "--pred",
        p(&mesh),
        "--gt",
        p(gt),
        "--json",
        "--set",
        "metrics.samples=30000",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let m: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(m["samples"].as_u64(), Some(30000));
    (m["fscore"].as_f64().unwrap(), line)
}

#[test]
fn any_unit_and_position_gives_the_same_reconstruction() {
    // The same object in metres at the origin, in millimetres far away, and
    // 100 times smaller: lengths in the config are relative to the object.
    let mut scores = Vec::new();
    for (scale, offset) in [
        (1.0, Vec3::zeros()),
        (1000.0, Vec3::new(2.5e4, -1.0e4, 3.0e3)),
        (0.01, Vec3::new(0.3, 0.2, 0.1)),
    ] {
        let dir = tempfile::tempdir().unwrap();
        let (scan, gt) = ellipsoid_scan(dir.path(), scale, offset);
        scores.push(reconstruct_and_score(dir.path(), &scan, &gt).0);
    }
    assert!(scores.iter().all(|&f| f >= 0.95), "F-scores {scores:?}");
    let spread =
        scores.iter().cloned().fold(0.0, f64::max) - scores.iter().cloned().fold(1.0, f64::min);
    assert!(spread < 0.02, "F-scores {scores:?} depend on the unit");
}

#[test]
fn reconstruct_then_eval_scores_the_mesh_against_ground_truth() {
    let dir = tempfile::tempdir().unwrap();
    let (scan, gt) = ellipsoid_scan(dir.path(), 1.0, Vec3::zeros());
    let (f, line) = reconstruct_and_score(dir.path(), &scan, &gt);
    assert_eq!(line.lines().count(), 1, "one summary line: {line}");
    for key in [
        "points in",
        "used",
        "dropped",
        "grid",
        "iterations",
        "eta_g",
        "stop",
        "ms",
    ] {
        assert!(line.contains(key), "summary lacks `{key}`: {line}");
    }
    assert!(f >= 0.95, "F-score {f} of the reconstruction");
    // The ground truth against itself scores F = 1 in the table output.
    let o = sepmem(&[
        "eval",
        "--pred",
        p(&gt),
        "--gt",
        p(&gt),
        "--set",
        "metrics.samples=20000",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let out = String::from_utf8_lossy(&o.stdout).to_string();
    let self_f: f64 = out
        .lines()
        .find_map(|l| l.strip_prefix("fscore"))
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or_else(|| panic!("no fscore line: {out}"));
    // Sampling noise only (20k samples per mesh at τ = 0.01).
    assert!(self_f > 0.97, "{out}");
}

#[test]
fn filter_writes_a_coloured_separability_map() {
    let dir = tempfile::tempdir().unwrap();
    // Two stacked sheets of different density with a luma edge: the map must
    // peak near the density step and stay low on the flat regions.
    let mut pts = Vec::new();
    let mut luma = Vec::new();
    for i in 0..60 {
        for j in 0..60 {
            let (x, y) = (f64::from(i) * 0.01, f64::from(j) * 0.01);
            if x < 0.3 || (i + j) % 2 == 0 {
                pts.push(Vec3::new(x, y, 0.0));
                luma.push(if y < 0.3 { 0.1 } else { 0.9 });
            }
        }
    }
    let mut cloud = PointCloud::from_points(pts);
    cloud.attributes.push(Attribute {
        name: "intensity".into(),
        values: luma,
    });
    let input = dir.path().join("sheet.ply");
    sepmem::io::save_cloud(&input, &cloud).unwrap();
    for direction in ["x", "all", "normal"] {
        let out = dir.path().join(format!("map_{direction}.ply"));
        let o = sepmem(&[
            "filter",
            p(&input),
            "-o",
            p(&out),
            "--direction",
            direction,
            "--size",
            "6d,0.02,6d",
            "--set",
            "separability.weights.intensity=1",
        ]);
        assert!(o.status.success(), "{}", text(&o));
        let map = sepmem::io::load_cloud(&out).unwrap().cloud;
        assert_eq!(map.len(), cloud.len());
        let sep = map
            .attribute("separability")
            .expect("separability property");
        assert!(map.attribute("r").is_some(), "colour properties");
        assert!(sep.iter().all(|v| (0.0..=1.0).contains(v)));
        if direction == "normal" {
            continue; // a flat sheet: its normal split sees no boundary to peak at
        }
        let near = |f: &dyn Fn(&Vec3) -> bool| {
            map.points
                .iter()
                .zip(sep)
                .filter(|(q, _)| f(q) && q.y > 0.05 && q.y < 0.55 && q.x > 0.05 && q.x < 0.55)
                .map(|(_, &v)| v)
                .fold(0.0f32, f32::max)
        };
        let step = near(&|q| (q.x - 0.3).abs() < 0.02);
        let flat = near(&|q| (q.x - 0.15).abs() < 0.05 && (q.y - 0.3).abs() > 0.05);
        assert!(
            step > 2.0 * flat + 0.02,
            "{direction}: step {step} flat {flat}"
        );
    }
}

#[test]
fn bad_input_fails_with_a_message_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("broken.ply");
    std::fs::write(
        &bad,
        b"ply\nformat ascii 1.0\nelement vertex 3\nend_header\n1 2\n",
    )
    .unwrap();
    let out = dir.path().join("o.ply");
    for args in [
        vec!["reconstruct", p(&bad), "-o", p(&out)],
        vec!["filter", p(&bad), "-o", p(&out)],
        vec!["eval", "--pred", p(&bad), "--gt", p(&bad)],
    ] {
        let o = sepmem(&args);
        assert!(!o.status.success(), "{}", text(&o));
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains("broken.ply"), "{}", text(&o));
        assert!(!err.contains("panicked"), "{}", text(&o));
    }
    let o = sepmem(&["filter", p(&bad), "-o", p(&out), "--size=-3"]);
    assert!(
        !o.status.success() && String::from_utf8_lossy(&o.stderr).contains("--size"),
        "{}",
        text(&o)
    );
}

/// Per-frame rows of a `sepmem replay` table without the wall-clock column
/// (`ms`, the 8th): stream, frame, points, path, reason, iterations, η_g and
/// the scores.
fn replay_rows(o: &Output) -> Vec<Vec<String>> {
    String::from_utf8_lossy(&o.stdout)
        .lines()
        .filter(|l| l.starts_with('/'))
        .map(|l| {
            l.split_whitespace()
                .enumerate()
                .filter(|(k, _)| *k != 7)
                .map(|(_, c)| c.to_string())
                .collect()
        })
        .collect()
}

#[test]
fn replay_is_deterministic_and_applies_the_deadlines_only_with_realtime() {
    let bag = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/bags/synth_ellipsoid.mcap");
    // A per-frame deadline that has passed before any iteration could run.
    let args = |realtime: bool| {
        let mut a = vec![
            "replay",
            p(&bag),
            "--set",
            "pipeline.deadline_ms=0.000001",
            "--set",
            "pipeline.cold_deadline_ms=0",
            "--set",
            "pipeline.warm_min_iterations=0",
            "--set",
            "pipeline.warm_eta_ratio=0",
        ];
        if realtime {
            a.push("--realtime");
        }
        a
    };
    let first = sepmem(&args(false));
    assert!(first.status.success(), "{}", text(&first));
    let stdout = String::from_utf8_lossy(&first.stdout).to_string();
    assert!(
        stdout.contains("no deadline (deterministic"),
        "{}",
        text(&first)
    );
    let rows = replay_rows(&first);
    assert_eq!(rows.len(), 12, "{}", text(&first));
    // Without --realtime the deadline is not applied: every frame iterates
    // (warm frames their cap of 4, the cold first frame more).
    for r in &rows {
        let it: usize = r[5].parse().unwrap();
        assert!(it >= 4, "{r:?}");
    }
    // Deterministic: a second run gives the same table (timings aside).
    let second = sepmem(&args(false));
    assert_eq!(replay_rows(&second), rows);
    // --realtime applies it: no frame gets an iteration.
    let late = sepmem(&args(true));
    assert!(late.status.success(), "{}", text(&late));
    assert!(String::from_utf8_lossy(&late.stdout).contains("deadlines 0.000001 ms warm"));
    let late_rows = replay_rows(&late);
    assert_eq!(late_rows.len(), 12);
    for r in &late_rows {
        assert_eq!(r[5], "0", "{r:?}");
    }
}

/// Issue 22 (10): printing into a closed pipe (`sepmem config | head`) ends
/// the process by SIGPIPE, as `cat` does, instead of a panic (exit 101).
#[cfg(unix)]
#[test]
fn printing_into_a_closed_pipe_ends_quietly() {
    use std::os::unix::process::ExitStatusExt;
    for args in [vec!["config"], vec!["config", "--annotated"]] {
        // A socket pair whose reading end is closed before the child starts:
        // its first write finds the peer gone, whatever the scheduling.
        let (ours, theirs) = std::os::unix::net::UnixStream::pair().unwrap();
        drop(ours);
        let o = Command::new(env!("CARGO_BIN_EXE_sepmem"))
            .args(&args)
            .stdout(std::process::Stdio::from(std::os::fd::OwnedFd::from(
                theirs,
            )))
            .stderr(std::process::Stdio::piped())
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!err.contains("panicked"), "{args:?}: {err}");
        assert_eq!(
            o.status.signal(),
            Some(libc::SIGPIPE),
            "{args:?}: {:?} {err}",
            o.status
        );
    }
}

/// Issue 22 (10): an unwritable output path fails before the reconstruction.
#[test]
fn an_unwritable_output_is_reported_before_the_work() {
    let dir = tempfile::tempdir().unwrap();
    let (scan, _) = ellipsoid_scan(dir.path(), 1.0, Vec3::zeros());
    let out = dir.path().join("missing/dir/mesh.ply");
    for args in [
        vec!["reconstruct", p(&scan), "-o", p(&out)],
        vec!["filter", p(&scan), "-o", p(&out)],
    ] {
        let o = sepmem(&args);
        assert!(!o.status.success(), "{}", text(&o));
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            err.contains("mesh.ply") && err.contains("before"),
            "{}",
            text(&o)
        );
        assert!(o.stdout.is_empty(), "nothing was computed: {}", text(&o));
    }
}

/// Issue 22 (9): an absurd sample count is a configuration error naming the
/// key and its maximum (it aborted on the allocation before).
#[test]
fn too_many_metric_samples_is_a_configuration_error() {
    let o = sepmem(&[
        "eval",
        "--pred",
        "p.ply",
        "--gt",
        "g.ply",
        "--set",
        "metrics.samples=1000000000",
    ]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("metrics.samples") && err.contains("10000000"),
        "{}",
        text(&o)
    );
}

/// Issue 19 (3): the flat membrane keys moved into sections; an old key,
/// through `--set` or a user file, is an error that names its new key.
#[test]
fn an_old_membrane_key_names_its_new_key() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("old.json5");
    std::fs::write(&file, "{ membrane: { grid_max: [32, 20] } }").unwrap();
    let cases = [
        (
            vec!["config", "--set", "membrane.alpha=2"],
            "`membrane.alpha` in --set was renamed to `membrane.fit.alpha`",
        ),
        (
            vec!["config", "--set", "membrane.outlier_factor=0"],
            "renamed to `membrane.prepare.outlier_factor`; null turns the filter off",
        ),
        (
            vec!["config", "--config", p(&file)],
            "was renamed to `membrane.schedule.growth.grid_max`",
        ),
    ];
    for (args, want) in cases {
        let o = sepmem(&args);
        assert_eq!(o.status.code(), Some(1), "{}", text(&o));
        assert!(
            String::from_utf8_lossy(&o.stderr).contains(want),
            "{want}: {}",
            text(&o)
        );
    }
    let o = sepmem(&["config", "--set", "membrane.fit.alpha=2.5"]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("\"alpha\": 2.5"),
        "{}",
        text(&o)
    );
}

/// Issue 22 (10): when no frame succeeds the replay summary says so (it
/// printed "p50 NaN"); a truncated bag says it is truncated and where.
#[test]
fn replay_says_when_no_frame_succeeded_and_when_a_bag_is_cut() {
    let bag = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/bags/synth_ellipsoid.mcap");
    let o = sepmem(&["replay", p(&bag), "--set", "pipeline.min_points=100000000"]);
    assert!(o.status.success(), "{}", text(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        out.contains("0 frames ok") && out.contains("no frame succeeded"),
        "{}",
        text(&o)
    );
    assert!(!out.contains("NaN"), "{}", text(&o));
    let dir = tempfile::tempdir().unwrap();
    let cut = dir.path().join("cut.mcap");
    let full = std::fs::read(&bag).unwrap();
    std::fs::write(&cut, &full[..full.len() * 2 / 3]).unwrap();
    let o = sepmem(&["replay", p(&cut)]);
    assert!(!o.status.success(), "{}", text(&o));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("truncated") && err.contains("cut.mcap"),
        "{}",
        text(&o)
    );
    assert!(
        err.contains(&format!("byte {}", full.len() * 2 / 3)),
        "{}",
        text(&o)
    );
}

/// `replay` with `pipeline.model` writes every frame's fused models to its
/// output bag on `{topic}/model` (sensor_msgs/PointCloud2), and two runs of
/// the same bag write the same bytes (the fused cloud's order does not
/// depend on the process).
#[test]
fn replay_writes_the_fused_model_and_repeats_it_byte_for_byte() {
    use sepmem::bag::Bag;
    let bag = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/bags/synth_ellipsoid.mcap");
    let dir = tempfile::tempdir().unwrap();
    let models = |name: &str| {
        let out = dir.path().join(name);
        let o = sepmem(&[
            "replay",
            p(&bag),
            "--no-score",
            "-q",
            "--set",
            "pipeline.model={}",
            "-o",
            p(&out),
        ]);
        assert!(o.status.success(), "{}", text(&o));
        let written = Bag::open(&out).unwrap();
        let topics: Vec<String> = written
            .topics
            .iter()
            .filter(|t| t.name.ends_with("/model"))
            .inspect(|t| assert_eq!(t.type_name, "sensor_msgs/msg/PointCloud2"))
            .map(|t| t.name.clone())
            .collect();
        assert_eq!(topics.len(), 1, "{:?}", written.topics);
        let refs: Vec<&str> = topics.iter().map(String::as_str).collect();
        written
            .read(&refs)
            .unwrap()
            .into_iter()
            .map(|m| m.data)
            .collect::<Vec<_>>()
    };
    let first = models("a.mcap");
    assert_eq!(first.len(), 12, "one model cloud per frame");
    assert!(first.iter().all(|d| d.len() > 1000));
    assert!(
        first == models("b.mcap"),
        "a second replay wrote other model clouds"
    );
}
