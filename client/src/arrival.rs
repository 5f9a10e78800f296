//! Spin-then-wait receiving: the wake-up of a blocked receiver (iceoryx2
//! event → kernel → scheduler) costs 15–30 µs on this kind of machine, while
//! checking the shared-memory queue costs well under 1 µs. Cameras and the
//! daemon publish periodically, so a receiver can block until shortly before
//! the next message is due and poll the queue from then on: the message is
//! then seen within a microsecond or two of `send`, for a CPU cost of about
//! `2 × margin` per period.
//!
//! [`ArrivalPredictor`] learns the period from arrival times (a running mean
//! at first, then smoothed) and how far arrivals stray from its grid; the
//! polling window widens with that jitter, up to four times the configured
//! margin, so a loaded sender is still caught while polling.
//! [`WaitStrategy`] says whether and how long to poll.

use std::time::Duration;

/// How a receiver waits for its next message.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WaitStrategy {
    /// Block on the iceoryx2 event until woken (no CPU while waiting).
    Block,
    /// Block until `margin` before the predicted arrival, then poll the queue
    /// until the message comes or `margin` after the prediction passed (then
    /// block again). Until a period is known this is [`WaitStrategy::Block`].
    SpinNearArrival { margin: Duration },
    /// Poll the queue all the time (one core busy; lowest latency).
    BusyPoll,
    /// [`WaitStrategy::SpinNearArrival`] when the waiting thread is pinned to
    /// one CPU, else [`WaitStrategy::Block`] (decided at each wait, see
    /// [`WaitStrategy::resolve`]). Unpinned, a polling receiver shares its CPU
    /// with the woken publisher often enough to be no faster than blocking
    /// (84–101 µs vs 62–84 µs p50 on 2 vCPUs); pinned it sees the frame in
    /// 7.7 µs (docs/BENCHMARKS.md, "Transport").
    SpinIfPinned { margin: Duration },
}

impl WaitStrategy {
    /// Spin-then-wait with a 200 µs margin: about 1.2 % of a core at 30 Hz.
    pub const DEFAULT_SPIN: Self = Self::SpinNearArrival { margin: Duration::from_micros(200) };

    /// The client's default: spin-then-wait (200 µs) on a pinned thread, else block.
    pub const DEFAULT: Self = Self::SpinIfPinned { margin: Duration::from_micros(200) };

    /// Replaces [`WaitStrategy::SpinIfPinned`] by what applies to the calling
    /// thread now; other strategies are returned as they are.
    pub fn resolve(self) -> Self {
        match self {
            Self::SpinIfPinned { margin } if current_thread_pinned() => Self::SpinNearArrival { margin },
            Self::SpinIfPinned { .. } => Self::Block,
            other => other,
        }
    }
}

/// Whether the calling thread may run on exactly one CPU.
pub fn current_thread_pinned() -> bool {
    // SAFETY: a zeroed cpu_set_t is a valid empty set; sched_getaffinity
    // writes at most size_of::<cpu_set_t>() bytes into it.
    unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        libc::sched_getaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &mut set) == 0 && libc::CPU_COUNT(&set) == 1
    }
}

/// What a receiver should do now.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WaitPlan {
    /// Block on the event until this `CLOCK_MONOTONIC` time at most (ns), then plan again.
    BlockUntil(u64),
    /// Block on the event with no time limit of the strategy's own.
    Block,
    /// Poll the queue until this time (ns), then plan again.
    SpinUntil(u64),
}

/// Learns the period of a periodic publisher from arrival times (ns).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ArrivalPredictor {
    last_arrival_ns: Option<u64>,
    /// Smoothed inter-arrival period, ns.
    period_ns: Option<f64>,
    /// Intervals seen (saturating), for the running mean at the start.
    intervals: u32,
    /// Smoothed distance of arrivals from the predicted grid, ns.
    jitter_ns: f64,
    /// Smoothed lateness of timed wake-ups (timer slack + scheduling), ns.
    wake_delay_ns: f64,
    /// Messages observed, and how many of them were caught while polling.
    arrivals: u64,
    polled: u64,
}

/// Weight of a new interval in the smoothed period (and jitter) once
/// `1 / PERIOD_GAIN` intervals were seen; before that a running mean.
const PERIOD_GAIN: f64 = 0.1;

/// Weight of a new wake-up lateness in its smoothed value.
const WAKE_GAIN: f64 = 0.2;

/// Wake-up lateness above this is a descheduled receiver, not timer behaviour.
const MAX_WAKE_DELAY_NS: f64 = 2e6;

/// The polling window grows with the jitter up to this many margins.
const MAX_MARGIN_FACTOR: u64 = 4;

impl ArrivalPredictor {
    /// Records that a message was found at `now_ns` while polling.
    pub fn observe_polled(&mut self, now_ns: u64) {
        self.polled += 1;
        self.observe(now_ns);
    }

    /// (messages observed, of them caught while polling).
    pub fn hits(&self) -> (u64, u64) {
        (self.arrivals, self.polled)
    }

