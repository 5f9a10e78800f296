//! At most one log line per kind per interval. What an interval suppressed is
//! reported: with the next line of that kind, or — when no further line of
//! the kind comes — by [`RateLimit::take_overdue`] once the interval is over,
//! so a burst of one kind never hides another and no suppressed count is lost.

/// Gate for one kind of repeated warning.
#[derive(Clone, Debug)]
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

    /// The number suppressed, once the interval of the last emitted line is
    /// over and nothing emitted since reported them (the caller logs that
    /// count; it counts as this interval's line). None otherwise.
    pub fn take_overdue(&mut self, now_ns: u64) -> Option<u64> {
        let last = self.last_ns?;
        if self.suppressed == 0 || now_ns.saturating_sub(last) < self.interval_ns {
            return None;
        }
        self.last_ns = Some(now_ns);
        Some(std::mem::take(&mut self.suppressed))
    }
}

/// One [`RateLimit`] per kind, kinds numbered `0..kinds` (e.g. the rejection
/// reason codes); kinds outside share the last gate.
#[derive(Clone, Debug)]
pub struct RateLimitByKind {
    gates: Vec<RateLimit>,
}

impl RateLimitByKind {
    pub fn new(interval_ns: u64, kinds: usize) -> Self {
        Self { gates: vec![RateLimit::new(interval_ns); kinds.max(1)] }
    }

    fn gate(&mut self, kind: usize) -> &mut RateLimit {
        let last = self.gates.len() - 1;
        &mut self.gates[kind.min(last)]
    }

    /// As [`RateLimit::allow`], for `kind` alone.
    pub fn allow(&mut self, kind: usize, now_ns: u64) -> Option<u64> {
        self.gate(kind).allow(now_ns)
    }

    /// Calls `report(kind, suppressed)` for every kind with an overdue count
    /// ([`RateLimit::take_overdue`]).
    pub fn take_overdue(&mut self, now_ns: u64, mut report: impl FnMut(usize, u64)) {
        for (kind, gate) in self.gates.iter_mut().enumerate() {
            if let Some(n) = gate.take_overdue(now_ns) {
                report(kind, n);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_line_per_interval_with_suppressed_count() {
        let mut r = RateLimit::new(1_000);
        assert_eq!(r.allow(0), Some(0));
        assert_eq!(r.allow(10), None);
        assert_eq!(r.allow(999), None);
        assert_eq!(r.allow(1_000), Some(2));
        assert_eq!(r.allow(1_001), None);
    }

    #[test]
    fn suppressed_lines_are_reported_once_the_interval_is_over() {
        let mut r = RateLimit::new(1_000);
        assert_eq!(r.take_overdue(5_000), None, "nothing logged yet");
        assert_eq!(r.allow(0), Some(0));
        assert_eq!(r.take_overdue(500), None, "nothing suppressed yet");
        assert_eq!(r.allow(100), None);
        assert_eq!(r.allow(200), None);
        assert_eq!(r.take_overdue(999), None, "interval not over");
        assert_eq!(r.take_overdue(1_000), Some(2));
        assert_eq!(r.take_overdue(5_000), None, "reported once");
        // The report counts as the interval's line.
        assert_eq!(r.allow(1_500), None);
        assert_eq!(r.allow(2_000), Some(1));
    }

    /// The bug of issue 23: one gate for every rejection reason logged only
    /// the first kind of a burst (bad_magic) and never the others.
    #[test]
    fn each_kind_has_its_own_gate() {
        let (bad_magic, wrong_camera, too_old) = (1, 12, 22);
        let mut r = RateLimitByKind::new(1_000_000_000, 23);
        assert_eq!(r.allow(bad_magic, 0), Some(0));
        assert_eq!(r.allow(wrong_camera, 100_000_000), Some(0));
        assert_eq!(r.allow(too_old, 200_000_000), Some(0));
        assert_eq!(r.allow(too_old, 210_000_000), None);
        assert_eq!(r.allow(too_old, 220_000_000), None);
        assert_eq!(r.allow(bad_magic, 230_000_000), None);
        let mut reported = Vec::new();
        r.take_overdue(1_100_000_000, |k, n| reported.push((k, n)));
        assert_eq!(reported, [(bad_magic, 1)], "bad_magic's interval is over, too_old's is not");
        reported.clear();
        r.take_overdue(1_300_000_000, |k, n| reported.push((k, n)));
        assert_eq!(reported, [(too_old, 2)]);
        // Kinds beyond the table share the last gate instead of panicking.
        let mut r = RateLimitByKind::new(1_000, 3);
        assert_eq!(r.allow(99, 0), Some(0));
        assert_eq!(r.allow(2, 1), None);
    }
}
