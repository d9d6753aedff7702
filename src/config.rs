//! The one sepmem configuration: loading, layering and `--set` overrides.
//!
//! The annotated file `launch/sepmem.json5` is the single source of the
//! defaults: it is embedded in the binary, parsed at start-up, and must name
//! every parameter (the structs below deny unknown keys and have no serde
//! defaults, so a parameter missing from the file fails the build's tests).
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
//! typo never silently falls back to a default.

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
    /// A `--set` argument is not of the form `key=value`.
    #[error("override `{0}` is not of the form section.key=value")]
    BadOverride(String),
    /// The merged values do not fit the parameter types.
    #[error("invalid configuration: {0}")]
    Invalid(String),
}

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
        for set in sets {
            apply_override(&mut merged, set)?;
        }
        serde_json::from_value(merged).map_err(|e| ConfigError::Invalid(e.to_string()))
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
                let slot = b.get_mut(&k).ok_or_else(|| ConfigError::UnknownKey {
                    key: prefix.clone(),
                    origin: origin.to_string(),
                })?;
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
}
