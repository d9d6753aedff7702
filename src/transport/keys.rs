//! Topic names ↔ zenoh key expressions in the three key modes.
//!
//! * [`KeyMode::Ros2`]: rmw_zenoh's data keys
//!   `<domain>/<topic without leading/trailing '/'>/<dds type name>/<type hash>`,
//!   e.g. `0/seg/points/sensor_msgs::msg::dds_::PointCloud2_/RIHS01_9198…`.
//!   Subscriptions wildcard the hash (`…/PointCloud2_/*`) so Humble
//!   (`TypeHashNotSupported`) and Jazzy publishers are both accepted.
//! * [`KeyMode::Bridge`]: zenoh-bridge-ros2dds keys: the topic without its
//!   leading `/`, prefixed by the bridge namespace if one is configured; no
//!   domain, type or hash.
//! * [`KeyMode::Plain`]: `<prefix>/<topic>` for plain zenoh applications.
//!
//! Topic *patterns* use zenoh's chunk wildcards: `*` is one name component
//! and `**` any number of them (`/seg/**` matches `/seg/a/points`).

use serde::{Deserialize, Serialize};
use thiserror::Error;

/// rmw_zenoh's type-hash placeholder for distributions without RIHS01 (Humble).
pub const HASH_NOT_SUPPORTED: &str = "TypeHashNotSupported";

/// Errors while building or reading key expressions.
#[derive(Debug, Clone, Error, PartialEq, Eq)]
pub enum KeyError {
    /// The topic name is empty or has an empty component (`//`).
    #[error("topic name `{0}` is empty or has an empty component")]
    BadTopic(String),
    /// A ROS type name is not of the form `pkg/msg/Name`.
    #[error("ROS type name `{0}` is not of the form pkg/msg/Name")]
    BadType(String),
    /// A received key does not have the layout of the configured mode.
    #[error("key `{key}` does not match the {mode} key layout")]
    Foreign {
        /// The received key expression.
        key: String,
        /// The configured key mode.
        mode: &'static str,
    },
}

/// How topics map to zenoh keys.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum KeyMode {
    /// rmw_zenoh (`<domain>/<topic>/<dds type>/<hash>`), with attachments and liveliness tokens.
    Ros2,
    /// zenoh-bridge-ros2dds (`[<namespace>/]<topic>`).
    Bridge,
    /// `<prefix>/<topic>`.
    Plain,
}

impl KeyMode {
    /// Lower-case name as written in the configuration.
    pub fn name(self) -> &'static str {
        match self {
            KeyMode::Ros2 => "ros2",
            KeyMode::Bridge => "bridge",
            KeyMode::Plain => "plain",
        }
    }
}

/// A ROS 2 message type with its RIHS01 hash (or [`HASH_NOT_SUPPORTED`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RosType {
    /// `pkg/msg/Name`.
    pub name: String,
    /// `RIHS01_<64 hex>` or [`HASH_NOT_SUPPORTED`].
    pub hash: String,
}

impl RosType {
    /// A type from its name and hash.
    pub fn new(name: impl Into<String>, hash: impl Into<String>) -> Self {
        Self {
            name: name.into(),
            hash: hash.into(),
        }
    }

    /// The DDS type name rmw_zenoh puts in keys: `pkg::msg::dds_::Name_`.
    ///
    /// # Errors
    /// [`KeyError::BadType`] when the name is not `pkg/msg/Name`.
    pub fn dds_name(&self) -> Result<String, KeyError> {
        dds_type_name(&self.name)
    }
}

/// `pkg/msg/Name` → `pkg::msg::dds_::Name_`.
///
/// # Errors
/// [`KeyError::BadType`] when the name is not of the form `pkg/<kind>/Name`.
pub fn dds_type_name(ros_type: &str) -> Result<String, KeyError> {
    let parts: Vec<&str> = ros_type.split('/').collect();
    match parts.as_slice() {
        [pkg, kind, name] if !pkg.is_empty() && !kind.is_empty() && !name.is_empty() => {
            Ok(format!("{pkg}::{kind}::dds_::{name}_"))
        }
        _ => Err(KeyError::BadType(ros_type.to_string())),
    }
}

