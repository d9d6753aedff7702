//! rosbag2 `metadata.yaml` (version 9) and QoS profile YAML: writing, plus
//! the minimal reading needed to find a bag directory's storage files.
//!
//! The layout follows `rosbag2_storage/yaml.hpp` (BagMetadata version 9):
//! `offered_qos_profiles` is a YAML list in `metadata.yaml` and the same list
//! dumped to a string in MCAP channel metadata and sqlite `topics` rows.

use std::fmt::Write as _;

/// A ROS 2 QoS profile as rosbag2 records it (durations are left at the
/// "system default" 0 s 0 ns).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Qos {
    /// KEEP_LAST depth (`None` = KEEP_ALL).
    pub depth: Option<u32>,
    /// RELIABLE (true) or BEST_EFFORT (false).
    pub reliable: bool,
    /// TRANSIENT_LOCAL (true) or VOLATILE (false).
    pub transient_local: bool,
}

impl Default for Qos {
    /// Reliable, volatile, keep last 10 (the ROS 2 default profile).
    fn default() -> Self {
        Self {
            depth: Some(10),
            reliable: true,
            transient_local: false,
        }
    }
}

impl Qos {
    /// The sensor-data profile: best effort, volatile, keep last 5.
    pub fn sensor_data() -> Self {
        Self {
            depth: Some(5),
            reliable: false,
            transient_local: false,
        }
    }

    /// YAML mapping lines of this profile, each prefixed with `indent`; the
    /// first line starts with `- `.
    pub(crate) fn yaml_item(&self, indent: &str) -> String {
        let (history, depth) = match self.depth {
            Some(d) => ("keep_last", d),
            None => ("keep_all", 0),
        };
        let mut s = String::new();
        let zero = |s: &mut String, key: &str| {
            let _ = write!(
                s,
                "{indent}  {key}:\n{indent}    sec: 0\n{indent}    nsec: 0\n"
            );
        };
        let _ = write!(
            s,
            "{indent}- history: {history}\n{indent}  depth: {depth}\n"
        );
        let _ = writeln!(
            s,
            "{indent}  reliability: {}",
            if self.reliable {
                "reliable"
            } else {
                "best_effort"
            }
        );
        let _ = writeln!(
            s,
            "{indent}  durability: {}",
            if self.transient_local {
                "transient_local"
            } else {
                "volatile"
            }
        );
        zero(&mut s, "deadline");
        zero(&mut s, "lifespan");
        let _ = writeln!(s, "{indent}  liveliness: automatic");
        zero(&mut s, "liveliness_lease_duration");
        let _ = writeln!(s, "{indent}  avoid_ros_namespace_conventions: false");
        s
    }

    /// The profile list as the YAML string stored in MCAP channel metadata.
    pub fn yaml_string(&self) -> String {
        self.yaml_item("").trim_end().to_string()
    }
}

/// One topic's entry in `metadata.yaml`.
pub(crate) struct TopicEntry<'a> {
    pub name: &'a str,
    pub type_name: &'a str,
    pub qos: Qos,
    pub type_hash: &'a str,
    pub count: u64,
}

/// Quote a YAML scalar when it could be misread.
fn scalar(s: &str) -> String {
    let plain = !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || "/_.-".contains(c))
        && !s.starts_with('-');
    if plain {
        s.to_string()
    } else {
        format!("'{}'", s.replace('\'', "''"))
    }
}

