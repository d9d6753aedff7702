//! Transport: ROS 2 wire compatibility over zenoh.
//!
//! | module | what it holds |
//! |---|---|
//! | [`keys`] | topic ↔ key-expression mapping for the `ros2` (rmw_zenoh), `bridge` (zenoh-bridge-ros2dds) and `plain` key modes |
//! | [`attachment`] | rmw_zenoh's 33-byte sample attachment and entity GIDs |
//! | [`liveliness`] | rmw_zenoh liveliness tokens (`@ros2_lv/…`) and their QoS strings |
//! | `session` | (feature `zenoh`) a zenoh session acting as a ROS 2 node: publishers with attachments, subscriptions, tokens |
//!
//! The wire facts (key layout, attachment, token grammar, QoS strings) come
//! from rmw_zenoh's sources; see `../shared/notes/ros2-zenoh-interop.md` §1.

pub mod attachment;
pub mod keys;
pub mod liveliness;
#[cfg(feature = "zenoh")]
pub mod session;

pub use attachment::{Attachment, AttachmentError};
pub use keys::{KeyError, KeyMapper, KeyMode, RosType};
pub use liveliness::{EntityKind, LivelinessError, Qos, Token};
#[cfg(feature = "zenoh")]
pub use session::{
    free_loopback_port, EntityToken, Lane, Outlet, Participant, Received, RosPublisher,
};

use serde::{Deserialize, Serialize};
use thiserror::Error;

/// Errors of the transport layer.
#[derive(Debug, Error)]
pub enum TransportError {
    /// A topic or type could not be mapped to a key.
    #[error(transparent)]
    Key(#[from] KeyError),
    /// zenoh refused an operation.
    #[error("zenoh: {what}: {message}")]
    Zenoh {
        /// What was being done.
        what: String,
        /// zenoh's message.
        message: String,
    },
    /// `ROS_DOMAIN_ID` is set but not a domain id.
    #[error("ROS_DOMAIN_ID=`{0}` is not a number in 0..=232")]
    Domain(String),
}

/// zenoh session settings (`node.transport.zenoh`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ZenohSettings {
    /// `peer` or `client` (empty: keep the config file's / zenoh's default).
    pub mode: String,
    /// Endpoints to connect to, e.g. `tcp/127.0.0.1:7447` for a router.
    pub connect: Vec<String>,
    /// Endpoints to listen on, e.g. `tcp/127.0.0.1:0`.
    pub listen: Vec<String>,
    /// A zenoh JSON5 config file loaded first (empty: none).
    pub config_file: String,
    /// Multicast scouting (off by default, as in rmw_zenoh).
    pub multicast_scouting: bool,
    /// zenoh's receive limit `transport/link/rx/max_message_size` (bytes):
    /// a larger message is dropped by zenoh while it is reassembled, before
    /// it is held whole. Not a configuration key: the node sets it from
    /// `wire.max_bytes` (`None`: zenoh's default, 1 GiB).
    #[serde(skip)]
    pub max_message_bytes: Option<usize>,
}

/// Transport settings (`node.transport`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TransportConfig {
    /// Key mode.
    pub key_mode: KeyMode,
    /// ROS domain id; `null` takes `ROS_DOMAIN_ID` (0 when unset).
    pub domain_id: Option<u32>,
    /// Bridge namespace (bridge mode) or key prefix (plain mode).
    pub prefix: String,
    /// ROS node name.
    pub node_name: String,
    /// ROS node namespace (`/` for none).
    pub namespace: String,
    /// Security enclave (`/` for none).
    pub enclave: String,
    /// Publish `TypeHashNotSupported` instead of RIHS01 hashes (Humble peers).
    pub humble: bool,
    /// zenoh session settings.
    pub zenoh: ZenohSettings,
}

impl TransportConfig {
    /// The domain id: the configured one, else `ROS_DOMAIN_ID`, else 0.
    ///
    /// # Errors
    /// [`TransportError::Domain`] when `ROS_DOMAIN_ID` is not a number.
    pub fn effective_domain(&self) -> Result<u32, TransportError> {
        if let Some(d) = self.domain_id {
            return Ok(d);
        }
        match std::env::var("ROS_DOMAIN_ID") {
            Ok(v) if !v.trim().is_empty() => v
                .trim()
                .parse::<u32>()
                .ok()
                .filter(|d| *d <= 232)
                .ok_or(TransportError::Domain(v)),
            _ => Ok(0),
        }
    }

    /// A type as advertised by this node (hash replaced for Humble peers).
    pub fn advertised(&self, ty: &RosType) -> RosType {
        if self.humble {
            RosType::new(ty.name.clone(), keys::HASH_NOT_SUPPORTED)
        } else {
            ty.clone()
        }
    }

    /// Loopback settings for tests and the demo: peer mode, listening on
    /// `listen` and connecting to `connect` (both `tcp/127.0.0.1:<port>`).
    pub fn loopback(node_name: &str, listen: Option<u16>, connect: &[u16]) -> Self {
        Self {
            key_mode: KeyMode::Ros2,
            domain_id: Some(0),
            prefix: String::new(),
            node_name: node_name.to_string(),
            namespace: "/".to_string(),
            enclave: "/".to_string(),
            humble: false,
            zenoh: ZenohSettings {
                mode: "peer".to_string(),
                connect: connect
                    .iter()
                    .map(|p| format!("tcp/127.0.0.1:{p}"))
                    .collect(),
                listen: listen
                    .map(|p| vec![format!("tcp/127.0.0.1:{p}")])
                    .unwrap_or_default(),
                config_file: String::new(),
                multicast_scouting: false,
                max_message_bytes: None,
            },
        }
    }
}
