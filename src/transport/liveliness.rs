//! rmw_zenoh liveliness tokens: the ROS 2 graph (`ros2 node list`,
//! `ros2 topic list`) on a zenoh network.
//!
//! Token keys have the form
//! `@ros2_lv/<domain>/<zid>/<nid>/<id>/<kind>/<enclave>/<namespace>/<node>[/<topic>/<type>/<hash>/<qos>]`
//! where `kind` is `NN` (node), `MP` (publisher), `MS` (subscription), `SS`
//! or `SC` (service server/client); every `/` inside enclave, namespace,
//! node, topic and type is replaced by `%` (an empty or root namespace is
//! `%`); and `qos` is
//! `<rel>:<dur>:<hist>,<depth>:<dl_s>,<dl_ns>:<ls_s>,<ls_ns>:<liv>,<liv_s>,<liv_ns>`
//! with every field equal to rmw_zenoh's default (KEEP_LAST 42, RELIABLE,
//! VOLATILE, infinite durations, AUTOMATIC liveliness) left empty
//! (`liveliness_utils.cpp`, `qos.cpp`).

use thiserror::Error;

/// The admin-space prefix of rmw_zenoh liveliness tokens.
pub const ADMIN_SPACE: &str = "@ros2_lv";

/// Errors while parsing liveliness tokens.
#[derive(Debug, Clone, Error, PartialEq, Eq)]
pub enum LivelinessError {
    /// The key does not start with `@ros2_lv` or has the wrong number of parts.
    #[error("liveliness key `{0}` is not an rmw_zenoh token (@ros2_lv/…, 9 or 13 parts)")]
    Layout(String),
    /// A component is empty.
    #[error("liveliness key `{0}` has an empty component")]
    Empty(String),
    /// A number (domain, node id, entity id) does not parse.
    #[error("liveliness key `{key}`: `{part}` is not a number")]
    Number {
        /// The key.
        key: String,
        /// The offending component.
        part: String,
    },
    /// The entity kind is not NN/MP/MS/SS/SC.
    #[error("liveliness key `{key}`: unknown entity kind `{kind}`")]
    Kind {
        /// The key.
        key: String,
        /// The offending kind.
        kind: String,
    },
    /// The QoS component is malformed.
    #[error("QoS string `{0}` is malformed")]
    Qos(String),
}

/// Kind of graph entity.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum EntityKind {
    /// A node (`NN`).
    Node,
    /// A publisher (`MP`).
    Publisher,
    /// A subscription (`MS`).
    Subscription,
    /// A service server (`SS`).
    ServiceServer,
    /// A service client (`SC`).
    ServiceClient,
}

impl EntityKind {
    /// The two-letter code used in token keys.
    pub fn code(self) -> &'static str {
        match self {
            EntityKind::Node => "NN",
            EntityKind::Publisher => "MP",
            EntityKind::Subscription => "MS",
            EntityKind::ServiceServer => "SS",
            EntityKind::ServiceClient => "SC",
        }
    }

    fn from_code(code: &str) -> Option<Self> {
        Some(match code {
            "NN" => EntityKind::Node,
            "MP" => EntityKind::Publisher,
            "MS" => EntityKind::Subscription,
            "SS" => EntityKind::ServiceServer,
            "SC" => EntityKind::ServiceClient,
            _ => return None,
        })
    }
}

/// Reliability policy (rmw enum values).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reliability {
    /// RELIABLE = 1 (rmw_zenoh default).
    Reliable,
    /// BEST_EFFORT = 2.
    BestEffort,
}

/// Durability policy (rmw enum values).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Durability {
    /// TRANSIENT_LOCAL = 1.
    TransientLocal,
    /// VOLATILE = 2 (rmw_zenoh default).
    Volatile,
}

/// The QoS profile part of a token (history is always KEEP_LAST here;
/// deadline, lifespan and liveliness lease are infinite / AUTOMATIC).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Qos {
    /// Reliability.
    pub reliability: Reliability,
    /// Durability.
    pub durability: Durability,
    /// `None` for KEEP_ALL, `Some(depth)` for KEEP_LAST.
    pub keep_last: Option<u32>,
}

impl Qos {
    /// `rclcpp::SensorDataQoS`: best effort, volatile, keep last 5.
    pub const SENSOR_DATA: Qos = Qos {
        reliability: Reliability::BestEffort,
        durability: Durability::Volatile,
        keep_last: Some(5),
    };
    /// `rclcpp::QoS(10)`: reliable, volatile, keep last 10.
    pub const DEFAULT_10: Qos = Qos {
        reliability: Reliability::Reliable,
        durability: Durability::Volatile,
        keep_last: Some(10),
    };

