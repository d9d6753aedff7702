//! A ROS 2-compatible participant on one zenoh session.
//!
//! [`Participant::open`] builds the zenoh configuration (peer mode, multicast
//! scouting off, optional connect/listen endpoints, an optional zenoh config
//! file passed through), opens the session and, in `ros2` key mode, declares
//! the node's liveliness token. Publishers created by
//! [`Participant::publisher`] put every sample with rmw_zenoh's 33-byte
//! attachment (sequence number, source timestamp, GID = XXH3-128 of the
//! publisher's liveliness key) and declare an `MP` token; subscriptions
//! created by [`Participant::subscribe`] deliver [`Received`] samples with
//! their topic and decoded attachment to a callback.
//!
//! A TRANSIENT_LOCAL publisher is a zenoh-ext `AdvancedPublisher` with a
//! cache of `depth` samples, publisher detection and (when RELIABLE)
//! sample-miss heartbeats, as in rmw_zenoh's `rmw_publisher_data.cpp`: an
//! rmw_zenoh TRANSIENT_LOCAL subscription (an `AdvancedSubscriber` that
//! detects late publishers) then queries that cache when it joins.

use super::attachment::{gid_of_liveliness_key, now_ns, Attachment, AttachmentError};
use super::keys::{KeyError, KeyMapper, KeyMode, RosType};
use super::liveliness::{Durability, EntityKind, Qos, Reliability, Token, TopicToken};
use super::{TransportConfig, TransportError};
use std::num::NonZeroUsize;
use std::sync::atomic::{AtomicI64, AtomicU64, Ordering};
use std::sync::Arc;
use zenoh::bytes::ZBytes;
use zenoh::Wait;
use zenoh_ext::AdvancedPublisherBuilderExt;

/// Heartbeat period of RELIABLE + TRANSIENT_LOCAL publishers (sample-miss detection).
const HEARTBEAT: std::time::Duration = std::time::Duration::from_millis(500);
/// Cache of a TRANSIENT_LOCAL + KEEP_ALL publisher (bounded all the same).
const KEEP_ALL_CACHE: usize = 100;

fn zerr(what: impl Into<String>) -> impl FnOnce(zenoh::Error) -> TransportError {
    let what = what.into();
    move |e| TransportError::Zenoh {
        what,
        message: e.to_string(),
    }
}

/// The zenoh priority lane a publisher's samples travel in. Each lane has
/// its own transmission queue, so a small sample in [`Lane::Urgent`] is not
/// dropped behind the fragments of a large one in [`Lane::Data`] (with "drop"
/// congestion control, a sample the queue cannot take within ~1 ms is lost).
/// Subscribers receive every lane alike, so the choice is invisible on the
/// ROS 2 graph.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Lane {
    /// zenoh's `Data` priority, which rmw_zenoh gives every publisher.
    #[default]
    Data,
    /// zenoh's `DataHigh`: for small messages a consumer must not miss.
    /// Measured: the conformance client under two busy cores lost a
    /// `/collision_object` sample, with a 577 KB marker array, in 4 of 8 runs
    /// while both went through the `Data` lane.
    Urgent,
}

impl Lane {
    fn priority(self) -> zenoh::qos::Priority {
        match self {
            Lane::Data => zenoh::qos::Priority::Data,
            Lane::Urgent => zenoh::qos::Priority::DataHigh,
        }
    }
}

/// How a publisher sends, beyond its ROS QoS.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Outlet {
    /// The zenoh priority lane.
    pub lane: Lane,
    /// Samples a TRANSIENT_LOCAL publisher's cache keeps for late joiners.
    /// `None`: the QoS's KEEP_LAST depth, or 100 for KEEP_ALL. A node's
    /// KEEP_ALL output (it blocks rather than drops) keeps a configured
    /// depth, so its memory stays bounded.
    pub cache: Option<NonZeroUsize>,
}

