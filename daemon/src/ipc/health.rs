//! [`Latency`]: the daemon's batch latency over the last minute, for its
//! status.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

/// How far back the percentiles look.
const WINDOW: Duration = Duration::from_secs(60);

/// How often the percentiles are recomputed.
const REFRESH: Duration = Duration::from_secs(1);

/// Batch latencies of the last minute, and their median and 99th
/// percentile as last computed.
#[derive(Debug, Default)]
pub struct Latency {
    samples: VecDeque<(Instant, f64)>,
    computed: Option<Instant>,
    p50_us: f64,
    p99_us: f64,
}

impl Latency {
    /// Records one batch's latency.
    pub fn push(&mut self, latency: Duration) {
        let now = Instant::now();
        self.samples.push_back((now, latency.as_secs_f64() * 1e6));
        while self
            .samples
            .front()
            .is_some_and(|(t, _)| now.duration_since(*t) > WINDOW)
        {
            self.samples.pop_front();
        }
    }

    /// The median and 99th percentile (µs) over the last minute,
    /// recomputed at most once a second (and whenever the last computation
    /// had no samples); zeros without samples.
    pub fn percentiles(&mut self) -> (f64, f64) {
        let stale = self.computed.is_none_or(|t| t.elapsed() >= REFRESH);
        if stale || (self.p99_us == 0.0 && !self.samples.is_empty()) {
            let mut v: Vec<f64> = self.samples.iter().map(|s| s.1).collect();
            v.sort_by(f64::total_cmp);
            let at = |q: f64| v.get(((v.len() as f64 - 1.0) * q).round() as usize).copied();
            self.p50_us = at(0.5).unwrap_or(0.0);
            self.p99_us = at(0.99).unwrap_or(0.0);
            self.computed = Some(Instant::now());
        }
        (self.p50_us, self.p99_us)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_of_the_window() {
        let mut l = Latency::default();
        assert_eq!(l.percentiles(), (0.0, 0.0));
        for us in 1..=100 {
            l.push(Duration::from_micros(us));
        }
        let (p50, p99) = l.percentiles();
        assert!(
            (p50 - 51.0).abs() < 1e-9 && (p99 - 99.0).abs() < 1e-9,
            "{p50} {p99}"
        );
    }
}
