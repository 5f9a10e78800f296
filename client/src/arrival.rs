//! Spin-then-wait receiving: the wake-up of a blocked receiver (iceoryx2
//! event → kernel → scheduler) costs 15–30 µs on this kind of machine, while
//! checking the shared-memory queue costs well under 1 µs. Cameras and the
//! daemon publish periodically, so a receiver can block until shortly before
//! the next message is due and poll the queue from then on: the message is
//! then seen within a microsecond or two of `send`, for a CPU cost of about
//! `2 × margin` per period.
//!
//! [`ArrivalPredictor`] learns the period from arrival times;
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
}

impl WaitStrategy {
    /// Spin-then-wait with a 200 µs margin: about 1.2 % of a core at 30 Hz.
    pub const DEFAULT_SPIN: Self = Self::SpinNearArrival {
        margin: Duration::from_micros(200),
    };
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
}

/// Weight of a new interval in the smoothed period.
const PERIOD_GAIN: f64 = 0.1;

impl ArrivalPredictor {
    /// Records that a message arrived at `now_ns`.
    pub fn observe(&mut self, now_ns: u64) {
        if let Some(last) = self.last_arrival_ns {
            let interval = now_ns.saturating_sub(last) as f64;
            self.period_ns = match self.period_ns {
                None if interval > 0.0 => Some(interval),
                Some(p) => {
                    // k skipped messages make one interval k + 1 periods long: use its share.
                    let k = (interval / p).round().max(1.0);
                    let share = if (interval - k * p).abs() < 0.2 * p {
                        interval / k
                    } else {
                        interval
                    };
                    Some(p + PERIOD_GAIN * (share - p))
                }
                None => None,
            };
        }
        self.last_arrival_ns = Some(now_ns);
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
            WaitStrategy::SpinNearArrival { margin } => {
                let margin_ns = margin.as_nanos() as u64;
                match self.next_arrival_ns(now_ns, margin_ns) {
                    None => WaitPlan::Block,
                    Some(next) if now_ns + margin_ns < next => {
                        WaitPlan::BlockUntil(next - margin_ns)
                    }
                    Some(next) => WaitPlan::SpinUntil(next + margin_ns),
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;
    const SPIN: WaitStrategy = WaitStrategy::SpinNearArrival {
        margin: Duration::from_micros(200),
    };

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
        assert_eq!(
            p.plan(SPIN, 111 * MS),
            WaitPlan::BlockUntil(120 * MS - 200_000)
        );
        assert_eq!(
            p.plan(SPIN, 120 * MS - 100_000),
            WaitPlan::SpinUntil(120 * MS + 200_000)
        );
        // Late: the next slot of the grid.
        assert_eq!(
            p.plan(SPIN, 121 * MS),
            WaitPlan::BlockUntil(130 * MS - 200_000)
        );
        assert_eq!(p.plan(WaitStrategy::Block, 121 * MS), WaitPlan::Block);
        assert_eq!(
            p.plan(WaitStrategy::BusyPoll, 121 * MS),
            WaitPlan::SpinUntil(u64::MAX)
        );
    }
}
