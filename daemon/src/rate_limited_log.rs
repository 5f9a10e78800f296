//! At most one log line per key per interval; the next line reports how many were suppressed.

/// Gate for one kind of repeated warning.
pub struct RateLimit {
    interval_ns: u64,
    last_ns: Option<u64>,
    suppressed: u64,
}

impl RateLimit {
    pub fn new(interval_ns: u64) -> Self {
        Self { interval_ns, last_ns: None, suppressed: 0 }
    }

    /// Some(number suppressed since the last emitted line) when a line may be
    /// emitted now, None when this one is suppressed.
    pub fn allow(&mut self, now_ns: u64) -> Option<u64> {
        match self.last_ns {
            Some(last) if now_ns.saturating_sub(last) < self.interval_ns => {
                self.suppressed += 1;
                None
            }
            _ => {
                self.last_ns = Some(now_ns);
                Some(std::mem::take(&mut self.suppressed))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn one_line_per_interval_with_suppressed_count() {
        let mut r = super::RateLimit::new(1_000);
        assert_eq!(r.allow(0), Some(0));
        assert_eq!(r.allow(10), None);
        assert_eq!(r.allow(999), None);
        assert_eq!(r.allow(1_000), Some(2));
        assert_eq!(r.allow(1_001), None);
    }
}
