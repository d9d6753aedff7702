//! `sepmem filter`: the 3D separability filter (paper §IV-A, Fig. 6). Every
//! point gets the separability of the two halves of a cuboid centred on it
//! ([`sepmem::separability::separability_map_of`], on the k-NN index built
//! for the cloud's density); the cloud is written as a PLY coloured by that
//! value, with a float `separability` property.

use anyhow::{bail, Context, Result};
use sepmem::cloud::{Attribute, PointCloud};
use sepmem::config::Config;
use sepmem::density::Density;
use sepmem::separability::{separability_map_of, AttributeSet, FilterDirection, FilterSize};
use std::path::Path;
use std::time::Instant;

/// A length of the `--size` option: relative to the object size (the longest
/// bounding-box edge), in metres (`m` suffix) or in multiples of the point
/// spacing δ (`d` suffix).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Length {
    /// Fraction of the object size.
    Relative(f64),
    /// Absolute length (input units, normally metres).
    Metres(f64),
    /// Multiple of δ.
    Delta(f64),
}

impl Length {
    fn parse(text: &str) -> Result<Self> {
        let t = text.trim();
        let (num, make): (&str, fn(f64) -> Length) = if let Some(n) = t.strip_suffix('m') {
            (n, Length::Metres)
        } else if let Some(n) = t.strip_suffix('d') {
            (n, Length::Delta)
        } else {
            (t, Length::Relative)
        };
        let v: f64 = num
            .parse()
            .with_context(|| format!("--size: `{t}` is not a number (suffix m = metres, d = δ)"))?;
        if !(v.is_finite() && v > 0.0) {
            bail!("--size: `{t}` must be a positive length");
        }
        Ok(make(v))
    }

    fn resolve(self, scale: f64, delta: f64) -> f64 {
        match self {
            Self::Relative(v) => v * scale,
            Self::Metres(v) => v,
            Self::Delta(v) => v * delta,
        }
    }
}

/// Parse `--size W[,H[,D]]` (H defaults to W, D to W).
pub fn parse_size(text: &str) -> Result<[Length; 3]> {
    let parts: Vec<&str> = text.split(',').collect();
    if parts.is_empty() || parts.len() > 3 {
        bail!("--size takes W, W,H or W,H,D; got `{text}`");
    }
    let w = Length::parse(parts[0])?;
    let h = parts
        .get(1)
        .map(|p| Length::parse(p))
        .transpose()?
        .unwrap_or(w);
    let d = parts
        .get(2)
        .map(|p| Length::parse(p))
        .transpose()?
        .unwrap_or(w);
    Ok([w, h, d])
}

/// Parse `--direction x|y|z|all|normal`.
pub fn parse_direction(text: &str, normal_k: usize) -> Result<FilterDirection> {
    Ok(match text.to_ascii_lowercase().as_str() {
        "x" => FilterDirection::X,
        "y" => FilterDirection::Y,
        "z" => FilterDirection::Z,
        "all" => FilterDirection::All,
        "normal" => FilterDirection::Normal { k: normal_k },
        other => bail!("--direction: `{other}` is not one of x, y, z, all, normal"),
    })
}

/// Run the filter on `input` and write the coloured map to `output` (.ply).
pub fn run(
    input: &Path,
    output: &Path,
    direction: &str,
    size: &str,
    config: Option<&Path>,
    set: &[String],
) -> Result<()> {
    let cfg = Config::load(config, set).context("loading configuration")?;
    let direction = parse_direction(direction, cfg.separability.normal_k)?;
    let size = parse_size(size)?;
    sepmem::io::check_output(output, sepmem::io::OutputKind::Cloud)
        .context("checking the output path before filtering")?;
    let start = Instant::now();
    let loaded = sepmem::io::load_cloud(input)
        .with_context(|| format!("reading point cloud {}", input.display()))?;
    let cloud = loaded.cloud;
    // One k-NN index of the cloud serves its density and its normals.
    let (density, knn) = Density::indexed(cloud.points.clone(), cfg.density.k)
        .with_context(|| format!("estimating the density of {}", input.display()))?;
    let delta = density.global(cfg.density.estimator);
    let scale = cloud.aabb().longest_edge();
    let size = FilterSize {
        width: size[0].resolve(scale, delta),
        height: size[1].resolve(scale, delta),
        depth: size[2].resolve(scale, delta),
    };
    let set = AttributeSet::from_cloud(
        &cloud,
        &cfg.separability.weights,
        delta,
        cfg.separability.density_radius,
    )
    .context("building the attribute set (separability.weights)")?;
    for name in set.missing() {
        eprintln!(
            "warning: attribute `{name}` is weighted but {} does not carry it; skipped",
            input.display()
        );
    }
    let attributes = (!set.channels().is_empty()).then_some(&set);
    let map = separability_map_of(&knn, delta, size, direction, attributes)
        .context("computing the separability map")?;
    let mut out = PointCloud::from_points(cloud.points.clone());
    let colours: Vec<[u8; 3]> = map.iter().map(|&v| sepmem::io::colormap(v)).collect();
    for (c, name) in ["r", "g", "b"].iter().enumerate() {
        out.attributes.push(Attribute {
            name: (*name).to_string(),
            values: colours
                .iter()
                .map(|rgb| f32::from(rgb[c]) / 255.0)
                .collect(),
        });
    }
    out.attributes.push(Attribute {
        name: "separability".into(),
        values: map.clone(),
    });
    sepmem::io::save_cloud(output, &out)
        .with_context(|| format!("writing {}", output.display()))?;
    let mut sorted = map;
    sorted.sort_by(f32::total_cmp);
    let q = |f: f64| {
        sorted
            .get(((sorted.len().saturating_sub(1)) as f64 * f) as usize)
            .copied()
            .unwrap_or(0.0)
    };
    println!(
        "{}: {} points (dropped non-finite {}); delta {:.4e}; cuboid {:.4e} x {:.4e} x {:.4e}; direction {:?}; separability median {:.3} p95 {:.3} max {:.3}; {:.1} ms -> {}",
        input.display(),
        cloud.len(),
        loaded.report.dropped_non_finite,
        delta,
        size.width,
        size.height,
        size.depth,
        direction,
        q(0.5),
        q(0.95),
        q(1.0),
        start.elapsed().as_secs_f64() * 1e3,
        output.display()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_and_directions_parse() {
        let s = parse_size("0.05,2m,6d").unwrap();
        assert_eq!(
            s,
            [
                Length::Relative(0.05),
                Length::Metres(2.0),
                Length::Delta(6.0)
            ]
        );
        assert_eq!(s[0].resolve(2.0, 0.1), 0.1);
        assert_eq!(s[2].resolve(2.0, 0.1), 6.0 * 0.1);
        assert_eq!(parse_size("8d").unwrap(), [Length::Delta(8.0); 3]);
        assert!(parse_size("-1").is_err());
        assert!(parse_size("a").is_err());
        assert!(parse_size("1,2,3,4").is_err());
        assert_eq!(
            parse_direction("Normal", 9).unwrap(),
            FilterDirection::Normal { k: 9 }
        );
        assert!(parse_direction("w", 9).is_err());
    }
}