    /// The token form, with defaults left empty.
    pub fn to_keyexpr(&self) -> String {
        let rel = match self.reliability {
            Reliability::Reliable => "",
            Reliability::BestEffort => "2",
        };
        let dur = match self.durability {
            Durability::Volatile => "",
            Durability::TransientLocal => "1",
        };
        let hist = match self.keep_last {
            Some(42) => String::from(","),
            Some(d) => format!(",{d}"),
            None => String::from("2,"),
        };
        format!("{rel}:{dur}:{hist}:,:,:,,")
    }

    /// Parse the token form (deadline/lifespan/liveliness are checked for
    /// shape but not kept).
    ///
    /// # Errors
    /// [`LivelinessError::Qos`] for a malformed string.
    pub fn from_keyexpr(s: &str) -> Result<Self, LivelinessError> {
        let bad = || LivelinessError::Qos(s.to_string());
        let parts: Vec<&str> = s.split(':').collect();
        if parts.len() < 6 {
            return Err(bad());
        }
        let sub = |i: usize, n: usize| -> Result<Vec<&str>, LivelinessError> {
            let v: Vec<&str> = parts[i].split(',').collect();
            if v.len() == n {
                Ok(v)
            } else {
                Err(bad())
            }
        };
        let reliability = match parts[0] {
            "" | "1" => Reliability::Reliable,
            "2" => Reliability::BestEffort,
            _ => return Err(bad()),
        };
        let durability = match parts[1] {
            "" | "2" => Durability::Volatile,
            "1" => Durability::TransientLocal,
            _ => return Err(bad()),
        };
        let hist = sub(2, 2)?;
        let depth = if hist[1].is_empty() {
            42
        } else {
            hist[1].parse::<u32>().map_err(|_| bad())?
        };
        let keep_last = match hist[0] {
            "" | "1" => Some(depth),
            "2" => None,
            _ => return Err(bad()),
        };
        sub(3, 2)?;
        sub(4, 2)?;
        sub(5, 3)?;
        Ok(Self {
            reliability,
            durability,
            keep_last,
        })
    }
}

/// The topic part of a publisher/subscription token.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TopicToken {
    /// Fully qualified topic (`/a/b`).
    pub topic: String,
    /// DDS type name (`pkg::msg::dds_::Name_`).
    pub dds_type: String,
    /// Type hash (`RIHS01_…`).
    pub hash: String,
    /// QoS.
    pub qos: Qos,
}

/// One rmw_zenoh liveliness token.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Token {
    /// ROS domain id.
    pub domain: u32,
    /// Zenoh session id (as printed by zenoh).
    pub zid: String,
    /// Node id (unique per session).
    pub node_id: u64,
    /// Entity id (unique per session; equals `node_id` for the node itself).
    pub entity_id: u64,
    /// Entity kind.
    pub kind: EntityKind,
    /// Security enclave (`/` when none).
    pub enclave: String,
    /// Node namespace (`/` when none).
    pub namespace: String,
    /// Node name.
    pub node: String,
    /// Topic, type, hash and QoS (publishers and subscriptions).
    pub topic: Option<TopicToken>,
}

/// `/` → `%`; an empty name becomes `%`.
pub fn mangle(name: &str) -> String {
    if name.is_empty() {
        "%".to_string()
    } else {
        name.replace('/', "%")
    }
}

/// `%` → `/`.
pub fn demangle(name: &str) -> String {
    name.replace('%', "/")
}

impl Token {
    /// The token's key expression.
    pub fn key(&self) -> String {
        let mut k = format!(
            "{ADMIN_SPACE}/{}/{}/{}/{}/{}/{}/{}/{}",
            self.domain,
            self.zid,
            self.node_id,
            self.entity_id,
            self.kind.code(),
            mangle(&self.enclave),
            mangle(&self.namespace),
            mangle(&self.node)
        );
        if let Some(t) = &self.topic {
            k.push('/');
            k.push_str(&mangle(&t.topic));
            k.push('/');
            k.push_str(&mangle(&t.dds_type));
            k.push('/');
            k.push_str(&t.hash);
            k.push('/');
            k.push_str(&t.qos.to_keyexpr());
        }
        k
    }

