//! The pictures, decoded and measured: `replay --snapshots/--plot`,
//! `reconstruct --snapshot` and `bench`'s plots run as a user would run
//! them, and every PNG is decoded with the `png` crate. A snapshot must show
//! the mesh in each of its three views (a measured share of mesh-blue
//! pixels in each panel, not a blank or one-view image) and the input
//! points; a plot must hold its series' colours.
#![allow(clippy::unwrap_used)]

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn sepmem(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_sepmem"))
        .args(args)
        .output()
        .unwrap()
}

fn ok(o: &Output) -> String {
    let text = format!(
        "{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(o.status.success(), "sepmem failed:\n{text}");
    text
}

/// A decoded RGB8 picture.
struct Picture {
    width: usize,
    height: usize,
    rgb: Vec<u8>,
}

fn decode(path: &Path) -> Picture {
    let file = std::fs::File::open(path).unwrap();
    let decoder = png::Decoder::new(std::io::BufReader::new(file));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgb, "{}", path.display());
    assert_eq!(info.bit_depth, png::BitDepth::Eight, "{}", path.display());
    buf.truncate(info.buffer_size());
    Picture {
        width: info.width as usize,
        height: info.height as usize,
        rgb: buf,
    }
}

impl Picture {
    /// Share of the pixels in `x0..x1 × y0..y1` that `class` accepts.
    fn share(
        &self,
        (x0, x1): (usize, usize),
        (y0, y1): (usize, usize),
        class: fn([u8; 3]) -> bool,
    ) -> f64 {
        let mut hits = 0usize;
        for y in y0..y1 {
            for x in x0..x1 {
                let i = 3 * (y * self.width + x);
                if class([self.rgb[i], self.rgb[i + 1], self.rgb[i + 2]]) {
                    hits += 1;
                }
            }
        }
        hits as f64 / ((x1 - x0) * (y1 - y0)) as f64
    }

    fn all(&self, class: fn([u8; 3]) -> bool) -> f64 {
        self.share((0, self.width), (0, self.height), class)
    }
}

/// Any shade of the mesh's blue (52, 110, 235), also under the translucent
/// ground truth; not white, grey, the orange points or the green truth.
fn mesh_blue([r, g, b]: [u8; 3]) -> bool {
    b > r.saturating_add(40) && b > g.saturating_add(20)
}

/// The points' orange (245, 130, 20).
fn point_orange([r, g, b]: [u8; 3]) -> bool {
    r > 200 && (90..170).contains(&g) && b < 80
}

/// A snapshot: three 400-pixel panels (title 28 px above each view, a
/// 30 px caption below); returns the mesh share of each view.
fn snapshot_views(path: &Path) -> [f64; 3] {
    let pic = decode(path);
    assert_eq!((pic.width, pic.height), (1200, 458), "{}", path.display());
    let view = |i: usize| pic.share((400 * i, 400 * (i + 1)), (28, 428), mesh_blue);
    assert!(
        pic.all(point_orange) > 1e-4,
        "{}: no input points drawn",
        path.display()
    );
    [view(0), view(1), view(2)]
}

fn pngs(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "png"))
        .collect();
    v.sort();
    v
}

