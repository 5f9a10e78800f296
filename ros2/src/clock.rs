//! ROS stamps ↔ fusepose capture times.
//!
//! ROS stamps (realsense2_camera, Isaac ROS, `rclcpp::Clock` with
//! `use_sim_time` off) are `CLOCK_REALTIME` nanoseconds since the Unix epoch;
//! fusepose capture times are `CLOCK_MONOTONIC` nanoseconds. Both clocks are
//! slewed alike by NTP, so their difference only changes when the wall clock
//! is stepped. [`ClockMap`] measures the difference as the tightest of a few
//! bracketed reads (MONOTONIC, REALTIME, MONOTONIC; error below a microsecond)
//! and re-measures it every second to follow steps:
//! `monotonic = ros − offset`, `ros = monotonic + offset`.

use std::time::Duration;

/// How often the offset is measured again.
const REFRESH: Duration = Duration::from_secs(1);

// `time_t` and `c_long` are i32 on 32-bit targets: the conversions are not useless there.
#[allow(clippy::useless_conversion)]
fn read(clock: libc::clockid_t) -> i64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: `ts` is a valid, writable timespec; both clocks exist on Linux.
    unsafe { libc::clock_gettime(clock, &mut ts) };
    i64::from(ts.tv_sec) * 1_000_000_000 + i64::from(ts.tv_nsec)
}

/// `CLOCK_REALTIME − CLOCK_MONOTONIC`, ns, from the tightest of 8 bracketed reads.
pub fn measure_offset_ns() -> i64 {
    let mut best = (i64::MAX, 0i64);
    for _ in 0..8 {
        let a = read(libc::CLOCK_MONOTONIC);
        let real = read(libc::CLOCK_REALTIME);
        let b = read(libc::CLOCK_MONOTONIC);
        let width = b - a;
        if width < best.0 {
            best = (width, real - (a + width / 2));
        }
    }
    best.1
}

/// The current REALTIME − MONOTONIC offset, re-measured every second.
pub struct ClockMap {
    offset_ns: i64,
    measured_mono_ns: u64,
}

impl Default for ClockMap {
    fn default() -> Self {
        Self::new()
    }
}

impl ClockMap {
    pub fn new() -> Self {
        Self { offset_ns: measure_offset_ns(), measured_mono_ns: fusepose_client::monotonic_ns() }
    }

    fn refresh(&mut self) {
        let now = fusepose_client::monotonic_ns();
        if now.saturating_sub(self.measured_mono_ns) >= REFRESH.as_nanos() as u64 {
            self.offset_ns = measure_offset_ns();
            self.measured_mono_ns = now;
        }
    }

    /// The offset in use, ns (REALTIME − MONOTONIC).
    pub fn offset_ns(&self) -> i64 {
        self.offset_ns
    }

    /// A ROS stamp (ns since the epoch) as `CLOCK_MONOTONIC` ns; None before the monotonic epoch (boot).
    pub fn ros_to_monotonic(&mut self, ros_ns: i64) -> Option<u64> {
        self.refresh();
        u64::try_from(ros_ns.checked_sub(self.offset_ns)?).ok()
    }

    /// A `CLOCK_MONOTONIC` time as a ROS stamp (ns since the epoch).
    pub fn monotonic_to_ros(&mut self, mono_ns: u64) -> i64 {
        self.refresh();
        (mono_ns as i64).saturating_add(self.offset_ns)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn offset_maps_the_current_monotonic_time_to_the_wall_clock() {
        let mut map = ClockMap::new();
        let mono = fusepose_client::monotonic_ns();
        let wall = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap().as_nanos() as i64;
        let ros = map.monotonic_to_ros(mono);
        assert!((ros - wall).abs() < 50_000_000, "mapped {ros}, wall {wall}");
        assert_eq!(map.ros_to_monotonic(ros), Some(mono));
        assert_eq!(map.ros_to_monotonic(-5), None);
    }
}
