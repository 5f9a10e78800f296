//! Per-camera frame counters and sequence-gap tracking.

use fusepose_client::InvalidReason;

/// Counts of what happened to a camera's frames.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct FrameCounters {
    pub received: u64,
    pub processed: u64,
    pub skipped_stale: u64,
    pub missed_sequence: u64,
    pub invalid: u64,
    pub invalid_by_reason: [u64; InvalidReason::COUNT],
    pub deadline_misses: u64,
    pub estimator_failures: u64,
    /// Times frames started coming from a new publisher (a restarted producer).
    pub producer_restarts: u64,
    /// Object poses with a NaN/infinite value, dropped instead of published.
    pub poses_non_finite: u64,
    /// Poses the depth check failed (dropped or published unverified).
    pub poses_failed_verification: u64,
    /// Instances the deadline did not pay for.
    pub objects_shed: u64,
    /// Messages flagged DEGRADED.
    pub frames_degraded: u64,
}

impl FrameCounters {
    pub fn count_invalid(&mut self, reason: InvalidReason) {
        self.invalid += 1;
        self.invalid_by_reason[reason as usize] += 1;
    }
}

/// Follows each publisher's sequence numbers: counts frames never received
/// and spots numbers that go backwards or repeat.
#[derive(Clone, Debug, Default)]
pub struct SequenceTracker {
    /// (iceoryx2 publisher id, last accepted sequence).
    last: Option<(u128, u64)>,
}

/// What one received sequence number means.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SequenceEvent {
    /// The next one, or the first ever.
    InOrder,
    /// `missed` sequence numbers were skipped.
    Gap { missed: u64 },
    /// The first frame of a new publisher (a restarted producer): counting begins anew.
    Restart,
    /// Not larger than the last one from the same publisher: a repeated or
    /// reordered frame. The tracker keeps the larger number.
    Regression { last: u64 },
}

impl SequenceTracker {
    pub fn observe(&mut self, publisher: u128, sequence: u64) -> SequenceEvent {
        let event = match self.last {
            None => SequenceEvent::InOrder,
            Some((p, _)) if p != publisher => SequenceEvent::Restart,
            Some((_, last)) if sequence == last.wrapping_add(1) => SequenceEvent::InOrder,
            Some((_, last)) if sequence > last => SequenceEvent::Gap { missed: sequence - last - 1 },
            Some((_, last)) => return SequenceEvent::Regression { last },
        };
        self.last = Some((publisher, sequence));
        event
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gaps_restarts_and_regressions_are_told_apart() {
        let mut t = SequenceTracker::default();
        assert_eq!(t.observe(1, 5), SequenceEvent::InOrder);
        assert_eq!(t.observe(1, 6), SequenceEvent::InOrder);
        assert_eq!(t.observe(1, 9), SequenceEvent::Gap { missed: 2 });
        // Same publisher going back or repeating: refused, the tracker keeps 9.
        assert_eq!(t.observe(1, 9), SequenceEvent::Regression { last: 9 });
        assert_eq!(t.observe(1, 3), SequenceEvent::Regression { last: 9 });
        assert_eq!(t.observe(1, 10), SequenceEvent::InOrder);
        // A new publisher may start anywhere.
        assert_eq!(t.observe(2, 0), SequenceEvent::Restart);
        assert_eq!(t.observe(2, 1), SequenceEvent::InOrder);
    }
}
