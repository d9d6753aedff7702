//! The one sepmem configuration: loading, layering and `--set` overrides.
//!
//! The annotated file `launch/sepmem.json5` is the single source of the
//! defaults: it is embedded in the binary, parsed at start-up, and must name
//! every parameter (the structs below deny unknown keys and have no serde
//! defaults, so a parameter missing from the file fails the build's tests;
//! an optional one, which serde would read as `None`, is caught by the test
//! that compares the file's keys with the serialised defaults).
//!
//! Layering, lowest first:
//! 1. the embedded `launch/sepmem.json5`;
//! 2. an optional user file (`.json5`, `.json` or `.toml`) holding only the
//!    keys it changes;
//! 3. `--set section.key=value` overrides, where `value` is parsed as JSON5
//!    (numbers, booleans, arrays, quoted strings) and taken as a bare string
//!    otherwise.
//!
//! A key that does not exist in the defaults is an error that names it, so a
//! typo never silently falls back to a default. A key that was renamed (the
//! flat `membrane` keys before the section moved into one sub-section per
//! module) is an error that names its new key ([`RENAMED`]).

use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};
use std::path::{Path, PathBuf};
use thiserror::Error;

/// The annotated default configuration, embedded at build time.
pub const DEFAULT_CONFIG: &str = include_str!("../launch/sepmem.json5");

/// Errors while loading or overriding the configuration.
#[derive(Debug, Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("cannot read config file {path}: {source}")]
    Io {
        /// File path.
        path: PathBuf,
        /// Underlying error.
        source: std::io::Error,
    },
    /// The file is not valid JSON5 / TOML.
    #[error("cannot parse config {origin}: {message}")]
    Parse {
        /// Where the text came from.
        origin: String,
        /// Parser message.
        message: String,
    },
    /// A key is not a sepmem parameter.
    #[error("unknown parameter `{key}` in {origin} (see launch/sepmem.json5 for the full list)")]
    UnknownKey {
        /// Dotted key path.
        key: String,
        /// Where it came from.
        origin: String,
    },
    /// A key that was renamed: the error names the new one.
    #[error(
        "parameter `{old}` in {origin} was renamed to `{new}`{note} (see launch/sepmem.json5)"
    )]
    RenamedKey {
        /// The old dotted key.
        old: String,
        /// The new dotted key.
        new: &'static str,
        /// How the value changed, if it did (starts with "; ").
        note: String,
        /// Where it came from.
        origin: String,
    },
    /// A `--set` argument is not of the form `key=value`.
    #[error("override `{0}` is not of the form section.key=value")]
    BadOverride(String),
    /// The merged values do not fit the parameter types.
    #[error("invalid configuration: {0}")]
    Invalid(String),
}

