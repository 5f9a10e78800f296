//! HdrHistogram latency recording per pipeline stage and end to end, since
//! start and over a rolling window.

use fusepose_client::{LatencySummary, STAGE_COUNT, TIMELINE_COUNT};
use hdrhistogram::Histogram;

/// Index of the end-to-end timeline (after the stages).
pub const END_TO_END: usize = STAGE_COUNT;

/// Largest recordable latency: 60 s (larger values are clamped).
pub(crate) const MAX_NS: u64 = 60_000_000_000;

pub(crate) fn new_histogram() -> Histogram<u64> {
    Histogram::new_with_bounds(1, MAX_NS, 3).expect("constant histogram bounds are valid")
}

/// One histogram per timeline (stages, then end-to-end).
pub struct TimelineHistograms {
    pub timelines: Vec<Histogram<u64>>,
}

impl TimelineHistograms {
    pub fn new() -> Self {
        Self { timelines: (0..TIMELINE_COUNT).map(|_| new_histogram()).collect() }
    }

    /// Records `ns` on `timeline` (values outside 1 ns..60 s are clamped).
    pub fn record(&mut self, timeline: usize, ns: u64) {
        self.timelines[timeline].saturating_record(ns.clamp(1, MAX_NS));
    }

    pub fn reset(&mut self) {
        self.timelines.iter_mut().for_each(Histogram::reset);
    }

    pub fn summary(&self, timeline: usize) -> LatencySummary {
        summarize(&self.timelines[timeline])
    }

    pub fn summaries(&self) -> [LatencySummary; TIMELINE_COUNT] {
        std::array::from_fn(|i| self.summary(i))
    }
}

impl Default for TimelineHistograms {
    fn default() -> Self {
        Self::new()
    }
}

/// Percentiles of a histogram (all zero when empty).
pub fn summarize(h: &Histogram<u64>) -> LatencySummary {
    if h.is_empty() {
        return LatencySummary::default();
    }
    LatencySummary {
        count: h.len(),
        p50_ns: h.value_at_quantile(0.5),
        p90_ns: h.value_at_quantile(0.9),
        p99_ns: h.value_at_quantile(0.99),
        p999_ns: h.value_at_quantile(0.999),
        max_ns: h.max(),
    }
}

/// Since-start histograms plus the current and the last completed window.
pub struct LatencyBook {
    pub since_start: TimelineHistograms,
    pub current_window: TimelineHistograms,
    pub last_window: TimelineHistograms,
    /// Start of the current window, CLOCK_MONOTONIC ns.
    pub window_start_ns: u64,
    /// Length of the last completed window, ns (0 before the first completes).
    pub last_window_ns: u64,
}

impl LatencyBook {
    pub fn new(now_ns: u64) -> Self {
        Self {
            since_start: TimelineHistograms::new(),
            current_window: TimelineHistograms::new(),
            last_window: TimelineHistograms::new(),
            window_start_ns: now_ns,
            last_window_ns: 0,
        }
    }

    pub fn record(&mut self, timeline: usize, ns: u64) {
        self.since_start.record(timeline, ns);
        self.current_window.record(timeline, ns);
    }

    /// Closes the current window at `now_ns`: it becomes the last window.
    pub fn rotate(&mut self, now_ns: u64) {
        std::mem::swap(&mut self.current_window, &mut self.last_window);
        self.current_window.reset();
        self.last_window_ns = now_ns.saturating_sub(self.window_start_ns);
        self.window_start_ns = now_ns;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_follow_recorded_values() {
        let mut book = LatencyBook::new(0);
        for v in 1..=1000u64 {
            book.record(END_TO_END, v * 1000);
        }
        let s = book.since_start.summary(END_TO_END);
        assert_eq!(s.count, 1000);
        assert!((s.p50_ns as i64 - 500_000).abs() < 1000, "{s:?}");
        assert!((s.p99_ns as i64 - 990_000).abs() < 1000, "{s:?}");
        assert!((s.max_ns as i64 - 1_000_000).abs() < 1000, "{s:?}");
        book.rotate(5_000);
        assert_eq!(book.last_window.summary(END_TO_END).count, 1000);
        assert_eq!(book.current_window.summary(END_TO_END).count, 0);
        assert_eq!(book.last_window_ns, 5_000);
        assert_eq!(book.since_start.summary(0), LatencySummary::default());
    }

    #[test]
    fn huge_and_zero_values_are_clamped_not_lost() {
        let mut h = TimelineHistograms::new();
        h.record(0, 0);
        h.record(0, u64::MAX);
        assert_eq!(h.summary(0).count, 2);
    }
}