/// Build the zenoh configuration described by `cfg`.
///
/// # Errors
/// [`TransportError::Zenoh`] when the file cannot be read or a value is rejected.
pub fn zenoh_config(cfg: &TransportConfig) -> Result<zenoh::Config, TransportError> {
    let z = &cfg.zenoh;
    let mut c = if z.config_file.is_empty() {
        zenoh::Config::default()
    } else {
        zenoh::Config::from_file(&z.config_file)
            .map_err(zerr(format!("reading zenoh config file {}", z.config_file)))?
    };
    let set = |c: &mut zenoh::Config, key: &str, value: String| {
        c.insert_json5(key, &value)
            .map_err(zerr(format!("setting zenoh {key}={value}")))
    };
    if !z.mode.is_empty() {
        set(&mut c, "mode", format!("\"{}\"", z.mode))?;
    }
    let list = |v: &[String]| {
        let quoted: Vec<String> = v.iter().map(|s| format!("\"{s}\"")).collect();
        format!("[{}]", quoted.join(","))
    };
    if !z.connect.is_empty() {
        set(&mut c, "connect/endpoints", list(&z.connect))?;
    }
    if !z.listen.is_empty() {
        set(&mut c, "listen/endpoints", list(&z.listen))?;
    }
    set(
        &mut c,
        "scouting/multicast/enabled",
        z.multicast_scouting.to_string(),
    )?;
    if let Some(n) = z.max_message_bytes {
        set(&mut c, "transport/link/rx/max_message_size", n.to_string())?;
    }
    // As rmw_zenoh's session config: samples carry timestamps, which the
    // advanced publisher cache (TRANSIENT_LOCAL) and subscribers rely on.
    set(&mut c, "timestamping/enabled", "true".to_string())?;
    Ok(c)
}

/// A TCP port on 127.0.0.1 that was free a moment ago (bind to port 0,
/// read the port, release it), for loopback sessions in tests and the demo.
///
/// # Errors
/// The I/O error if no socket can be bound.
pub fn free_loopback_port() -> std::io::Result<u16> {
    let l = std::net::TcpListener::bind("127.0.0.1:0")?;
    Ok(l.local_addr()?.port())
}

/// One received sample.
#[derive(Debug, Clone)]
pub struct Received {
    /// The zenoh key it was put on.
    pub key: String,
    /// The ROS topic of that key (or why it is not one).
    pub topic: Result<String, KeyError>,
    /// The payload (CDR with its 4-byte encapsulation header for ROS types).
    pub payload: Vec<u8>,
    /// The rmw_zenoh attachment, if the sample had one.
    pub attachment: Option<Result<Attachment, AttachmentError>>,
    /// Local receive time, ns since the Unix epoch.
    pub received_ns: i64,
}

/// A zenoh session acting as one ROS 2 node.
pub struct Participant {
    session: zenoh::Session,
    mapper: KeyMapper,
    cfg: TransportConfig,
    zid: String,
    node_id: u64,
    next_entity: AtomicU64,
    node_token: std::sync::Mutex<Option<zenoh::liveliness::LivelinessToken>>,
    node_token_key: Option<String>,
}

/// A liveliness token held for an entity (undeclared on drop or [`EntityToken::undeclare`]).
pub struct EntityToken {
    token: Option<zenoh::liveliness::LivelinessToken>,
    key: String,
}

impl EntityToken {
    /// The token's key expression (empty when no token was declared).
    pub fn key(&self) -> &str {
        &self.key
    }

    /// Withdraw the token.
    ///
    /// # Errors
    /// [`TransportError::Zenoh`] if zenoh refuses.
    pub async fn undeclare(mut self) -> Result<(), TransportError> {
        if let Some(t) = self.token.take() {
            t.undeclare().await.map_err(zerr("undeclaring token"))?;
        }
        Ok(())
    }
}

impl Participant {
    /// Open the zenoh session and (in ros2 mode) declare the node token.
    ///
    /// # Errors
    /// [`TransportError`] if the configuration is invalid or zenoh fails.
    pub async fn open(cfg: &TransportConfig) -> Result<Self, TransportError> {
        let zc = zenoh_config(cfg)?;
        let session = zenoh::open(zc)
            .await
            .map_err(zerr("opening zenoh session"))?;
        let zid = session.zid().to_string();
        let domain = cfg.effective_domain()?;
        let mapper = KeyMapper::new(cfg.key_mode, domain, &cfg.prefix);
        let mut p = Self {
            session,
            mapper,
            cfg: cfg.clone(),
            zid,
            node_id: 0,
            next_entity: AtomicU64::new(1),
            node_token: std::sync::Mutex::new(None),
            node_token_key: None,
        };
        if p.ros2() {
            let key = p.token(0, EntityKind::Node, None).key();
            let tok = p
                .session
                .liveliness()
                .declare_token(key.clone())
                .await
                .map_err(zerr(format!("declaring node token {key}")))?;
            p.node_token = std::sync::Mutex::new(Some(tok));
            p.node_token_key = Some(key);
        }
        Ok(p)
    }

    fn ros2(&self) -> bool {
        self.mapper.mode == KeyMode::Ros2
    }

    fn token(&self, entity_id: u64, kind: EntityKind, topic: Option<TopicToken>) -> Token {
        Token {
            domain: self.mapper.domain,
            zid: self.zid.clone(),
            node_id: self.node_id,
            entity_id,
            kind,
            enclave: self.cfg.enclave.clone(),
            namespace: self.cfg.namespace.clone(),
            node: self.cfg.node_name.clone(),
            topic,
        }
    }

