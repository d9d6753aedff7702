//! The node's own clock. Silence (stream eviction, `pipeline.objects`
//! forgetting), stalls and receipt-to-publish latencies are measured on a
//! monotonic clock, so that a step of the wall clock (a robot whose chrony
//! corrects its boot time by hours, a suspended VM resumed) neither evicts
//! every stream and forgets every label at once nor keeps a silent one
//! forever (`tests/node_loopback.rs`, a stepped clock). Wall time serves only
//! what is compared across processes: the publishers' source stamps and the
//! stamps the node writes.

use std::sync::OnceLock;
use std::time::Instant;

/// Nanoseconds on the node's monotonic clock, always above 0 (so that 0
/// can stand for "never"). Its origin is just before the first reading in
/// this process: values are only compared with each other.
pub fn mono_ns() -> i64 {
    static ORIGIN: OnceLock<Instant> = OnceLock::new();
    let origin = *ORIGIN.get_or_init(Instant::now);
    i64::try_from(origin.elapsed().as_nanos())
        .unwrap_or(i64::MAX)
        .saturating_add(1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn never_goes_back() {
        let mut last = mono_ns();
        for _ in 0..10_000 {
            let now = mono_ns();
            assert!(now >= last);
            last = now;
        }
    }
}