    /// Parse a token key expression.
    ///
    /// # Errors
    /// [`LivelinessError`] naming the key and the problem.
    pub fn parse(key: &str) -> Result<Self, LivelinessError> {
        let parts: Vec<&str> = key.split('/').collect();
        if parts.first() != Some(&ADMIN_SPACE) || !(parts.len() == 9 || parts.len() == 13) {
            return Err(LivelinessError::Layout(key.to_string()));
        }
        if parts.iter().any(|p| p.is_empty()) {
            return Err(LivelinessError::Empty(key.to_string()));
        }
        let num = |p: &str| -> Result<u64, LivelinessError> {
            p.parse::<u64>().map_err(|_| LivelinessError::Number {
                key: key.to_string(),
                part: p.to_string(),
            })
        };
        let domain = u32::try_from(num(parts[1])?).map_err(|_| LivelinessError::Number {
            key: key.to_string(),
            part: parts[1].to_string(),
        })?;
        let kind = EntityKind::from_code(parts[5]).ok_or_else(|| LivelinessError::Kind {
            key: key.to_string(),
            kind: parts[5].to_string(),
        })?;
        let topic = if parts.len() == 13 {
            Some(TopicToken {
                topic: demangle(parts[9]),
                dds_type: demangle(parts[10]),
                hash: parts[11].to_string(),
                qos: Qos::from_keyexpr(parts[12])?,
            })
        } else {
            None
        };
        if (kind == EntityKind::Node) != topic.is_none() {
            return Err(LivelinessError::Layout(key.to_string()));
        }
        Ok(Self {
            domain,
            zid: parts[2].to_string(),
            node_id: num(parts[3])?,
            entity_id: num(parts[4])?,
            kind,
            enclave: demangle(parts[6]),
            namespace: demangle(parts[7]),
            node: demangle(parts[8]),
            topic,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn qos_strings_match_the_rmw_zenoh_examples() {
        // Examples from the interop notes (rmw_zenoh qos_to_keyexpr).
        assert_eq!(Qos::DEFAULT_10.to_keyexpr(), "::,10:,:,:,,");
        assert_eq!(Qos::SENSOR_DATA.to_keyexpr(), "2::,5:,:,:,,");
        let tl = Qos {
            reliability: Reliability::Reliable,
            durability: Durability::TransientLocal,
            keep_last: Some(1),
        };
        assert_eq!(tl.to_keyexpr(), ":1:,1:,:,:,,");
        for s in [
            "::,10:,:,:,,",
            "2::,5:,:,:,,",
            ":1:,1:,:,:,,",
            "::,:,:,:,,",
            "::2,:,:,:,,",
        ] {
            assert_eq!(Qos::from_keyexpr(s).unwrap().to_keyexpr(), s, "{s}");
        }
        // Explicit (non-empty) defaults parse to the same profile.
        assert_eq!(
            Qos::from_keyexpr("1:2:1,10:,:,:,,").unwrap(),
            Qos::DEFAULT_10
        );
        for bad in [
            "",
            "::,10:,:,:",
            "::10:,:,:,,",
            "3::,10:,:,:,,",
            "::,x:,:,:,,",
        ] {
            assert!(Qos::from_keyexpr(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn tokens_match_the_documented_examples_and_parse_back() {
        let node = "@ros2_lv/0/aabbcc/0/0/NN/%/%/seg_mesher";
        let t = Token::parse(node).unwrap();
        assert_eq!(t.kind, EntityKind::Node);
        assert_eq!(t.namespace, "/");
        assert_eq!(t.node, "seg_mesher");
        assert_eq!(t.key(), node);

        let sub = "@ros2_lv/0/aabbcc/0/1/MS/%/%/seg_mesher/%robot1%seg%points/sensor_msgs::msg::dds_::PointCloud2_/RIHS01_9198cabf7da3796ae6fe19c4cb3bdd3525492988c70522628af5daa124bae2b5/2::,5:,:,:,,";
        let t = Token::parse(sub).unwrap();
        assert_eq!(t.kind, EntityKind::Subscription);
        let tt = t.topic.clone().unwrap();
        assert_eq!(tt.topic, "/robot1/seg/points");
        assert_eq!(tt.dds_type, "sensor_msgs::msg::dds_::PointCloud2_");
        assert_eq!(tt.qos, Qos::SENSOR_DATA);
        assert_eq!(t.key(), sub);

        let ns = Token {
            domain: 3,
            zid: "1f".into(),
            node_id: 2,
            entity_id: 9,
            kind: EntityKind::Publisher,
            enclave: "/".into(),
            namespace: "/robot1".into(),
            node: "sepmem".into(),
            topic: Some(TopicToken {
                topic: "/diagnostics".into(),
                dds_type: "diagnostic_msgs::msg::dds_::DiagnosticArray_".into(),
                hash: "RIHS01_x".into(),
                qos: Qos::DEFAULT_10,
            }),
        };
        assert_eq!(
            ns.key(),
            "@ros2_lv/3/1f/2/9/MP/%/%robot1/sepmem/%diagnostics/diagnostic_msgs::msg::dds_::DiagnosticArray_/RIHS01_x/::,10:,:,:,,"
        );
        assert_eq!(Token::parse(&ns.key()).unwrap(), ns);
    }

    #[test]
    fn malformed_tokens_are_rejected() {
        for bad in [
            "@ros2_lv/0/z/0/0/NN/%/%",
            "@other/0/z/0/0/NN/%/%/n",
            "@ros2_lv/x/z/0/0/NN/%/%/n",
            "@ros2_lv/0/z/0/0/XX/%/%/n",
            "@ros2_lv/0/z/0/0/NN//%/n",
            "@ros2_lv/0/z/0/1/MP/%/%/n",
            "@ros2_lv/0/z/0/1/MP/%/%/n/%t/T/h/bad",
        ] {
            assert!(Token::parse(bad).is_err(), "{bad}");
        }
    }
}