/// Render the bare BagMetadata map (version 9) for one MCAP file: `version`
/// at its root, as rosbag2_storage_mcap writes it into the MCAP `rosbag2`
/// metadata record (`YAML::Dump(convert<BagMetadata>::encode(metadata))`)
/// and as its reader expects it (`node["version"].as<int>()`).
pub(crate) fn render_bag_metadata(
    file: &str,
    start_ns: u64,
    duration_ns: u64,
    topics: &[TopicEntry<'_>],
) -> String {
    let total: u64 = topics.iter().map(|t| t.count).sum();
    let mut s = String::from("version: 9\nstorage_identifier: mcap\n");
    let _ = write!(
        s,
        "duration:\n  nanoseconds: {duration_ns}\nstarting_time:\n  nanoseconds_since_epoch: {start_ns}\nmessage_count: {total}\n"
    );
    if topics.is_empty() {
        s.push_str("topics_with_message_count:\n  []\n");
    } else {
        s.push_str("topics_with_message_count:\n");
    }
    for t in topics {
        let _ = write!(
            s,
            "  - topic_metadata:\n      name: {}\n      type: {}\n      serialization_format: cdr\n      offered_qos_profiles:\n{}      type_description_hash: {}\n    message_count: {}\n",
            scalar(t.name),
            scalar(t.type_name),
            t.qos.yaml_item("        "),
            scalar(t.type_hash),
            t.count
        );
    }
    let _ = write!(
        s,
        "compression_format: \"\"\ncompression_mode: \"\"\nrelative_file_paths:\n  - {f}\nfiles:\n  - path: {f}\n    starting_time:\n      nanoseconds_since_epoch: {start_ns}\n    duration:\n      nanoseconds: {duration_ns}\n    message_count: {total}\ncustom_data: ~\nros_distro: jazzy\n",
        f = scalar(file)
    );
    s
}

/// Render `metadata.yaml` of a bag directory: the same map as
/// [`render_bag_metadata`] under the `rosbag2_bagfile_information` key
/// (`rosbag2_storage/metadata_io.cpp`).
pub(crate) fn render_metadata(
    file: &str,
    start_ns: u64,
    duration_ns: u64,
    topics: &[TopicEntry<'_>],
) -> String {
    let mut s = String::from("rosbag2_bagfile_information:\n");
    for line in render_bag_metadata(file, start_ns, duration_ns, topics).lines() {
        let _ = writeln!(s, "  {line}");
    }
    s
}

/// `storage_identifier` and `relative_file_paths` of a `metadata.yaml`
/// (only what is needed to locate the storage files).
pub(crate) fn storage_files(yaml: &str) -> (Option<String>, Vec<String>) {
    let unquote = |v: &str| {
        let v = v.trim();
        v.strip_prefix('\'')
            .and_then(|v| v.strip_suffix('\''))
            .or_else(|| v.strip_prefix('"').and_then(|v| v.strip_suffix('"')))
            .unwrap_or(v)
            .to_string()
    };
    let mut storage = None;
    let mut files = Vec::new();
    let mut in_paths = false;
    let mut paths_indent = 0;
    for line in yaml.lines() {
        let indent = line.len() - line.trim_start().len();
        let t = line.trim();
        if let Some(v) = t.strip_prefix("storage_identifier:") {
            storage = Some(unquote(v));
        }
        if in_paths {
            if let Some(v) = t.strip_prefix("- ") {
                if indent >= paths_indent {
                    files.push(unquote(v));
                    continue;
                }
            }
            if !t.is_empty() {
                in_paths = false;
            }
        }
        if t == "relative_file_paths:" {
            in_paths = true;
            paths_indent = indent;
        }
    }
    (storage, files)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn storage_files_from_rosbag2_and_rosbags_layouts() {
        let a = "rosbag2_bagfile_information:\n  relative_file_paths:\n  - b_0.mcap\n  - 'b_1.mcap'\n  ros_distro: x\n  storage_identifier: mcap\n";
        assert_eq!(
            storage_files(a),
            (
                Some("mcap".into()),
                vec!["b_0.mcap".to_string(), "b_1.mcap".to_string()]
            )
        );
        let b = render_metadata("x_0.mcap", 5, 10, &[]);
        assert_eq!(
            storage_files(&b),
            (Some("mcap".into()), vec!["x_0.mcap".to_string()])
        );
    }
}
