//! Room kept before a deadline for the work that follows the step it
//! stops: `pipeline.deadline_ms` is the frame's deadline, not only its
//! membrane's.
//!
//! The membrane stops before an iteration that would end past its
//! deadline, but a frame goes on after its membrane: the seen side's snap
//! (`pipeline.snap`), the next frame's alignment model, the start of the
//! background rebuild, and in the node the outputs' encoding. Measured with
//! `sepmem bench-node --streams 1 --rate 10 --duration 15` on an idle
//! machine, before this reserve: a healthy stream's every frame finished
//! after its 15 ms deadline (151 of 151 at 6 k points and at 20 k), so
//! `/diagnostics` reported it WARN (late) all the time. Each of those
//! steps measures what followed it on the last frames ([`Reserve`]) and
//! stops that much earlier.

use std::time::{Duration, Instant};

/// How far [`Reserve`] moves towards a lower measurement at each.
const WEIGHT: f64 = 0.25;

/// The time kept before a deadline for what follows: the larger of the last
/// measurement and the reserve moved a quarter of the way towards it, so it
/// rises at once with a slower frame and falls back over a few frames.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Reserve(Duration);

impl Reserve {
    /// The time to keep.
    pub fn get(self) -> Duration {
        self.0
    }

    /// `deadline` less the time to keep (`deadline` itself where the clock
    /// cannot go that far back).
    pub fn before(self, deadline: Instant) -> Instant {
        deadline.checked_sub(self.0).unwrap_or(deadline)
    }

    /// Record that the work that followed the deadline's step took `took`.
    pub fn record(&mut self, took: Duration) {
        let mean = self.0.mul_f64(1.0 - WEIGHT) + took.mul_f64(WEIGHT);
        self.0 = took.max(mean);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_reserve_rises_at_once_and_falls_back_over_a_few_frames() {
        let ms = Duration::from_millis;
        let mut r = Reserve::default();
        assert_eq!(r.get(), Duration::ZERO);
        r.record(ms(2));
        assert_eq!(r.get(), ms(2));
        // A slow frame is kept in full.
        r.record(ms(10));
        assert_eq!(r.get(), ms(10));
        // Then the mean: 10 -> 8 -> 6.5 -> ... towards 2.
        r.record(ms(2));
        assert_eq!(r.get(), ms(8));
        for _ in 0..20 {
            r.record(ms(2));
        }
        assert!(r.get() < Duration::from_micros(2100), "{:?}", r.get());
        assert!(r.get() >= ms(2));
    }
}
