//! The daemon loop: an iceoryx2 WaitSet woken by frame events and a periodic
//! tick; SIGINT/SIGTERM end it cleanly with a final summary and `.hlog`.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use fusepose_client::{ArrivalPredictor, Ipc, Stage, WaitPlan, WaitStrategy, monotonic_ns, poll_until};
use iceoryx2::prelude::*;
use iceoryx2::waitset::{WaitSetAttachmentId, WaitSetRunResult};

use crate::camera::{CameraPorts, CameraState};
use crate::camera_lock::CameraLock;
use crate::config::DaemonConfig;
use crate::engine::{EngineSpec, PoseEngine};
use crate::interval_log::IntervalLog;

/// How the loop ended and what it saw, per camera.
#[derive(Debug)]
pub struct RunReport {
    pub cameras: Vec<(String, crate::counters::FrameCounters)>,
    pub hlog_path: Option<std::path::PathBuf>,
}

/// Far enough ahead that every rate-limit interval counts as over (exit report).
const LOG_FLUSH_NS: u64 = 3_600_000_000_000;

fn seconds_to_ns(s: f64) -> u64 {
    (s * 1e9) as u64
}

fn write_windows(log: &mut Option<IntervalLog>, states: &[CameraState], end_ns: u64) {
    let Some(log) = log.as_mut() else { return };
    let names = fusepose_client::Stage::timeline_names();
    for state in states {
        for (timeline, h) in state.latency.current_window.timelines.iter().enumerate() {
            let tag = format!("{}.{}", state.name, names[timeline]);
            if let Err(e) = log.write(&tag, state.latency.window_start_ns, end_ns, h) {
                tracing::warn!(path = %log.path().display(), error = %e, "writing the interval log failed");
                return;
            }
        }
    }
}

/// Polls every camera's frame queue until one has a frame (its index) or `until_ns` passes.
fn poll_frames(ports: &[CameraPorts], until_ns: u64) -> Option<usize> {
    let ready = || Ok::<_, ()>(ports.iter().position(|p| p.frames.has_samples().unwrap_or(false)));
    poll_until(until_ns, true, ready).unwrap_or(None)
}

