//! The robot side: wait for pose messages; and the stats query client.
//!
//! Waiting follows a [`WaitStrategy`] (default: block until shortly before
//! the next message is due, then poll; see [`crate::arrival`]), through
//! [`wait_for_samples`], which any iceoryx2 subscriber + listener pair can use.

use std::time::{Duration, Instant};

use iceoryx2::port::client::Client;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;

use crate::arrival::{ArrivalPredictor, WaitPlan, WaitStrategy, poll_until};
use crate::services::CameraServices;
use crate::{ClientError, Ipc, PoseMessage, StatsRequest, StatsSnapshot, monotonic_ns};

/// Blocks until `has_samples` says true (returns true) or `timeout` passes
/// (false), waiting on `listener` as `strategy` and `predictor` plan; records
/// each arrival in `predictor`. Pending wake-ups of `listener` are consumed.
pub fn wait_for_samples<E: std::fmt::Debug>(
    listener: &Listener<ipc::Service>,
    mut has_samples: impl FnMut() -> Result<bool, E>,
    predictor: &mut ArrivalPredictor,
    strategy: WaitStrategy,
    timeout: Duration,
) -> Result<bool, (&'static str, String)> {
    let deadline = monotonic_ns().saturating_add(timeout.as_nanos() as u64);
    let strategy = strategy.resolve();
    let mut check = || has_samples().map_err(|e| ("receive", format!("{e:?}")));
    loop {
        // Consume pending wake-ups first so the next wait really blocks.
        let _ = listener.try_wait(|_| {});
        if check()? {
            predictor.observe(monotonic_ns());
            return Ok(true);
        }
        let now = monotonic_ns();
        if now >= deadline {
            return Ok(false);
        }
        let block_until = match predictor.plan(strategy, now) {
            WaitPlan::Block => deadline,
            WaitPlan::BlockUntil(t) => t.min(deadline),
            WaitPlan::SpinUntil(t) => {
                let yield_cpu = strategy != WaitStrategy::BusyPoll;
                if poll_until(t.min(deadline), yield_cpu, || check().map(|ready| ready.then_some(())))?.is_some() {
                    predictor.observe_polled(monotonic_ns());
                    return Ok(true);
                }
                continue;
            }
        };
        let wait = Duration::from_nanos(block_until.saturating_sub(now));
        wait_readable(listener, wait).map_err(|e| ("wait", e.to_string()))?;
        let woke = monotonic_ns();
        if woke >= block_until && block_until < deadline {
            predictor.record_wake(block_until, woke);
        }
    }
}

/// Blocks until `listener` has a pending wake-up or `timeout` passes (an
/// interrupting signal ends the wait early, which callers treat as a time-out).
///
/// `ppoll` on the listener's socket rather than `Listener::timed_wait`: in
/// iceoryx2 0.10 that waits through `SO_RCVTIMEO`, which counts whole
/// scheduler ticks, so a 100 µs time-out took 7–8 ms and a 31 ms one 36 ms
/// on this machine (docs/BENCHMARKS.md) — spin-then-wait then never woke
/// before the message. `ppoll`'s time-out runs on high-resolution timers.
fn wait_readable(listener: &Listener<ipc::Service>, timeout: Duration) -> std::io::Result<()> {
    // SAFETY: the descriptor belongs to `listener`, which outlives this call;
    // it is only polled, never stored or closed.
    let fd = unsafe { listener.file_descriptor().native_handle() };
    let mut pfd = libc::pollfd { fd, events: libc::POLLIN, revents: 0 };
    let ts = libc::timespec {
        tv_sec: timeout.as_secs().min(i32::MAX as u64) as libc::time_t,
        tv_nsec: timeout.subsec_nanos() as libc::c_long,
    };
    // SAFETY: one valid pollfd, a valid timespec, no signal mask change.
    let r = unsafe { libc::ppoll(&mut pfd, 1, &ts, std::ptr::null()) };
    if r < 0 {
        let e = std::io::Error::last_os_error();
        if e.kind() != std::io::ErrorKind::Interrupted {
            return Err(e);
        }
    }
    Ok(())
}

/// Receives the pose messages of one camera.
pub struct Consumer {
    services: CameraServices,
    subscriber: Subscriber<ipc::Service, PoseMessage, ()>,
    listener: Listener<ipc::Service>,
    strategy: WaitStrategy,
    predictor: ArrivalPredictor,
}

