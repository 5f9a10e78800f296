//! Scheduling several cameras on one loop: earliest deadline first over
//! each camera's newest frame, and a time slice per frame so that no camera
//! starves while another's frames are expensive.
//!
//! The loop thread and the network's worker thread serve one frame at a
//! time. A frame's own deadline (capture + the camera's `deadline_ms`) says
//! when it must be published; with several cameras active it also gets at
//! most its camera's frame period divided by the number of active cameras,
//! so that every camera's frames fit one period together (a utilisation of
//! at most 1 for earliest-deadline-first). The estimator fits each frame to
//! the sooner of the two ends (fewer refiner iterations, fewer points,
//! the smallest instances shed), so a frame is degraded rather than late.

use fusepose_client::ArrivalPredictor;

/// A camera counts as active while its last frame is at most this many of its periods old.
const ACTIVE_PERIODS: u64 = 3;
/// Period assumed for a camera whose period is not learned yet, ns.
const UNKNOWN_PERIOD_NS: u64 = 41_666_667;

/// What the scheduler knows about one camera.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CameraClock {
    /// The frame period, learned from capture times (skipped frames and
    /// pauses count as whole periods, not as longer ones).
    captures: ArrivalPredictor,
    last_capture_ns: Option<u64>,
    /// When the loop last received a frame of this camera (its clock), ns.
    last_arrival_ns: Option<u64>,
}

impl CameraClock {
    /// Records a received frame (capture time from its header, arrival on the loop's clock).
    pub fn observe(&mut self, capture_ns: u64, arrival_ns: u64) {
        if self.last_capture_ns.is_none_or(|last| capture_ns > last) {
            self.captures.observe(capture_ns);
            self.last_capture_ns = Some(capture_ns);
        }
        self.last_arrival_ns = Some(arrival_ns);
    }

    /// The learned frame period, ns.
    pub fn period_ns(&self) -> Option<u64> {
        self.captures.period_ns()
    }

    /// When this camera's next frame is expected to be captured, ns.
    pub fn next_capture_ns(&self) -> Option<u64> {
        Some(self.last_capture_ns? + self.period_ns()?)
    }

    /// Whether this camera sent a frame within its last few periods.
    pub fn is_active(&self, now_ns: u64) -> bool {
        let period = self.period_ns().unwrap_or(UNKNOWN_PERIOD_NS);
        self.last_arrival_ns.is_some_and(|t| now_ns.saturating_sub(t) <= ACTIVE_PERIODS * period)
    }
}

/// Index of the pending frame with the earliest deadline (ties: the lower
/// index); `deadlines[i]` is camera i's pending frame's deadline, if any.
pub fn earliest_deadline(deadlines: impl IntoIterator<Item = Option<u64>>) -> Option<usize> {
    deadlines.into_iter().enumerate().filter_map(|(i, d)| d.map(|d| (d, i))).min().map(|(_, i)| i)
}

/// The latest time the frame being started may end so that another
/// camera's frame due at `other_deadline_ns`, needing at least
/// `other_min_cost_ns`, can still meet its deadline — but never less than
/// `own_min_cost_ns` from `now_ns` (each frame keeps its own minimum).
pub fn leave_room_for(now_ns: u64, own_min_cost_ns: u64, other_deadline_ns: u64, other_min_cost_ns: u64) -> u64 {
    other_deadline_ns.saturating_sub(other_min_cost_ns).max(now_ns + own_min_cost_ns)
}

/// The time one frame of a camera with frame period `period_ns` may take
/// while `active` cameras share the loop; `None` with one active camera
/// (its deadline alone bounds it).
pub fn slice_ns(period_ns: Option<u64>, active: usize) -> Option<u64> {
    (active >= 2).then(|| period_ns.unwrap_or(UNKNOWN_PERIOD_NS) / active as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_earliest_deadline_goes_first() {
        assert_eq!(earliest_deadline([Some(50), None, Some(30), Some(40)]), Some(2));
        assert_eq!(earliest_deadline([None, None]), None);
        assert_eq!(earliest_deadline([Some(7), Some(7)]), Some(0), "ties: lower index");
    }

    #[test]
    fn slices_share_one_period_among_active_cameras() {
        assert_eq!(slice_ns(Some(41_666_667), 1), None);
        assert_eq!(slice_ns(Some(40_000_000), 2), Some(20_000_000));
        assert_eq!(slice_ns(None, 3), Some(UNKNOWN_PERIOD_NS / 3));
        // Two cameras at 24 and 12 FPS: each frame's slice over its period sums to 1.
        let (a, b) = (slice_ns(Some(41_666_667), 2).unwrap(), slice_ns(Some(83_333_333), 2).unwrap());
        let utilisation = a as f64 / 41_666_667.0 + b as f64 / 83_333_333.0;
        assert!((utilisation - 1.0).abs() < 1e-6, "{utilisation}");
    }

    #[test]
    fn a_frame_leaves_room_for_the_next_due_frame_but_keeps_its_own_minimum() {
        // Now 0; another camera's frame is due at 40 ms and needs 15 ms: end by 25 ms.
        assert_eq!(leave_room_for(0, 5_000_000, 40_000_000, 15_000_000), 25_000_000);
        // That frame is nearly doomed: this one still gets its own 5 ms.
        assert_eq!(leave_room_for(0, 5_000_000, 8_000_000, 15_000_000), 5_000_000);
    }

    #[test]
    fn the_period_is_learned_and_a_silent_camera_goes_inactive() {
        let mut c = CameraClock::default();
        assert!(!c.is_active(0));
        for i in 0..50u64 {
            c.observe(i * 40_000_000, i * 40_000_000 + 1_000_000);
        }
        let p = c.period_ns().unwrap();
        assert!((39_900_000..=40_100_000).contains(&p), "{p}");
        // A pause of 2 s does not teach the period.
        c.observe(51 * 40_000_000 + 2_000_000_000, 51 * 40_000_000 + 2_000_000_000);
        assert!((39_900_000..=40_100_000).contains(&c.period_ns().unwrap()));
        let last = 51 * 40_000_000 + 2_000_000_000;
        assert!(c.is_active(last + 100_000_000));
        assert!(!c.is_active(last + 130_000_000), "silent for over 3 periods");
    }
}