    /// Records that a message arrived at `now_ns`.
    pub fn observe(&mut self, now_ns: u64) {
        self.arrivals += 1;
        if let Some(last) = self.last_arrival_ns {
            let interval = now_ns.saturating_sub(last) as f64;
            self.intervals = self.intervals.saturating_add(1);
            let gain = PERIOD_GAIN.max(1.0 / self.intervals as f64);
            self.period_ns = match self.period_ns {
                None if interval > 0.0 => Some(interval),
                Some(p) => {
                    // k skipped messages make one interval k + 1 periods long: use its share.
                    let k = (interval / p).round().max(1.0);
                    let off_grid = (interval - k * p).abs();
                    let share = if off_grid < 0.2 * p { interval / k } else { interval };
                    self.jitter_ns += gain * (off_grid.min(0.2 * p) - self.jitter_ns);
                    Some(p + gain * (share - p))
                }
                None => None,
            };
        }
        self.last_arrival_ns = Some(now_ns);
    }

    /// Records that a timed wait planned to end at `planned_ns` returned at
    /// `woke_ns` without a message: later waits end that much earlier. A timed
    /// wake-up came 70–130 µs late on this project's machine, most of the
    /// default 200 µs margin.
    pub fn record_wake(&mut self, planned_ns: u64, woke_ns: u64) {
        let late = (woke_ns.saturating_sub(planned_ns) as f64).min(MAX_WAKE_DELAY_NS);
        self.wake_delay_ns += WAKE_GAIN * (late - self.wake_delay_ns);
    }

    /// Smoothed lateness of timed wake-ups, ns.
    pub fn wake_delay_ns(&self) -> u64 {
        self.wake_delay_ns as u64
    }

    /// Smoothed distance of arrivals from the predicted grid, ns.
    pub fn jitter_ns(&self) -> u64 {
        self.jitter_ns as u64
    }

    /// The learned period, ns.
    pub fn period_ns(&self) -> Option<u64> {
        self.period_ns.map(|p| p as u64)
    }

    /// When the next message is expected (ns), once a period is known: the
    /// first multiple of the period after the last arrival that is not more
    /// than a margin in the past.
    pub fn next_arrival_ns(&self, now_ns: u64, margin_ns: u64) -> Option<u64> {
        let (last, period) = (self.last_arrival_ns?, self.period_ns? as u64);
        if period == 0 {
            return None;
        }
        let mut next = last + period;
        if next + margin_ns < now_ns {
            // Messages were missed: step to the next slot of the same grid.
            let behind = now_ns - margin_ns - next;
            next += (behind / period + 1) * period;
        }
        Some(next)
    }

    /// What to do at `now_ns` under `strategy`.
    pub fn plan(&self, strategy: WaitStrategy, now_ns: u64) -> WaitPlan {
        match strategy {
            WaitStrategy::Block => WaitPlan::Block,
            WaitStrategy::BusyPoll => WaitPlan::SpinUntil(u64::MAX),
            WaitStrategy::SpinNearArrival { margin } | WaitStrategy::SpinIfPinned { margin } => {
                let base = margin.as_nanos() as u64;
                let margin_ns = base.max((2 * self.jitter_ns()).min(MAX_MARGIN_FACTOR * base));
                // Wake early by the usual lateness so polling starts on time.
                let early_ns = margin_ns + self.wake_delay_ns();
                match self.next_arrival_ns(now_ns, margin_ns) {
                    None => WaitPlan::Block,
                    Some(next) if now_ns + early_ns < next => WaitPlan::BlockUntil(next - early_ns),
                    Some(next) => WaitPlan::SpinUntil(next + margin_ns),
                }
            }
        }
    }
}

/// Queue checks between two `sched_yield`s while polling.
const YIELD_EVERY: u32 = 8;