    /// The underlying zenoh session.
    pub fn session(&self) -> &zenoh::Session {
        &self.session
    }

    /// The key mapper (mode, domain, prefix).
    pub fn mapper(&self) -> &KeyMapper {
        &self.mapper
    }

    /// This session's zenoh id.
    pub fn zid(&self) -> &str {
        &self.zid
    }

    /// The node token's key (ros2 mode), for diagnostics and tests.
    pub fn node_token_key(&self) -> Option<String> {
        self.node_token_key.clone()
    }

    /// Declare an `MP`/`MS` liveliness token for `topic` (no-op outside ros2 mode).
    ///
    /// # Errors
    /// [`TransportError`] for a bad topic/type or a zenoh failure.
    pub async fn declare_entity(
        &self,
        kind: EntityKind,
        topic: &str,
        ty: &RosType,
        qos: Qos,
    ) -> Result<EntityToken, TransportError> {
        if !self.ros2() {
            return Ok(EntityToken {
                token: None,
                key: String::new(),
            });
        }
        let id = self.next_entity.fetch_add(1, Ordering::Relaxed);
        let tt = TopicToken {
            topic: format!("/{}", super::keys::strip_topic(topic)?),
            dds_type: ty.dds_name()?,
            hash: ty.hash.clone(),
            qos,
        };
        let key = self.token(id, kind, Some(tt)).key();
        let token = self
            .session
            .liveliness()
            .declare_token(key.clone())
            .await
            .map_err(zerr(format!("declaring token {key}")))?;
        Ok(EntityToken {
            token: Some(token),
            key,
        })
    }

    /// Declare a publisher of `topic` with type `ty` (and its `MP` token in
    /// ros2 mode), in the [`Lane::Data`] lane as rmw_zenoh does.
    ///
    /// # Errors
    /// [`TransportError`] for a bad topic/type or a zenoh failure.
    pub async fn publisher(
        &self,
        topic: &str,
        ty: &RosType,
        qos: Qos,
    ) -> Result<RosPublisher, TransportError> {
        self.publisher_in(topic, ty, qos, Outlet::default()).await
    }

    /// [`Participant::publisher`] with a chosen priority lane and cache
    /// depth (`outlet`).
    ///
    /// # Errors
    /// [`TransportError`] for a bad topic/type or a zenoh failure.
    pub async fn publisher_in(
        &self,
        topic: &str,
        ty: &RosType,
        qos: Qos,
        outlet: Outlet,
    ) -> Result<RosPublisher, TransportError> {
        let key = self.mapper.publish_key(topic, ty)?;
        let token = self
            .declare_entity(EntityKind::Publisher, topic, ty, qos)
            .await?;
        let gid = gid_of_liveliness_key(token.key());
        // rmw_zenoh's mapping: RELIABLE + KEEP_ALL blocks under congestion,
        // everything else drops (see `rmw_publisher_data.cpp`).
        let congestion = if qos.reliability == Reliability::Reliable && qos.keep_last.is_none() {
            zenoh::qos::CongestionControl::Block
        } else {
            zenoh::qos::CongestionControl::Drop
        };
        let builder = self
            .session
            .declare_publisher(key.clone())
            .congestion_control(congestion)
            .priority(outlet.lane.priority());
        let publisher = if qos.durability == Durability::TransientLocal {
            let depth = outlet.cache.map_or_else(
                || {
                    qos.keep_last.map_or(KEEP_ALL_CACHE, |d| {
                        usize::try_from(d).unwrap_or(KEEP_ALL_CACHE)
                    })
                },
                NonZeroUsize::get,
            );
            let mut b = builder
                .cache(zenoh_ext::CacheConfig::default().max_samples(depth))
                .publisher_detection();
            if qos.reliability == Reliability::Reliable {
                b = b.sample_miss_detection(
                    zenoh_ext::MissDetectionConfig::default().heartbeat(HEARTBEAT),
                );
            }
            Sink::Advanced(
                b.await
                    .map_err(zerr(format!("declaring advanced publisher {key}")))?,
            )
        } else {
            Sink::Plain(
                builder
                    .await
                    .map_err(zerr(format!("declaring publisher {key}")))?,
            )
        };
        Ok(RosPublisher {
            publisher,
            token,
            gid,
            seq: AtomicI64::new(0),
            key,
            topic: topic.to_string(),
            attach: self.ros2(),
        })
    }

