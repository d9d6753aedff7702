//! Per-stream statistics for the `/diagnostics` report: frame and drop
//! counts, warm/cold counts, the last η_g and iteration count, and latency
//! percentiles over a bounded window of recent frames.

/// Number of recent latencies kept per stream for the percentiles.
pub const LATENCY_WINDOW: usize = 512;

/// Diagnostic level (diagnostic_msgs/DiagnosticStatus values).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Level {
    /// OK = 0.
    Ok = 0,
    /// WARN = 1.
    Warn = 1,
    /// ERROR = 2.
    Error = 2,
    /// STALE = 3.
    Stale = 3,
}

impl Level {
    /// The wire byte.
    pub fn byte(self) -> u8 {
        self as u8
    }
}

/// A bounded ring of latencies (seconds) with percentiles.
#[derive(Debug, Clone, Default)]
pub struct LatencyWindow {
    values: Vec<f64>,
    next: usize,
}

impl LatencyWindow {
    /// Record one latency in seconds.
    pub fn push(&mut self, seconds: f64) {
        if self.values.len() < LATENCY_WINDOW {
            self.values.push(seconds);
        } else {
            self.values[self.next] = seconds;
        }
        self.next = (self.next + 1) % LATENCY_WINDOW;
    }

    /// Number of values held.
    pub fn len(&self) -> usize {
        self.values.len()
    }

    /// Whether no value was recorded.
    pub fn is_empty(&self) -> bool {
        self.values.is_empty()
    }

    /// The `q`-quantile (nearest rank, `q` in `[0, 1]`); `None` when empty.
    pub fn quantile(&self, q: f64) -> Option<f64> {
        quantile(&self.values, q)
    }
}

/// Nearest-rank quantile of unsorted values; `None` when empty.
pub fn quantile(values: &[f64], q: f64) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let rank = (q.clamp(0.0, 1.0) * v.len() as f64).ceil() as usize;
    Some(v[rank.saturating_sub(1).min(v.len() - 1)])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_are_nearest_rank() {
        let v: Vec<f64> = (1..=100).map(f64::from).collect();
        assert_eq!(quantile(&v, 0.5), Some(50.0));
        assert_eq!(quantile(&v, 0.95), Some(95.0));
        assert_eq!(quantile(&v, 1.0), Some(100.0));
        assert_eq!(quantile(&[], 0.5), None);
        let mut w = LatencyWindow::default();
        for i in 0..(LATENCY_WINDOW + 10) {
            w.push(i as f64);
        }
        assert_eq!(w.len(), LATENCY_WINDOW);
        // The 10 oldest values were overwritten.
        assert_eq!(w.quantile(0.0), Some(10.0));
    }
}
