//! Sharing the compute pool between streams, and telling a stalled stream.
//!
//! All streams share one rayon pool. When the node was attacked (issue 22),
//! one labelled cloud (400 labels at 1 Hz) or one poisoned message held the
//! pool's threads for seconds at a time and every healthy stream starved.
//! Two guards, both per stream:
//!
//! * [`ShareMeter`], a token bucket over the wall time a stream's frames
//!   spend in compute (`node.compute_share`): a stream earns `cores`
//!   seconds of compute per second, up to `burst_ms`; a frame's time is
//!   charged when it finishes. A stream in debt gets no compute until it has
//!   earned it back: its newest frame waits in its keep-latest slot, the
//!   frames that waited or were replaced meanwhile are counted as
//!   `over_budget`, and `/diagnostics` reports it WARN. So a
//!   stream whose frames cost more than its share is slowed to its share,
//!   whatever its input, and the others keep theirs.
//! * The stall bound (`node.stall_after_ms`): a frame that has been in
//!   compute for longer than the stream's cold-start budget plus this bound
//!   is reported ERROR ("stalled") while it lasts. Compute cannot be
//!   preempted; the membrane stops at its deadline and decoding is linear
//!   in the message size, so this only fires on a defect, which it names.

use serde::{Deserialize, Serialize};
use std::time::{Duration, Instant};

/// `node.compute_share`: how much of the compute pool one stream may use.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ComputeShareConfig {
    /// Compute seconds a stream earns per second (wall time of its frames
    /// in compute; 0.5 = half of one thread).
    pub cores: f64,
    /// Most compute time a stream can save up (ms): a burst of this much
    /// runs at once, e.g. a cold start after quiet warm frames.
    pub burst_ms: f64,
}

impl ComputeShareConfig {
    /// Check the values.
    ///
    /// # Errors
    /// The name of the key at fault.
    pub fn validate(&self) -> Result<(), String> {
        if !positive(self.cores) {
            return Err(format!(
                "node.compute_share.cores must be > 0, got {}",
                self.cores
            ));
        }
        if !positive(self.burst_ms) {
            return Err(format!(
                "node.compute_share.burst_ms must be > 0, got {}",
                self.burst_ms
            ));
        }
        Ok(())
    }
}

fn positive(x: f64) -> bool {
    x.is_finite() && x > 0.0
}

/// A token bucket of compute time for one stream.
#[derive(Debug, Clone)]
pub struct ShareMeter {
    cores: f64,
    burst_s: f64,
    credit_s: f64,
    last: Instant,
}

impl ShareMeter {
    /// A full bucket at `now`.
    pub fn new(cfg: &ComputeShareConfig, now: Instant) -> Self {
        let burst_s = cfg.burst_ms / 1e3;
        Self {
            cores: cfg.cores,
            burst_s,
            credit_s: burst_s,
            last: now,
        }
    }

    fn refill(&mut self, now: Instant) {
        let dt = now.saturating_duration_since(self.last).as_secs_f64();
        self.credit_s = (self.credit_s + dt * self.cores).min(self.burst_s);
        self.last = now;
    }

    /// Charge `busy` of compute, finished at `now`.
    pub fn charge(&mut self, busy: Duration, now: Instant) {
        self.refill(now);
        self.credit_s -= busy.as_secs_f64();
    }

    /// How long the stream must wait at `now` before it may compute again
    /// (`None`: it may now).
    pub fn debt(&mut self, now: Instant) -> Option<Duration> {
        self.refill(now);
        (self.credit_s < 0.0).then(|| Duration::from_secs_f64(-self.credit_s / self.cores))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_stream_over_its_share_waits_until_it_earned_it_back() {
        let cfg = ComputeShareConfig {
            cores: 0.5,
            burst_ms: 100.0,
        };
        assert!(cfg.validate().is_ok());
        let t0 = Instant::now();
        let mut m = ShareMeter::new(&cfg, t0);
        assert_eq!(m.debt(t0), None);
        // 300 ms of compute with 100 ms saved: 200 ms in debt, earned back
        // at 0.5 s/s in 400 ms (the 300 ms it ran earned nothing: the
        // bucket was full).
        let t1 = t0 + Duration::from_millis(300);
        m.charge(Duration::from_millis(300), t1);
        let d = m.debt(t1).unwrap();
        assert!((d.as_secs_f64() - 0.4).abs() < 1e-9, "{d:?}");
        assert!(m.debt(t1 + Duration::from_millis(390)).is_some());
        assert!(m.debt(t1 + Duration::from_millis(410)).is_none());
        // Saving is capped at the burst.
        let mut m = ShareMeter::new(&cfg, t0);
        m.charge(Duration::from_millis(150), t0 + Duration::from_secs(100));
        assert!(m.debt(t0 + Duration::from_secs(100)).is_some());
        let bad = ComputeShareConfig {
            cores: 0.0,
            burst_ms: 1.0,
        };
        assert!(bad
            .validate()
            .unwrap_err()
            .contains("node.compute_share.cores"));
    }
}