/// Runs the daemon until SIGINT/SIGTERM (or `stop` becomes true).
pub fn run(config: &DaemonConfig, spec: &EngineSpec, stop: Option<Arc<AtomicBool>>) -> anyhow::Result<RunReport> {
    let threads_used = if spec.estimate_stage == Stage::Network && spec.factory.is_some() { 2 } else { 1 };
    if let Some(asked) = config.estimator.worker_threads
        && asked > threads_used
    {
        tracing::warn!(
            worker_threads = asked,
            used = threads_used,
            "estimator.worker_threads: only {threads_used} used (the network uses at most 2, ICP 1)"
        );
    }
    // Refuse a root directory other users could tamper with, before iceoryx2 touches it.
    let root = crate::ipc_root::effective_root(&config.ipc_options())?;
    crate::ipc_root::check_root_path(&root)?;
    let ipc = Ipc::new(&config.ipc_options())?;
    // One daemon per camera: lock every camera before opening any port.
    let prefix = crate::ipc_root::effective_prefix(&config.ipc_options())?;
    let node = format!("{} ({})", ipc.node().name(), ipc.node().id());
    let mut locks = Vec::with_capacity(config.cameras.len());
    for name in &config.cameras {
        let mut lock = CameraLock::acquire(&root, &prefix, name)?;
        if let Err(e) = lock.record_node(&node) {
            tracing::warn!(path = %lock.path().display(), error = %e, "cannot write the node into the camera lock");
        }
        locks.push(lock);
    }
    let (removed, failed) = ipc.cleanup_dead_nodes();
    if removed + failed > 0 {
        tracing::info!(removed, failed, "removed iceoryx2 resources of dead processes at start");
    }
    let start_ns = monotonic_ns();
    let mut ports = Vec::with_capacity(config.cameras.len());
    let mut states = Vec::with_capacity(config.cameras.len());
    for name in &config.cameras {
        ports.push(CameraPorts::open(&ipc, name)?);
        let mut engine = PoseEngine::new(spec)?;
        engine.set_deadline_aware(config.estimator.deadline_aware);
        states.push(CameraState::new(name, engine, config.deadline_ns(), start_ns));
    }
    // After the engines: their worker threads were started unpinned (they pin themselves).
    if let Some(&cpu) = config.estimator.pin_cpus.first() {
        fusepose_estimator::cpu_pin::pin_current_thread(cpu).map_err(|e| {
            anyhow::anyhow!(
                "estimator.pin_cpus = {:?}: cannot pin the loop thread to CPU {cpu}: {e}",
                config.estimator.pin_cpus
            )
        })?;
    }
    let mut hlog = if config.stats.hlog_path.as_os_str().is_empty() {
        None
    } else {
        let comment = format!("fuseposed interval log; cameras {:?}; estimator {}", config.cameras, spec.description);
        Some(IntervalLog::create(&config.stats.hlog_path, start_ns, &comment).map_err(|e| {
            anyhow::anyhow!("stats.hlog_path = {:?}: {e}", config.stats.hlog_path.display().to_string())
        })?)
    };

    let waitset = WaitSetBuilder::new()
        .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
        .create::<ipc::Service>()
        .map_err(|e| anyhow::anyhow!("cannot create the WaitSet: {e:?}"))?;
    let mut frame_guards = Vec::with_capacity(ports.len());
    for p in &ports {
        frame_guards
            .push(waitset.attach_notification(&p.frame_listener).map_err(|e| anyhow::anyhow!("WaitSet: {e:?}"))?);
    }
    let tick = waitset
        .attach_interval(Duration::from_millis(config.ipc.tick_ms))
        .map_err(|e| anyhow::anyhow!("WaitSet: {e:?}"))?;

    if let Some(cost) = &spec.startup_cost {
        tracing::info!("budget: {}", cost.describe(config.deadline_ms));
    }
    tracing::info!(
        cameras = ?config.cameras,
        estimator = %spec.description,
        deadline_ms = config.deadline_ms,
        hlog = %config.stats.hlog_path.display(),
        "fuseposed ready"
    );

    let window_ns = seconds_to_ns(config.stats.window_s);
    let summary_ns = seconds_to_ns(config.stats.summary_interval_s);
    let cleanup_ns = seconds_to_ns(config.ipc.cleanup_interval_s);
    let (mut last_summary, mut last_cleanup) = (start_ns, start_ns);
    let mut fired = vec![false; ports.len()];
    // Spin-then-wait (client library): poll the frame queues from shortly
    // before a frame is due, saving the event wake-up — only when this loop
    // thread is pinned (`estimator.pin_cpus`); unpinned it gains nothing.
    let spin = Duration::from_micros(config.ipc.receive_spin_us);
    let strategy =
        if spin.is_zero() { WaitStrategy::Block } else { WaitStrategy::SpinIfPinned { margin: spin }.resolve() };
    let mut arrivals = vec![ArrivalPredictor::default(); ports.len()];
    loop {
        let mut ticked = false;
        fired.iter_mut().for_each(|f| *f = false);
        let now = monotonic_ns();
        let (mut spin_until, mut block_until) = (0u64, u64::MAX);
        for a in &arrivals {
            match a.plan(strategy, now) {
                WaitPlan::SpinUntil(t) => spin_until = spin_until.max(t),
                WaitPlan::BlockUntil(t) => block_until = block_until.min(t),
                WaitPlan::Block => {}
            }
        }
        if spin_until > now
            && let Some(i) = poll_frames(&ports, spin_until)
        {
            arrivals[i].observe(monotonic_ns());
            let _ = ports[i].frame_listener.try_wait(|_| {});
            states[i].process_newest(&ports[i]);
            continue;
        }
        let on_event = |id: WaitSetAttachmentId<ipc::Service>| {
            if id.has_event_from(&tick) {
                ticked = true;
            }
            for (i, guard) in frame_guards.iter().enumerate() {
                if id.has_event_from(guard) {
                    fired[i] = true;
                }
            }
            CallbackProgression::Continue
        };
        let now = monotonic_ns();
        let result = if block_until == u64::MAX {
            waitset.wait_and_process_once(on_event)
        } else {
            // The WaitSet (epoll) rounds time-outs up to whole milliseconds
            // (+80 µs measured): round down so it wakes before the spin window.
            // Under a millisecond: a plain sleep (high-resolution timer) to the spin window.
            let left_ns = block_until.saturating_sub(now);
            if left_ns < 1_000_000 {
                std::thread::sleep(Duration::from_nanos(left_ns));
                let woke = monotonic_ns();
                arrivals.iter_mut().for_each(|a| a.record_wake(block_until, woke));
                continue;
            }
            waitset.wait_and_process_once_with_timeout(on_event, Duration::from_millis(left_ns / 1_000_000))
        };
        match result {
            Ok(WaitSetRunResult::TerminationRequest) => {
                tracing::info!("termination requested (SIGINT/SIGTERM)");
                break;
            }
            // EINTR (e.g. SIGSTOP/SIGCONT); a SIGINT/SIGTERM is reported on the next call.
            Ok(WaitSetRunResult::Interrupt) => continue,
            Ok(_) => {}
            Err(e) => anyhow::bail!("WaitSet failed: {e:?}"),
        }
        let woke_ns = monotonic_ns();
        for (i, p) in ports.iter().enumerate() {
            if fired[i] {
                arrivals[i].observe(woke_ns);
            }
            if fired[i] || ticked {
                // Consume the wake-ups; the subscriber is drained below either way.
                let _ = p.frame_listener.try_wait(|_| {});
                states[i].process_newest(p);
            }
        }
        if !ticked {
            continue;
        }
        let now = monotonic_ns();
        for (p, s) in ports.iter().zip(states.iter_mut()) {
            s.serve_stats(p);
            s.report_suppressed(now);
        }
        if now.saturating_sub(states[0].latency.window_start_ns) >= window_ns {
            write_windows(&mut hlog, &states, now);
            states.iter_mut().for_each(|s| s.latency.rotate(now));
        }
        if summary_ns > 0 && now.saturating_sub(last_summary) >= summary_ns {
            last_summary = now;
            for s in &states {
                tracing::info!(camera = %s.name, "{}", s.summary_line(true));
            }
        }
        if now.saturating_sub(last_cleanup) >= cleanup_ns {
            last_cleanup = now;
            let (removed, failed) = ipc.cleanup_dead_nodes();
            if removed + failed > 0 {
                tracing::info!(removed, failed, "removed iceoryx2 resources of dead processes");
            }
        }
        if stop.as_ref().is_some_and(|s| s.load(Ordering::Relaxed)) {
            tracing::info!("stop requested");
            break;
        }
    }

    let end = monotonic_ns();
    write_windows(&mut hlog, &states, end);
    // Suppressed lines not reported yet, whether or not their second is over.
    states.iter_mut().for_each(|s| s.report_suppressed(end.saturating_add(LOG_FLUSH_NS)));
    for s in &states {
        tracing::info!(camera = %s.name, "final: {}", s.summary_line(false));
        let names = Stage::timeline_names();
        for (timeline, summary) in s.latency.since_start.summaries().iter().enumerate() {
            if summary.count > 0 {
                tracing::info!(
                    camera = %s.name,
                    "final {:<12} n={:<7} p50 {:>9.3} ms  p90 {:>9.3} ms  p99 {:>9.3} ms  p99.9 {:>9.3} ms  max {:>9.3} ms",
                    names[timeline],
                    summary.count,
                    summary.p50_ns as f64 / 1e6,
                    summary.p90_ns as f64 / 1e6,
                    summary.p99_ns as f64 / 1e6,
                    summary.p999_ns as f64 / 1e6,
                    summary.max_ns as f64 / 1e6,
                );
            }
        }
    }
    let hlog_path = hlog.as_ref().map(|l| l.path().to_owned());
    drop(hlog);
    drop(frame_guards);
    drop(tick);
    drop(locks);
    Ok(RunReport { cameras: states.iter().map(|s| (s.name.clone(), s.counters.clone())).collect(), hlog_path })
}