/// Renamed keys: old dotted key, new dotted key, and how the value changed
/// (empty when only the name did). Consulted where an unknown key is reported.
pub const RENAMED: &[(&str, &str, &str)] = &[
    ("membrane.max_points", "membrane.prepare.max_points", "null keeps every point, not 0"),
    ("membrane.knn_k", "membrane.prepare.knn_k", ""),
    ("membrane.outlier_factor", "membrane.prepare.outlier_factor", "null turns the filter off, not 0"),
    ("membrane.density_sample", "membrane.prepare.density_sample", "null: every point, not 0"),
    ("membrane.local_delta", "membrane.prepare.search_delta", "\"global\" or \"local\", not a boolean"),
    ("membrane.delta_quantile", "membrane.prepare.delta_quantile", ""),
    ("membrane.delta_scale", "membrane.prepare.delta_scale", ""),
    ("membrane.pole_axis", "membrane.init.pole_axis", ""),
    ("membrane.pole_axis_candidates", "membrane.init.pole_axis_candidates", ""),
    ("membrane.pole_axis_support", "membrane.init.pole_axis_support", ""),
    ("membrane.init_quantile", "membrane.init.quantile", ""),
    ("membrane.init_margin", "membrane.init.margin", ""),
    ("membrane.grid_start", "membrane.init.grid", ""),
    ("membrane.grid_max", "membrane.schedule.growth.grid_max", ""),
    ("membrane.grid_step", "membrane.schedule.growth.grid_step", ""),
    ("membrane.adaptive", "membrane.schedule.growth", "an object { grid_max, grid_step, g_min, grow_after } grows the grid, null keeps it fixed"),
    ("membrane.g_min", "membrane.schedule.growth.g_min", ""),
    ("membrane.grow_after", "membrane.schedule.growth.grow_after", ""),
    ("membrane.div_min", "membrane.fit.div_min", ""),
    ("membrane.alpha", "membrane.fit.alpha", ""),
    ("membrane.alpha_warm", "membrane.fit.alpha_warm", ""),
    ("membrane.roughness", "membrane.fit.roughness", ""),
    ("membrane.redistribute_stretch", "membrane.fit.redistribute_stretch", "null turns it off, not 0"),
    ("membrane.boundaries", "membrane.step.boundaries", ""),
    ("membrane.beta", "membrane.step.beta", ""),
    ("membrane.cross_scale", "membrane.step.cross_scale", ""),
    ("membrane.cross_min_delta", "membrane.step.cross_min_delta", ""),
    ("membrane.cross_max", "membrane.step.cross_max", ""),
    ("membrane.band_inner_delta", "membrane.step.band_inner_delta", ""),
    ("membrane.band_outer_delta", "membrane.step.band_outer_delta", ""),
    ("membrane.inside_denser", "membrane.step.inside_denser", "an object { inner_margin } keeps the rule, null accepts every boundary"),
    ("membrane.inner_margin", "membrane.step.inside_denser.inner_margin", ""),
    ("membrane.significance", "membrane.step.significance", ""),
    ("membrane.sparse_warm_search", "membrane.step.sparse_warm_search", ""),
    ("membrane.sparse_cold_search", "membrane.step.sparse_cold_search", ""),
    ("membrane.inward_force", "membrane.step.inward", "an object { voxel_delta, min_points, shift } keeps it, null turns it off"),
    ("membrane.inward_voxel_delta", "membrane.step.inward.voxel_delta", ""),
    ("membrane.inward_min_points", "membrane.step.inward.min_points", ""),
    ("membrane.inward_step", "membrane.step.inward.shift", ""),
    ("membrane.spatial_weight", "membrane.step.spatial_weight", ""),
    ("membrane.attributes", "membrane.step.attributes", ""),
    ("membrane.threads", "membrane.step.threads", ""),
    ("membrane.median_filter", "membrane.regularize.median_filter", ""),
    ("membrane.pole_tension", "membrane.regularize.pole_tension.strength", "now part of the object regularize.pole_tension { strength, rows }, which null turns off (not 0)"),
    ("membrane.pole_tension_rows", "membrane.regularize.pole_tension.rows", ""),
    ("membrane.warm_back_smoothing", "membrane.regularize.warm_back_smoothing", "null turns it off, not 0"),
    ("membrane.depth_start", "membrane.schedule.depth_start", ""),
    ("membrane.depth_warm", "membrane.schedule.depth_warm", ""),
    ("membrane.depth_decay", "membrane.schedule.depth_decay", ""),
    ("membrane.depth_floor_delta", "membrane.schedule.depth_floor_delta", ""),
    ("membrane.plateau_eps", "membrane.schedule.plateau_eps", ""),
    ("membrane.plateau_patience", "membrane.schedule.plateau_patience", ""),
    ("membrane.max_iterations", "membrane.schedule.max_iterations", ""),
    ("membrane.time_limit_ms", "membrane.schedule.time_limit_ms", "null: no limit, not 0"),
    ("membrane.viewpoint", "membrane.view.viewpoint", ""),
    ("membrane.view_completion", "membrane.view.completion", "\"none\" or \"mirror\", not a boolean"),
];

/// Every sepmem parameter. Sections are documented in `launch/sepmem.json5`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// Point density estimation (paper §III-A).
    pub density: crate::density::DensityConfig,
    /// Separability search (paper §III-B/C).
    pub separability: crate::separability::SeparabilityConfig,
    /// Evaluation metrics (`sepmem eval`, benchmarks).
    pub metrics: crate::metrics::MetricsConfig,
    /// The separability membrane (paper §III-D to §III-F): see [`crate::membrane::MembraneConfig`].
    pub membrane: crate::membrane::MembraneConfig,
    /// ROS 2 wire limits (PointCloud2 decoding).
    pub wire: crate::wire::pointcloud2::WireConfig,
    /// The live node (`sepmem node`): topics, outputs, real-time bounds, sharding, transport.
    pub node: crate::node::NodeConfig,
    /// The frame pipeline: streams, warm starts, per-frame budget, output topics.
    pub pipeline: crate::pipeline::PipelineConfig,
}