    /// Subscribe to a topic pattern of type `ty`; `callback` runs on zenoh's
    /// threads for every sample and must return quickly.
    ///
    /// # Errors
    /// [`TransportError`] for a bad pattern/type or a zenoh failure.
    pub async fn subscribe<F>(
        &self,
        pattern: &str,
        ty: &RosType,
        callback: F,
    ) -> Result<zenoh::pubsub::Subscriber<()>, TransportError>
    where
        F: Fn(Received) + Send + Sync + 'static,
    {
        let key = self.mapper.subscribe_key(pattern, ty)?;
        let mapper = Arc::new(self.mapper.clone());
        let sub = self
            .session
            .declare_subscriber(key.clone())
            .callback(move |sample: zenoh::sample::Sample| {
                let key = sample.key_expr().as_str().to_string();
                let received = Received {
                    topic: mapper.topic_of(&key),
                    key,
                    payload: sample.payload().to_bytes().into_owned(),
                    attachment: sample
                        .attachment()
                        .map(|a| Attachment::decode(&a.to_bytes())),
                    received_ns: now_ns(),
                };
                callback(received);
            })
            .await
            .map_err(zerr(format!("declaring subscriber {key}")))?;
        Ok(sub)
    }

    /// Withdraw the node token and close the session.
    ///
    /// # Errors
    /// [`TransportError::Zenoh`] if zenoh fails to close.
    pub async fn close(&self) -> Result<(), TransportError> {
        let token = match self.node_token.lock() {
            Ok(mut g) => g.take(),
            Err(p) => p.into_inner().take(),
        };
        if let Some(t) = token {
            t.undeclare()
                .await
                .map_err(zerr("undeclaring node token"))?;
        }
        self.session
            .close()
            .await
            .map_err(zerr("closing zenoh session"))
    }
}

/// A plain zenoh publisher (VOLATILE) or an advanced one with a cache (TRANSIENT_LOCAL).
enum Sink {
    Plain(zenoh::pubsub::Publisher<'static>),
    Advanced(zenoh_ext::AdvancedPublisher<'static>),
}

/// A publisher that stamps rmw_zenoh attachments (in ros2 mode).
pub struct RosPublisher {
    publisher: Sink,
    token: EntityToken,
    gid: [u8; 16],
    seq: AtomicI64,
    key: String,
    topic: String,
    attach: bool,
}

impl RosPublisher {
    /// The key samples are put on.
    pub fn key(&self) -> &str {
        &self.key
    }

    /// The ROS topic.
    pub fn topic(&self) -> &str {
        &self.topic
    }

    /// The publisher's GID (XXH3-128 of its liveliness key).
    pub fn gid(&self) -> [u8; 16] {
        self.gid
    }

    /// The `MP` token key (empty outside ros2 mode).
    pub fn token_key(&self) -> &str {
        self.token.key()
    }

    fn next_attachment(&self) -> Option<Vec<u8>> {
        self.attach.then(|| {
            Attachment {
                sequence: self.seq.fetch_add(1, Ordering::Relaxed) + 1,
                timestamp_ns: now_ns(),
                gid: self.gid,
            }
            .encode()
            .to_vec()
        })
    }

    /// Put one serialized message (a `Vec<u8>`, or a `ZBytes` that shares
    /// its buffer: a repeated payload is then not copied per put).
    ///
    /// # Errors
    /// [`TransportError::Zenoh`] if zenoh refuses the put.
    pub async fn put(&self, payload: impl Into<ZBytes>) -> Result<(), TransportError> {
        let attachment = self.next_attachment();
        match &self.publisher {
            Sink::Plain(p) => p.put(payload).attachment(attachment).await,
            Sink::Advanced(p) => p.put(payload).attachment(attachment).await,
        }
        .map_err(zerr(format!("put on {}", self.key)))
    }

    /// Put one serialized message without awaiting (zenoh puts do not block
    /// on the network; used from synchronous code).
    ///
    /// # Errors
    /// [`TransportError::Zenoh`] if zenoh refuses the put.
    pub fn put_sync(&self, payload: impl Into<ZBytes>) -> Result<(), TransportError> {
        let attachment = self.next_attachment();
        match &self.publisher {
            Sink::Plain(p) => p.put(payload).attachment(attachment).wait(),
            Sink::Advanced(p) => p.put(payload).attachment(attachment).wait(),
        }
        .map_err(zerr(format!("put on {}", self.key)))
    }

    /// Undeclare the publisher and its token.
    ///
    /// # Errors
    /// [`TransportError::Zenoh`] if zenoh fails.
    pub async fn undeclare(self) -> Result<(), TransportError> {
        self.token.undeclare().await?;
        match self.publisher {
            Sink::Plain(p) => p.undeclare().await,
            Sink::Advanced(p) => p.undeclare().await,
        }
        .map_err(zerr("undeclaring publisher"))
    }
}
