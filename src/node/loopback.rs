//! A node and an observer on zenoh over loopback, in one process: what
//! `sepmem demo`, `sepmem bench-node` and the end-to-end tests run.
//!
//! The observer ("harness") is a participant listening on an ephemeral
//! `tcp/127.0.0.1` port; the node runs as a tokio task whose session
//! connects to it (peer mode, no scouting, no router). The harness publishes
//! inputs the rmw_zenoh way and subscribes to the node's outputs.

use super::runtime::{run, NodeSummary};
use super::{Backend, NodeConfig, NodeError};
use crate::transport::{
    free_loopback_port, Participant, Received, RosType, TransportConfig, TransportError,
};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::sync::oneshot;
use tokio::task::JoinHandle;

/// Samples received by an observer subscription.
pub type Inbox = Arc<Mutex<Vec<Received>>>;

/// Lock an inbox (a poisoned lock still yields the samples).
pub fn inbox_lock(inbox: &Inbox) -> std::sync::MutexGuard<'_, Vec<Received>> {
    match inbox.lock() {
        Ok(g) => g,
        Err(p) => p.into_inner(),
    }
}

/// A running node with an observer participant connected to it.
pub struct LoopbackNode {
    /// The observer: publish inputs and subscribe to outputs with it.
    pub harness: Participant,
    node: JoinHandle<Result<NodeSummary, NodeError>>,
    stop: oneshot::Sender<()>,
    /// `/diagnostics` arrays seen: a count, not the arrays (the observer of
    /// a 30-minute soak kept every array, 18 KB a second, and its RSS grew
    /// by 1.1 MiB a minute; [`LoopbackNode::collect_diagnostics`] keeps
    /// them for a caller that wants them).
    ready: Arc<AtomicU64>,
    diagnostics: (String, RosType),
    _ready_sub: zenoh::pubsub::Subscriber<()>,
}

impl LoopbackNode {
    /// Start `backend` with `cfg` (its transport is replaced by a loopback
    /// one named after `cfg.transport.node_name`) and an observer.
    ///
    /// # Errors
    /// [`NodeError`] when no port is free or the observer cannot start.
    pub async fn start(cfg: &NodeConfig, backend: Arc<dyn Backend>) -> Result<Self, NodeError> {
        let port = free_loopback_port().map_err(|e| {
            NodeError::Transport(TransportError::Zenoh {
                what: "finding a free loopback port".into(),
                message: e.to_string(),
            })
        })?;
        let name = cfg.transport.node_name.clone();
        let harness = Participant::open(&TransportConfig::loopback(
            &format!("{name}_observer"),
            Some(port),
            &[],
        ))
        .await?;
        let ready: Arc<AtomicU64> = Arc::default();
        let r = ready.clone();
        let diagnostics = (cfg.outputs.diagnostics.clone(), backend.diagnostics_type());
        let ready_sub = harness
            .subscribe(&diagnostics.0, &diagnostics.1, move |_| {
                r.fetch_add(1, Ordering::Relaxed);
            })
            .await?;
        let mut cfg = cfg.clone();
        let mut tr = TransportConfig::loopback(&name, None, &[port]);
        tr.key_mode = cfg.transport.key_mode;
        tr.prefix = cfg.transport.prefix.clone();
        cfg.transport = tr;
        let (stop, stop_rx) = oneshot::channel::<()>();
        let node = tokio::spawn(async move {
            run(&cfg, backend, async {
                let _ = stop_rx.await;
            })
            .await
        });
        Ok(Self {
            harness,
            node,
            stop,
            ready,
            diagnostics,
            _ready_sub: ready_sub,
        })
    }

    /// Wait until the node's `/diagnostics` reaches the observer (its
    /// subscribers were declared before), plus a short settling delay.
    /// Returns false after `timeout`.
    pub async fn wait_ready(&self, timeout: Duration) -> bool {
        let t0 = tokio::time::Instant::now();
        while self.ready.load(Ordering::Relaxed) == 0 {
            if t0.elapsed() > timeout || self.node.is_finished() {
                return false;
            }
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        tokio::time::sleep(Duration::from_millis(200)).await;
        true
    }

    /// Keep every `/diagnostics` array from now on in an inbox (for a
    /// bounded run: the inbox grows until the caller drains it).
    ///
    /// # Errors
    /// [`TransportError`] when the subscription cannot be declared.
    pub async fn collect_diagnostics(
        &self,
    ) -> Result<(zenoh::pubsub::Subscriber<()>, Inbox), TransportError> {
        self.collect(&self.diagnostics.0, &self.diagnostics.1).await
    }

    /// Subscribe the observer to `pattern` with type `ty` (hash wildcarded).
    ///
    /// # Errors
    /// [`TransportError`] for a bad pattern or a zenoh failure.
    pub async fn collect(
        &self,
        pattern: &str,
        ty: &RosType,
    ) -> Result<(zenoh::pubsub::Subscriber<()>, Inbox), TransportError> {
        let inbox: Inbox = Arc::default();
        let i = inbox.clone();
        let sub = self
            .harness
            .subscribe(pattern, ty, move |r| inbox_lock(&i).push(r))
            .await?;
        Ok((sub, inbox))
    }

    /// Stop the node (graceful shutdown), then close the observer.
    ///
    /// # Errors
    /// The node's error, or [`NodeError::Config`] if its task panicked.
    pub async fn stop(self) -> Result<NodeSummary, NodeError> {
        let _ = self.stop.send(());
        let summary = self
            .node
            .await
            .map_err(|e| NodeError::Config(format!("node task failed: {e}")))??;
        // Let the final outputs and token withdrawals reach the observer.
        tokio::time::sleep(Duration::from_millis(100)).await;
        drop(self._ready_sub);
        self.harness.close().await?;
        Ok(summary)
    }
}