/// `pkg::msg::dds_::Name_` → `pkg/msg/Name`; `None` if not a DDS type name.
pub fn ros_type_from_dds(dds: &str) -> Option<String> {
    let parts: Vec<&str> = dds.split("::").collect();
    match parts.as_slice() {
        [pkg, kind, "dds_", name] => {
            let name = name.strip_suffix('_')?;
            Some(format!("{pkg}/{kind}/{name}"))
        }
        _ => None,
    }
}

/// A topic with its leading and trailing `/` removed, checked for empty parts.
///
/// # Errors
/// [`KeyError::BadTopic`] for an empty topic or one with `//`.
pub fn strip_topic(topic: &str) -> Result<&str, KeyError> {
    let t = topic.trim_matches('/');
    if t.is_empty() || t.split('/').any(str::is_empty) {
        return Err(KeyError::BadTopic(topic.to_string()));
    }
    Ok(t)
}

/// Maps topics to keys (and received keys back to topics) for one key mode.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct KeyMapper {
    /// The key mode.
    pub mode: KeyMode,
    /// ROS domain id (ros2 mode).
    pub domain: u32,
    /// Key prefix: the bridge namespace (bridge mode, may be empty) or the
    /// plain prefix (plain mode). Stored without leading/trailing `/`.
    pub prefix: String,
}

impl KeyMapper {
    /// A mapper; `prefix` is used by the bridge and plain modes.
    pub fn new(mode: KeyMode, domain: u32, prefix: &str) -> Self {
        Self {
            mode,
            domain,
            prefix: prefix.trim_matches('/').to_string(),
        }
    }

    fn prefixed(&self, t: &str) -> String {
        if self.prefix.is_empty() {
            t.to_string()
        } else {
            format!("{}/{t}", self.prefix)
        }
    }

    /// The key a publisher of `topic` with type `ty` puts on.
    ///
    /// # Errors
    /// [`KeyError`] for a malformed topic or type.
    pub fn publish_key(&self, topic: &str, ty: &RosType) -> Result<String, KeyError> {
        let t = strip_topic(topic)?;
        Ok(match self.mode {
            KeyMode::Ros2 => format!("{}/{t}/{}/{}", self.domain, ty.dds_name()?, ty.hash),
            KeyMode::Bridge | KeyMode::Plain => self.prefixed(t),
        })
    }

    /// The key expression subscribing to a topic pattern of type `ty`
    /// (the hash is wildcarded in ros2 mode).
    ///
    /// # Errors
    /// [`KeyError`] for a malformed pattern or type.
    pub fn subscribe_key(&self, pattern: &str, ty: &RosType) -> Result<String, KeyError> {
        let t = strip_topic(pattern)?;
        Ok(match self.mode {
            KeyMode::Ros2 => format!("{}/{t}/{}/*", self.domain, ty.dds_name()?),
            KeyMode::Bridge | KeyMode::Plain => self.prefixed(t),
        })
    }

    /// The ROS topic (`/a/b`) a received key belongs to.
    ///
    /// # Errors
    /// [`KeyError::Foreign`] when the key does not have this mode's layout.
    pub fn topic_of(&self, key: &str) -> Result<String, KeyError> {
        let foreign = || KeyError::Foreign {
            key: key.to_string(),
            mode: self.mode.name(),
        };
        let rest = match self.mode {
            KeyMode::Ros2 => {
                let domain = self.domain.to_string();
                let rest = key
                    .strip_prefix(domain.as_str())
                    .and_then(|r| r.strip_prefix('/'))
                    .ok_or_else(foreign)?;
                // Drop the trailing `<type>/<hash>`.
                let (rest, _hash) = rest.rsplit_once('/').ok_or_else(foreign)?;
                let (rest, ty) = rest.rsplit_once('/').ok_or_else(foreign)?;
                if ros_type_from_dds(ty).is_none() {
                    return Err(foreign());
                }
                rest
            }
            KeyMode::Bridge | KeyMode::Plain => {
                if self.prefix.is_empty() {
                    key
                } else {
                    key.strip_prefix(self.prefix.as_str())
                        .and_then(|r| r.strip_prefix('/'))
                        .ok_or_else(foreign)?
                }
            }
        };
        let t = strip_topic(rest).map_err(|_| foreign())?;
        Ok(format!("/{t}"))
    }
}