impl Consumer {
    /// Subscribes to the poses of camera `camera` (the daemon need not run yet).
    pub fn open(ipc: &Ipc, camera: &str) -> Result<Self, ClientError> {
        let services = CameraServices::open(ipc, camera)?;
        let subscriber = services.pose_subscriber()?;
        let listener = services.pose_listener()?;
        Ok(Self {
            services,
            subscriber,
            listener,
            strategy: WaitStrategy::DEFAULT,
            predictor: ArrivalPredictor::default(),
        })
    }

    /// How [`Consumer::wait`] and [`Consumer::wait_ready`] wait (default [`WaitStrategy::DEFAULT`]: spin-then-wait when the thread is pinned to one CPU, else block).
    pub fn set_wait_strategy(&mut self, strategy: WaitStrategy) {
        self.strategy = strategy;
    }

    /// The pose-message period learned so far, ns.
    pub fn learned_period_ns(&self) -> Option<u64> {
        self.predictor.period_ns()
    }

    /// The listener woken on every pose message, to attach to a caller's WaitSet.
    pub fn listener(&self) -> &Listener<ipc::Service> {
        &self.listener
    }

    /// Takes every pose message received since the last call and returns the
    /// newest (None when nothing new arrived). Never blocks.
    pub fn latest(&mut self) -> Result<Option<PoseMessage>, ClientError> {
        let mut newest = None;
        loop {
            let received = self
                .subscriber
                .receive()
                .map_err(|e| ClientError::transfer(&self.services.poses_name, "receive", &e))?;
            let Some(sample) = received else { break };
            let msg = *sample.payload();
            ClientError::check_version(&self.services.poses_name, "pose message", msg.format_version)?;
            newest = Some(msg);
        }
        Ok(newest)
    }

    /// Every pose message received since the last call, oldest first (at most
    /// the subscriber buffer; older ones were overwritten).
    pub fn drain(&mut self, out: &mut Vec<PoseMessage>) -> Result<(), ClientError> {
        while let Some(sample) =
            self.subscriber.receive().map_err(|e| ClientError::transfer(&self.services.poses_name, "receive", &e))?
        {
            out.push(*sample.payload());
        }
        Ok(())
    }

    /// Blocks until a new pose message arrives or `timeout` passes; returns the newest.
    pub fn wait(&mut self, timeout: Duration) -> Result<Option<PoseMessage>, ClientError> {
        if self.wait_ready(timeout)? { self.latest() } else { Ok(None) }
    }

    /// Blocks until at least one pose message is waiting (true) or `timeout` passes (false);
    /// takes nothing (use [`Consumer::latest`] or [`Consumer::drain`]).
    pub fn wait_ready(&mut self, timeout: Duration) -> Result<bool, ClientError> {
        let subscriber = &self.subscriber;
        wait_for_samples(&self.listener, || subscriber.has_samples(), &mut self.predictor, self.strategy, timeout)
            .map_err(|(operation, detail)| ClientError::Transfer {
                service: self.services.poses_name.clone(),
                operation,
                detail,
            })
    }
}

/// Asks the daemon for its stats snapshot of one camera.
pub struct StatsClient {
    services: CameraServices,
    client: Client<ipc::Service, StatsRequest, (), StatsSnapshot, ()>,
}

impl StatsClient {
    pub fn open(ipc: &Ipc, camera: &str) -> Result<Self, ClientError> {
        let services = CameraServices::open(ipc, camera)?;
        let client = services.stats_client()?;
        Ok(Self { services, client })
    }

    /// Sends one request and waits up to `timeout` for the snapshot.
    pub fn query(&self, timeout: Duration) -> Result<StatsSnapshot, ClientError> {
        let service = &self.services.stats_name;
        let deadline = Instant::now() + timeout;
        let pending =
            self.client.send_copy(StatsRequest::default()).map_err(|e| ClientError::transfer(service, "send", &e))?;
        loop {
            if let Some(response) = pending.receive().map_err(|e| ClientError::transfer(service, "receive", &e))? {
                let snapshot = *response.payload();
                ClientError::check_version(service, "stats snapshot", snapshot.format_version)?;
                return Ok(snapshot);
            }
            if Instant::now() >= deadline {
                return Err(ClientError::Timeout { service: service.clone(), timeout_ms: timeout.as_millis() as u64 });
            }
            std::thread::sleep(Duration::from_millis(2));
        }
    }
}
