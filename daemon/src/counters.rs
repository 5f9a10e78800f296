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
    /// Times the producer's sequence went backwards (a restarted producer).
    pub producer_restarts: u64,
}

impl FrameCounters {
    pub fn count_invalid(&mut self, reason: InvalidReason) {
        self.invalid += 1;
        self.invalid_by_reason[reason as usize] += 1;
    }
}

/// Follows the producer's sequence numbers to count frames never received.
#[derive(Clone, Debug, Default)]
pub struct SequenceTracker {
    last: Option<u64>,
}

/// What one received sequence number means.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SequenceEvent {
    /// The next one, or the first ever.
    InOrder,
    /// `missed` sequence numbers were skipped.
    Gap { missed: u64 },
    /// Not larger than the last one: the producer restarted (counting begins anew).
    Restart,
}

impl SequenceTracker {
    pub fn observe(&mut self, sequence: u64) -> SequenceEvent {
        let event = match self.last {
            None => SequenceEvent::InOrder,
            Some(last) if sequence == last.wrapping_add(1) => SequenceEvent::InOrder,
            Some(last) if sequence > last => SequenceEvent::Gap { missed: sequence - last - 1 },
            Some(_) => SequenceEvent::Restart,
        };
        self.last = Some(sequence);
        event
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gaps_and_restarts_are_told_apart() {
        let mut t = SequenceTracker::default();
        assert_eq!(t.observe(5), SequenceEvent::InOrder);
        assert_eq!(t.observe(6), SequenceEvent::InOrder);
        assert_eq!(t.observe(9), SequenceEvent::Gap { missed: 2 });
        assert_eq!(t.observe(0), SequenceEvent::Restart);
        assert_eq!(t.observe(1), SequenceEvent::InOrder);
    }
}
