//! `sepmem synth`: write a synthetic depth-camera sequence of moving objects
//! (pixel rays of a pinhole camera cast against the posed meshes) as a
//! rosbag2 MCAP bag with a ground-truth side channel. The argument parsing
//! lives here; scene building and writing are [`sepmem::synth::sequence`].

use anyhow::{Context, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use sepmem::synth::sequence::{
    parse_noise, write_sequence, Layout, SceneMotion, SequenceSpec, GROUND_TRUTH_TOPIC,
};
use sepmem::synth::{Camera, FlyingPixels};
use std::io::IsTerminal;
use std::path::PathBuf;

/// Arguments of `sepmem synth`.
#[derive(Args, Debug)]
pub struct SynthArgs {
    /// Output bag: a `.mcap` file, or a directory (gets metadata.yaml).
    #[arg(short, long)]
    out: PathBuf,
    /// Objects, comma-separated: procedural shapes (sphere, ellipsoid,
    /// rounded_box, bottle, bowl, torus, mug, capsule, bent_tube) or mesh
    /// file paths (PLY/OBJ).
    #[arg(long, value_delimiter = ',', default_value = "ellipsoid")]
    shapes: Vec<String>,
    /// Number of frames.
    #[arg(long, default_value_t = 30)]
    frames: usize,
    /// Legacy point budget: approximate visible points per object and frame,
    /// reached by choosing the focal length (Kinect field of view) instead of
    /// the fixed intrinsics of --width/--height/--focal.
    #[arg(long, conflicts_with_all = ["width", "height", "focal"])]
    points: Option<usize>,
    /// Image width of the depth camera (pixels).
    #[arg(long, default_value_t = 640)]
    width: usize,
    /// Image height of the depth camera (pixels).
    #[arg(long, default_value_t = 480)]
    height: usize,
    /// Focal length of the depth camera (pixels; principal point at the image centre).
    #[arg(long, default_value_t = 525.0)]
    focal: f64,
    /// Motion: `drift` (drift, wobble and spin), `turn` (each object turns in
    /// place about the vertical by --degrees), `orbit` (the camera orbits the
    /// still objects by --degrees), `pick` (each object is picked up, carried
    /// and set down), `swap` (the shapes follow one another on one stream,
    /// turning by --degrees).
    #[arg(long, default_value = "drift")]
    motion: String,
    /// Total angle of `turn`, `orbit` and `swap` over the sequence (0–360°).
    #[arg(long, default_value_t = 180.0)]
    degrees: f64,
    /// Flying pixels: the chance that a pixel on a depth edge returns a mixed
    /// depth between its surface and the one behind (default: none).
    #[arg(long)]
    flying_pixels: Option<f64>,
    /// Frame rate (Hz) of the stamps.
    #[arg(long, default_value_t = 10.0)]
    rate: f64,
    /// Depth noise: `kinect` (σ = 1.2 mm + 1.9e-3·(z − 0.4)², 1 % outliers), `none`, or σ in metres.
    #[arg(long, default_value = "kinect")]
    noise: String,
    /// Outlier fraction (of the visible points), overriding the noise model's.
    #[arg(long)]
    outliers: Option<f64>,
    /// Add rgb colour.
    #[arg(long)]
    colour: bool,
    /// All objects in one cloud on `--topic` with a `label` field (default:
    /// one topic per object, /synth/<name>/points).
    #[arg(long)]
    labels: bool,
    /// Topic of the labelled cloud (with --labels).
    #[arg(long, default_value = "/synth/points")]
    topic: String,
    /// Seed of the noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Longest edge of every object (m).
    #[arg(long, default_value_t = 0.2)]
    size: f64,
    /// Distance of the objects from the camera (m).
    #[arg(long, default_value_t = 1.0)]
    distance: f64,
    /// Tessellation resolution of procedural shapes (the GT mesh is sent once per stream).
    #[arg(long, default_value_t = 48)]
    mesh_res: usize,
    /// Print only the summary line.
    #[arg(short, long)]
    quiet: bool,
}

/// Run `sepmem synth`.
pub fn run(a: &SynthArgs) -> Result<()> {
    let mut noise = parse_noise(&a.noise)?;
    if let Some(f) = a.outliers {
        noise.outlier_fraction = f;
    }
    noise.flying = a.flying_pixels.map(FlyingPixels::with_probability);
    let spec = SequenceSpec {
        shapes: a.shapes.clone(),
        frames: a.frames,
        points_per_object: a
            .points
            .unwrap_or(SequenceSpec::default().points_per_object),
        intrinsics: match a.points {
            Some(_) => None,
            None => Some(Camera::with_resolution(a.width, a.height, a.focal)),
        },
        motion: SceneMotion::parse(&a.motion, a.degrees)?,
        rate_hz: a.rate,
        noise,
        colour: a.colour,
        layout: if a.labels {
            Layout::Labelled {
                topic: a.topic.clone(),
            }
        } else {
            Layout::SeparateTopics
        },
        seed: a.seed,
        object_size: a.size,
        distance: a.distance,
        mesh_resolution: a.mesh_res,
        ..SequenceSpec::default()
    };
    let bar = if std::io::stderr().is_terminal() && !a.quiet {
        let b = ProgressBar::new(a.frames as u64);
        b.set_style(
            ProgressStyle::with_template("{bar:40} {pos}/{len} frames {elapsed}")
                .unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        b
    } else {
        ProgressBar::hidden()
    };
    let summary = write_sequence(&spec, &a.out, |_| bar.inc(1))
        .with_context(|| format!("writing {}", a.out.display()))?;
    bar.finish_and_clear();
    if !a.quiet {
        for (topic, n) in &summary.counts {
            println!("{topic:<40} {n:>6} messages");
        }
        for (stream, name) in &summary.streams {
            println!("stream {stream:<36} object {name}");
        }
    }
    println!(
        "wrote {} ({} frames, {:.0} points per object and frame, {} outliers, truth on {GROUND_TRUTH_TOPIC})",
        summary.mcap_path.display(),
        a.frames,
        summary.mean_points_per_object,
        summary.outliers
    );
    Ok(())
}