/// Calls `check` until it gives `Some` or the `CLOCK_MONOTONIC` time
/// `until_ns` passes (then `None`). With `yield_cpu` it yields the CPU every
/// few checks instead of only spinning: a publisher woken on this core would
/// otherwise wait out the scheduler's wake-up granularity (~1 ms measured on
/// 2 cores) behind a short polling window. A permanent busy poll does not
/// yield (under load a yield hands the core to whatever else runs: 60 µs
/// instead of 4–7 µs measured beside a training run).
pub fn poll_until<T, E>(
    until_ns: u64,
    yield_cpu: bool,
    mut check: impl FnMut() -> Result<Option<T>, E>,
) -> Result<Option<T>, E> {
    let mut polls = 0u32;
    loop {
        if let Some(v) = check()? {
            return Ok(Some(v));
        }
        if crate::monotonic_ns() >= until_ns {
            return Ok(None);
        }
        polls = polls.wrapping_add(1);
        if yield_cpu && polls.is_multiple_of(YIELD_EVERY) {
            std::thread::yield_now();
        } else {
            std::hint::spin_loop();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;
    const SPIN: WaitStrategy = WaitStrategy::SpinNearArrival { margin: Duration::from_micros(200) };

    #[test]
    fn learns_a_steady_period_and_ignores_a_skipped_message() {
        let mut p = ArrivalPredictor::default();
        for i in 0..20 {
            p.observe(1000 * MS + i * 33 * MS);
        }
        assert_eq!(p.period_ns(), Some(33 * MS));
        p.observe(1000 * MS + 21 * 33 * MS); // one message missing: 66 ms interval
        assert!(p.period_ns().unwrap().abs_diff(33 * MS) < MS / 10);
    }

    #[test]
    fn blocks_until_shortly_before_the_message_then_spins() {
        let mut p = ArrivalPredictor::default();
        assert_eq!(p.plan(SPIN, 0), WaitPlan::Block, "no period yet");
        p.observe(100 * MS);
        p.observe(110 * MS);
        assert_eq!(p.plan(SPIN, 111 * MS), WaitPlan::BlockUntil(120 * MS - 200_000));
        assert_eq!(p.plan(SPIN, 120 * MS - 100_000), WaitPlan::SpinUntil(120 * MS + 200_000));
        // Late: the next slot of the grid.
        assert_eq!(p.plan(SPIN, 121 * MS), WaitPlan::BlockUntil(130 * MS - 200_000));
        assert_eq!(p.plan(WaitStrategy::Block, 121 * MS), WaitPlan::Block);
        assert_eq!(p.jitter_ns(), 0, "a steady sender has no jitter");
        assert_eq!(p.plan(WaitStrategy::BusyPoll, 121 * MS), WaitPlan::SpinUntil(u64::MAX));
    }

    #[test]
    fn the_period_converges_fast_from_a_short_first_interval() {
        let mut p = ArrivalPredictor::default();
        p.observe(0);
        p.observe(30 * MS); // the first interval happens to be short
        for i in 2..12 {
            p.observe(30 * MS + (i - 1) * 33 * MS);
        }
        let err = p.period_ns().unwrap().abs_diff(33 * MS);
        assert!(err < MS / 2, "period off by {err} ns after 11 intervals");
    }

    #[test]
    fn jittery_arrivals_widen_the_polling_window_up_to_four_margins() {
        let mut p = ArrivalPredictor::default();
        let mut t = 0;
        for i in 0..60u64 {
            // ±300 µs around a 10 ms grid.
            let jitter = if i % 2 == 0 { 300_000 } else { 0 };
            p.observe(t + jitter);
            t += 10 * MS;
        }
        let j = p.jitter_ns();
        assert!(j > 100_000 && j < 400_000, "jitter {j} ns");
        let last = t - 10 * MS; // last arrival (odd i: on the grid)
        let WaitPlan::BlockUntil(until) = p.plan(SPIN, last + MS) else { panic!("expected a block") };
        let margin = (last + 10 * MS).abs_diff(until);
        assert!(margin > 200_000 && margin <= 800_000, "margin {margin} ns");
        // A wildly irregular sender is capped at four margins.
        let mut q = ArrivalPredictor::default();
        for i in 0..60u64 {
            q.observe(i * 10 * MS + (i * 7919 % 13) * 250_000);
        }
        let last = 59u64;
        let n = last * 10 * MS + (last * 7919 % 13) * 250_000;
        if let WaitPlan::BlockUntil(until) = q.plan(SPIN, n + MS) {
            let next = q.next_arrival_ns(n + MS, 0).unwrap();
            assert!(next - until <= 800_000);
        }
    }

    #[test]
    fn late_timed_wake_ups_make_the_receiver_wake_earlier() {
        let mut p = ArrivalPredictor::default();
        p.observe(100 * MS);
        p.observe(110 * MS);
        for _ in 0..30 {
            p.record_wake(0, 100_000); // 100 µs late every time
        }
        assert!(p.wake_delay_ns().abs_diff(100_000) < 1_000);
        assert_eq!(p.plan(SPIN, 111 * MS), WaitPlan::BlockUntil(120 * MS - 200_000 - p.wake_delay_ns()));
        // Within margin + delay of the arrival: poll.
        assert_eq!(p.plan(SPIN, 120 * MS - 250_000), WaitPlan::SpinUntil(120 * MS + 200_000));
        // A descheduled receiver (50 ms late) counts as at most 2 ms.
        let mut q = ArrivalPredictor::default();
        q.record_wake(0, 50 * MS);
        assert!(q.wake_delay_ns() <= 2 * MS / 5 + 1);
    }

    #[test]
    fn spin_if_pinned_follows_the_threads_affinity() {
        std::thread::spawn(|| {
            if !current_thread_pinned() {
                assert_eq!(WaitStrategy::DEFAULT.resolve(), WaitStrategy::Block, "an unpinned thread blocks");
            }
            // SAFETY: a zeroed cpu_set_t is a valid empty set; CPU 0 exists.
            unsafe {
                let mut set: libc::cpu_set_t = std::mem::zeroed();
                libc::CPU_SET(0, &mut set);
                assert_eq!(libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set), 0);
            }
            assert!(current_thread_pinned());
            assert_eq!(WaitStrategy::DEFAULT.resolve(), WaitStrategy::DEFAULT_SPIN);
            assert_eq!(WaitStrategy::BusyPoll.resolve(), WaitStrategy::BusyPoll);
        })
        .join()
        .unwrap();
    }
}