#[test]
fn replay_snapshots_show_the_mesh_from_three_sides_and_the_plot_its_series() {
    let dir = tempfile::tempdir().unwrap();
    let snaps = dir.path().join("snaps");
    let plot = dir.path().join("replay.png");
    let bag = common::data_dir().join("bags/synth_ellipsoid.mcap");
    let text = ok(&sepmem(&[
        "replay",
        bag.to_str().unwrap(),
        "-q",
        "--snapshots",
        snaps.to_str().unwrap(),
        "--plot",
        plot.to_str().unwrap(),
    ]));
    let files = pngs(&snaps);
    // 12 frames of one stream, one snapshot each.
    assert_eq!(files.len(), 12, "{files:?}\n{text}");
    assert!(text.contains("wrote 12 snapshots"), "{text}");
    for f in &files {
        let views = snapshot_views(f);
        // The ellipsoid fills a good part of each view (about a quarter of
        // the panel): a blank or clipped view would be near 0.
        for (v, share) in views.iter().enumerate() {
            assert!(
                *share > 0.05,
                "{} view {v}: mesh covers only {share:.4} of the panel",
                f.display()
            );
        }
    }
    // The plot: F / R_vis panel and latency panel, one stream (F blue,
    // R_vis orange, latency blue).
    let pic = decode(&plot);
    assert_eq!((pic.width, pic.height), (900, 640));
    let top = pic.share((0, 900), (0, 320), mesh_blue);
    let top_orange = pic.share((0, 900), (0, 320), point_orange);
    let bottom = pic.share((0, 900), (320, 640), mesh_blue);
    assert!(
        top > 1e-3 && top_orange > 1e-3 && bottom > 1e-3,
        "plot series: F {top}, R_vis {top_orange}, latency {bottom}"
    );
}

#[test]
fn reconstruct_snapshot_shows_the_mesh_in_every_view() {
    let dir = tempfile::tempdir().unwrap();
    let cloud = common::data_dir().join("spot_low_resolution.obj");
    let mesh = dir.path().join("spot.ply");
    let png = dir.path().join("spot.png");
    ok(&sepmem(&[
        "reconstruct",
        cloud.to_str().unwrap(),
        "-o",
        mesh.to_str().unwrap(),
        "--snapshot",
        png.to_str().unwrap(),
    ]));
    for (v, share) in snapshot_views(&png).iter().enumerate() {
        assert!(*share > 0.03, "view {v}: mesh covers only {share:.4}");
    }
}

/// The series colours of the bar chart, in order: sepmem, then the peers.
const SERIES: [fn([u8; 3]) -> bool; 4] = [
    mesh_blue,
    point_orange,
    |[r, g, b]| g > 140 && r < 80 && b < 100, // green (30, 170, 60)
    |[r, g, b]| r > 170 && g < 70 && b < 70,  // red (200, 40, 40)
];

#[test]
fn bench_plots_the_sweep_and_f_per_condition_beside_the_peers() {
    let out = tempfile::tempdir().unwrap();
    let peers = common::data_dir().join("peers_paper_table1.json");
    let text = ok(&Command::new(env!("CARGO_BIN_EXE_sepmem"))
        .args([
            "bench",
            "--quick",
            "--only",
            "table1,sweep,sphere",
            "--peers",
        ])
        .arg(&peers)
        .arg("--out")
        .arg(out.path())
        .env("SEPMEM_DATASETS", out.path().join("no-datasets"))
        .output()
        .unwrap());
    assert!(
        text.contains("sweep.png") && text.contains("conditions.png"),
        "{text}"
    );
    let sweep = decode(&out.path().join("sweep.png"));
    assert_eq!((sweep.width, sweep.height), (900, 640));
    assert!(sweep.all(mesh_blue) > 1e-3, "sweep: no line drawn");
    let bars = decode(&out.path().join("conditions.png"));
    for (i, class) in SERIES.iter().enumerate() {
        let s = bars.all(*class);
        assert!(s > 2e-3, "conditions.png: series {i} covers only {s:.4}");
    }
    // Every bar is drawn whole, its height in proportion to its figure: the
    // peers' from the peers file, sepmem's from bench.json. (A legend drawn
    // over the chart hid the tops of two bars and added its swatches as
    // bars of their own.)
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.path().join("bench.json")).unwrap())
            .unwrap();
    const CONDITIONS: [&str; 4] = ["original", "noise", "region_outliers", "surface_outliers"];
    let summaries = report["table1"]["genus0"].as_array().unwrap();
    // sepmem also has a bar for the non-uniform condition (no peer figure).
    let ours: Vec<f64> = CONDITIONS
        .iter()
        .chain(&["non_uniform"])
        .map(|c| {
            let s = summaries.iter().find(|s| s["group"] == *c).unwrap();
            s["fscore"].as_f64().unwrap()
        })
        .collect();
    let peers: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&peers).unwrap()).unwrap();
    let figures = |method: &str| -> Vec<f64> {
        CONDITIONS
            .iter()
            .map(|c| peers[method][c].as_f64().unwrap())
            .collect()
    };
    let expected = [
        ours,
        figures("Alpha-shape (paper)"),
        figures("PSR (paper)"),
        figures("SAP (paper)"),
    ];
    // Pixels per unit of F, from the tallest bar of all.
    let measured: Vec<Vec<usize>> = SERIES.iter().map(|c| bar_heights(&bars, *c)).collect();
    let (h_max, v_max) = measured
        .iter()
        .flatten()
        .zip(expected.iter().flat_map(|v| v.iter().filter(|f| **f > 0.0)))
        .fold(
            (0usize, 0.0f64),
            |m, (h, v)| if *h > m.0 { (*h, *v) } else { m },
        );
    for (i, (heights, values)) in measured.iter().zip(&expected).enumerate() {
        let drawn: Vec<f64> = values.iter().copied().filter(|v| *v > 0.0).collect();
        assert_eq!(
            heights.len(),
            drawn.len(),
            "series {i}: bars {heights:?} for {values:?}"
        );
        for (h, v) in heights.iter().zip(&drawn) {
            let want = v * h_max as f64 / v_max;
            assert!(
                (*h as f64 - want).abs() <= 2.0,
                "series {i}: bar of F {v} is {h} px high, expected {want:.1} px"
            );
        }
    }
}

