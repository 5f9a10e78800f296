//! The ROS stamps of recent frames, so that poses go out with the exact stamp
//! of the image they belong to.
//!
//! The camera bridge maps a frame's ROS stamp to `CLOCK_MONOTONIC`; the pose
//! bridge maps the capture time back with its own measurement of the clock
//! offset, which agrees to well under a microsecond ([`crate::clock`]). The
//! pose bridge also listens to the camera's `CameraInfo` (tiny; same stamp
//! and frame id as the colour image) and replaces the mapped stamp by the
//! nearest recent one within a tolerance: exact for frames that came through
//! the camera bridge, the mapped time for any other producer.

use std::collections::VecDeque;

/// Recent (stamp ns, frame id) pairs, newest last.
pub struct RecentStamps {
    capacity: usize,
    tolerance_ns: i64,
    stamps: VecDeque<(i64, String)>,
}

impl RecentStamps {
    pub fn new(capacity: usize, tolerance_ns: i64) -> Self {
        Self { capacity: capacity.max(1), tolerance_ns, stamps: VecDeque::new() }
    }

    pub fn push(&mut self, stamp_ns: i64, frame_id: String) {
        if self.stamps.len() == self.capacity {
            self.stamps.pop_front();
        }
        self.stamps.push_back((stamp_ns, frame_id));
    }

    /// The frame id of the newest stamp seen, if any.
    pub fn latest_frame_id(&self) -> Option<&str> {
        self.stamps.back().map(|(_, f)| f.as_str())
    }

    /// The recorded stamp nearest `mapped_ns` within the tolerance (and its frame id).
    pub fn snap(&self, mapped_ns: i64) -> Option<(i64, &str)> {
        self.stamps
            .iter()
            .map(|(s, f)| ((s - mapped_ns).abs(), *s, f.as_str()))
            .filter(|(d, _, _)| *d <= self.tolerance_ns)
            .min_by_key(|(d, _, _)| *d)
            .map(|(_, s, f)| (s, f))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mapped_times_snap_to_the_nearest_recorded_stamp_within_tolerance() {
        let mut s = RecentStamps::new(2, 1_000_000);
        s.push(100_000_000, "a".into());
        s.push(141_666_666, "b".into());
        assert_eq!(s.snap(141_666_700), Some((141_666_666, "b")));
        assert_eq!(s.snap(100_000_400), Some((100_000_000, "a")));
        assert_eq!(s.snap(120_000_000), None, "between frames: no snap");
        s.push(183_333_333, "c".into());
        assert_eq!(s.snap(100_000_000), None, "the oldest was dropped");
        assert_eq!(s.latest_frame_id(), Some("c"));
    }
}