impl Config {
    /// Load the defaults, then `path` (if any), then the `sets` overrides.
    ///
    /// # Errors
    /// [`ConfigError`] naming the file, key or value at fault.
    pub fn load(path: Option<&Path>, sets: &[String]) -> Result<Self, ConfigError> {
        let mut merged = parse_text(DEFAULT_CONFIG, "json5", "embedded launch/sepmem.json5")?;
        if let Some(path) = path {
            let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Io {
                path: path.to_path_buf(),
                source,
            })?;
            let ext = path
                .extension()
                .and_then(|e| e.to_str())
                .unwrap_or("json5")
                .to_ascii_lowercase();
            let origin = path.display().to_string();
            let user = parse_text(&text, &ext, &origin)?;
            merge(&mut merged, user, &mut String::new(), &origin)?;
        }
        with_overrides(merged, sets)
    }

    /// This configuration with the `sets` overrides (`section.key=value`, as
    /// `--set` takes them) applied.
    ///
    /// # Errors
    /// [`ConfigError`] naming the key or value at fault.
    pub fn with_sets(&self, sets: &[String]) -> Result<Self, ConfigError> {
        let value = serde_json::to_value(self).map_err(|e| ConfigError::Invalid(e.to_string()))?;
        with_overrides(value, sets)
    }

    /// The embedded defaults.
    ///
    /// # Errors
    /// Only if the embedded file is broken, which the test suite rules out.
    pub fn defaults() -> Result<Self, ConfigError> {
        Self::load(None, &[])
    }

    /// The node's reconstruction backend, built from the sections it needs
    /// (membrane, pipeline, wire and the collision-object output): the node
    /// never sees the whole configuration.
    ///
    /// # Errors
    /// [`ConfigError`] naming the first bad membrane key.
    pub fn pipeline_backend(
        &self,
    ) -> Result<crate::node::PipelineBackend, crate::membrane::ConfigError> {
        Ok(crate::node::PipelineBackend::new(
            &self.membrane,
            self.pipeline.clone(),
            self.wire.clone(),
        )?
        .with_collision_objects(self.node.outputs.collision_objects.clone()))
    }
}

/// `merged` with the `sets` overrides applied, as a [`Config`].
fn with_overrides(mut merged: Value, sets: &[String]) -> Result<Config, ConfigError> {
    for set in sets {
        apply_override(&mut merged, set)?;
    }
    // The path names the key whose value a type refused (a share, a count).
    serde_path_to_error::deserialize(merged)
        .map_err(|e| ConfigError::Invalid(format!("{}: {}", e.path(), e.inner())))
}

fn parse_text(text: &str, ext: &str, origin: &str) -> Result<Value, ConfigError> {
    let parsed = match ext {
        "toml" => toml::from_str::<Value>(text).map_err(|e| e.to_string()),
        _ => json5::from_str::<Value>(text).map_err(|e| e.to_string()),
    };
    parsed.map_err(|message| ConfigError::Parse {
        origin: origin.to_string(),
        message,
    })
}

/// Deep-merge `over` into `base`; every key of `over` must exist in `base`.
fn merge(
    base: &mut Value,
    over: Value,
    prefix: &mut String,
    origin: &str,
) -> Result<(), ConfigError> {
    match (base, over) {
        (Value::Object(b), Value::Object(o)) => {
            for (k, v) in o {
                let len = prefix.len();
                if !prefix.is_empty() {
                    prefix.push('.');
                }
                prefix.push_str(&k);
                let slot = b.get_mut(&k).ok_or_else(|| unknown_key(prefix, origin))?;
                merge(slot, v, prefix, origin)?;
                prefix.truncate(len);
            }
            Ok(())
        }
        (slot, v) => {
            *slot = v;
            Ok(())
        }
    }
}

/// The error for a key missing from the defaults: [`ConfigError::RenamedKey`]
/// when [`RENAMED`] lists it, [`ConfigError::UnknownKey`] otherwise.
fn unknown_key(key: &str, origin: &str) -> ConfigError {
    match RENAMED.iter().find(|(old, _, _)| *old == key) {
        Some(&(_, new, note)) => ConfigError::RenamedKey {
            old: key.to_string(),
            new,
            note: if note.is_empty() {
                String::new()
            } else {
                format!("; {note}")
            },
            origin: origin.to_string(),
        },
        None => ConfigError::UnknownKey {
            key: key.to_string(),
            origin: origin.to_string(),
        },
    }
}