/// The bars of colour `class` in a bar chart (its left 690 pixels; the
/// legend column is the right 210), left to right: the height in pixels of
/// each (the longest vertical run of the colour in the middle column of
/// each run of columns holding the colour).
fn bar_heights(pic: &Picture, class: fn([u8; 3]) -> bool) -> Vec<usize> {
    let chart_w = pic.width - 210;
    let column = |x: usize| -> usize {
        let (mut best, mut run) = (0, 0);
        for y in 0..pic.height {
            let i = 3 * (y * pic.width + x);
            run = if class([pic.rgb[i], pic.rgb[i + 1], pic.rgb[i + 2]]) {
                run + 1
            } else {
                0
            };
            best = best.max(run);
        }
        best
    };
    // Runs of at least 3 columns: a bar, not a glyph of the legend text.
    let mut bars = Vec::new();
    let mut x = 0;
    while x < chart_w {
        if column(x) == 0 {
            x += 1;
            continue;
        }
        let start = x;
        while x < chart_w && column(x) > 0 {
            x += 1;
        }
        if x - start >= 3 {
            bars.push(column((start + x) / 2));
        }
    }
    bars
}

#[test]
fn a_peers_file_with_an_unknown_condition_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let peers = dir.path().join("peers.json");
    std::fs::write(&peers, r#"{"PSR": {"orignal": 0.9}}"#).unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_sepmem"))
        .args(["bench", "--quick", "--only", "sweep", "--peers"])
        .arg(&peers)
        .arg("--out")
        .arg(dir.path())
        .output()
        .unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    let last = err.lines().last().unwrap_or_default();
    assert!(
        last.starts_with("error: ")
            && last.contains("\"orignal\"")
            && last.contains("region_outliers"),
        "{err}"
    );
}

#[test]
fn the_readme_shows_a_snapshot_that_holds_the_mesh() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let readme = std::fs::read_to_string(root.join("README.md")).unwrap();
    // Markdown images: ![alt](path).
    let images: Vec<&str> = readme
        .split("![")
        .skip(1)
        .filter_map(|s| s.split_once("](")?.1.split_once(')').map(|(p, _)| p))
        .collect();
    assert_eq!(images, ["docs/snapshot.png"], "README images");
    for (v, share) in snapshot_views(&root.join(images[0])).iter().enumerate() {
        assert!(
            *share > 0.05,
            "README picture view {v}: mesh covers only {share:.4}"
        );
    }
}