/// Expand `{topic}` in an output topic template with the input topic
/// (`/seg/points` + `{topic}/mesh` → `/seg/points/mesh`).
pub fn expand_topic_template(template: &str, input_topic: &str) -> String {
    let out = template.replace("{topic}", input_topic.trim_matches('/'));
    let parts: Vec<&str> = out.split('/').filter(|p| !p.is_empty()).collect();
    format!("/{}", parts.join("/"))
}

#[cfg(test)]
mod tests {
    use super::*;

    const PC2_HASH: &str =
        "RIHS01_9198cabf7da3796ae6fe19c4cb3bdd3525492988c70522628af5daa124bae2b5";

    fn pc2() -> RosType {
        RosType::new("sensor_msgs/msg/PointCloud2", PC2_HASH)
    }

    #[test]
    fn ros2_key_matches_the_rmw_zenoh_example() {
        // Example taken verbatim from the interop notes (rmw_zenoh TopicInfo).
        let m = KeyMapper::new(KeyMode::Ros2, 0, "");
        let key = m.publish_key("/robot1/seg/points", &pc2()).unwrap();
        assert_eq!(
            key,
            "0/robot1/seg/points/sensor_msgs::msg::dds_::PointCloud2_/RIHS01_9198cabf7da3796ae6fe19c4cb3bdd3525492988c70522628af5daa124bae2b5"
        );
        assert_eq!(m.topic_of(&key).unwrap(), "/robot1/seg/points");
        let sub = m.subscribe_key("/robot1/**", &pc2()).unwrap();
        assert_eq!(sub, "0/robot1/**/sensor_msgs::msg::dds_::PointCloud2_/*");
        // Humble publishers use a placeholder hash; the topic still parses.
        let humble =
            "0/robot1/seg/points/sensor_msgs::msg::dds_::PointCloud2_/TypeHashNotSupported";
        assert_eq!(m.topic_of(humble).unwrap(), "/robot1/seg/points");
    }

    #[test]
    fn ros2_keys_reject_other_domains_and_layouts() {
        let m = KeyMapper::new(KeyMode::Ros2, 7, "");
        assert!(m
            .topic_of("0/a/sensor_msgs::msg::dds_::PointCloud2_/h")
            .is_err());
        assert!(m.topic_of("7/a/b/c").is_err());
        assert!(m
            .topic_of("7/sensor_msgs::msg::dds_::PointCloud2_/h")
            .is_err());
        assert_eq!(
            m.topic_of("7/a/sensor_msgs::msg::dds_::PointCloud2_/h")
                .unwrap(),
            "/a"
        );
    }

    #[test]
    fn bridge_and_plain_keys() {
        let b = KeyMapper::new(KeyMode::Bridge, 0, "");
        assert_eq!(b.publish_key("/seg/points", &pc2()).unwrap(), "seg/points");
        assert_eq!(b.topic_of("seg/points").unwrap(), "/seg/points");
        let ns = KeyMapper::new(KeyMode::Bridge, 0, "/botX");
        assert_eq!(
            ns.publish_key("/seg/points", &pc2()).unwrap(),
            "botX/seg/points"
        );
        assert_eq!(ns.topic_of("botX/seg/points").unwrap(), "/seg/points");
        assert!(ns.topic_of("botY/seg/points").is_err());
        let p = KeyMapper::new(KeyMode::Plain, 0, "sepmem/");
        assert_eq!(p.subscribe_key("/in/**", &pc2()).unwrap(), "sepmem/in/**");
    }

    #[test]
    fn type_names_round_trip() {
        assert_eq!(
            dds_type_name("visualization_msgs/msg/MarkerArray").unwrap(),
            "visualization_msgs::msg::dds_::MarkerArray_"
        );
        assert_eq!(
            ros_type_from_dds("visualization_msgs::msg::dds_::MarkerArray_").unwrap(),
            "visualization_msgs/msg/MarkerArray"
        );
        assert!(dds_type_name("MarkerArray").is_err());
        assert!(strip_topic("//").is_err());
        assert!(strip_topic("/a//b").is_err());
    }

    #[test]
    fn templates_expand() {
        assert_eq!(
            expand_topic_template("{topic}/mesh", "/seg/points"),
            "/seg/points/mesh"
        );
        assert_eq!(
            expand_topic_template("/diagnostics", "/seg/points"),
            "/diagnostics"
        );
        assert_eq!(expand_topic_template("out/{topic}", "/a"), "/out/a");
    }
}