fn apply_override(base: &mut Value, set: &str) -> Result<(), ConfigError> {
    let (key, raw) = set
        .split_once('=')
        .ok_or_else(|| ConfigError::BadOverride(set.to_string()))?;
    let key = key.trim();
    if key.is_empty() {
        return Err(ConfigError::BadOverride(set.to_string()));
    }
    let value = json5::from_str::<Value>(raw.trim())
        .unwrap_or_else(|_| Value::String(raw.trim().to_string()));
    let mut over = value;
    for part in key.rsplit('.') {
        let mut m = Map::new();
        m.insert(part.to_string(), over);
        over = Value::Object(m);
    }
    merge(base, over, &mut String::new(), "--set")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn embedded_defaults_parse() {
        Config::defaults().unwrap();
    }

    #[test]
    fn unknown_keys_are_rejected_with_their_name() {
        let err = Config::load(None, &["no_such.section=1".into()]).unwrap_err();
        assert!(err.to_string().contains("`no_such`"), "{err}");
        let err = Config::load(None, &["missing_equals".into()]).unwrap_err();
        assert!(matches!(err, ConfigError::BadOverride(_)));
    }

    #[test]
    fn a_refused_value_names_its_key() {
        for (set, key) in [
            (
                "pipeline.refit.min_model_inliers=1.5",
                "pipeline.refit.min_model_inliers: ",
            ),
            (
                "pipeline.model_icp.normal_k=2",
                "pipeline.model_icp.normal_k: ",
            ),
            ("pipeline.model_icp.steps=0", "pipeline.model_icp.steps: "),
            (
                "pipeline.model_icp.refine.max_points=0",
                "pipeline.model_icp.refine.max_points: ",
            ),
            (
                "pipeline.model_icp.keep_normals=0",
                "pipeline.model_icp.keep_normals: ",
            ),
            ("membrane.fit.alpha=\"x\"", "membrane.fit.alpha: "),
        ] {
            let err = Config::load(None, &[set.into()]).unwrap_err();
            assert!(err.to_string().contains(key), "{set}: {err}");
        }
    }

    #[test]
    fn old_membrane_keys_name_their_new_keys() {
        for (old, new) in [
            ("membrane.alpha=2", "`membrane.fit.alpha`"),
            ("membrane.threads=1", "`membrane.step.threads`"),
            ("membrane.inward_force=false", "`membrane.step.inward`"),
            (
                "membrane.pole_tension_rows=3",
                "`membrane.regularize.pole_tension.rows`",
            ),
        ] {
            let err = Config::load(None, &[old.into()]).unwrap_err();
            assert!(matches!(err, ConfigError::RenamedKey { .. }), "{err}");
            assert!(err.to_string().contains(new), "{old}: {err}");
        }
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("user.toml");
        std::fs::write(&path, "[membrane]\nmax_iterations = 10\n").unwrap();
        let err = Config::load(Some(&path), &[]).unwrap_err();
        let text = err.to_string();
        assert!(text.contains("`membrane.max_iterations`"), "{text}");
        assert!(
            text.contains("`membrane.schedule.max_iterations`"),
            "{text}"
        );
    }

    #[test]
    fn every_old_key_is_gone_and_every_new_key_exists() {
        let defaults = serde_json::to_value(Config::defaults().unwrap()).unwrap();
        let at = |key: &str| {
            key.split('.')
                .try_fold(&defaults, |v, part| v.as_object()?.get(part))
        };
        for (old, new, _) in RENAMED {
            assert!(at(old).is_none(), "{old} still exists");
            assert!(at(new).is_some(), "{new} does not exist");
        }
    }

    /// The key paths of `v` (objects only; arrays and scalars are leaves).
    fn key_paths(v: &Value, prefix: &str, out: &mut Vec<String>) {
        if let Value::Object(m) = v {
            for (k, child) in m {
                let path = format!("{prefix}{k}");
                key_paths(child, &format!("{path}."), out);
                out.push(path);
            }
        }
    }

    /// The embedded file names every key, including the optional ones
    /// (an `Option` missing from the file would otherwise read as `None`),
    /// and its membrane section equals `MembraneConfig::default()`.
    #[test]
    fn embedded_file_documents_every_key_and_matches_the_defaults() {
        let cfg = Config::defaults().unwrap();
        let embedded = parse_text(DEFAULT_CONFIG, "json5", "embedded").unwrap();
        let (mut file, mut typed) = (Vec::new(), Vec::new());
        key_paths(&embedded, "", &mut file);
        key_paths(&serde_json::to_value(&cfg).unwrap(), "", &mut typed);
        file.sort();
        typed.sort();
        assert_eq!(file, typed);
        assert_eq!(cfg.membrane, crate::membrane::MembraneConfig::default());
    }
}
