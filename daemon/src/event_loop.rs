//! The daemon loop: an iceoryx2 WaitSet woken by frame events and a periodic
//! tick; pending frames of all cameras run earliest deadline first
//! (`schedule`); SIGHUP reloads the camera list (`reload`); SIGINT/SIGTERM
//! end it cleanly with a final summary and `.hlog`.

use std::path::PathBuf;
use std::rc::Rc;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use fusepose_client::{ArrivalPredictor, Ipc, Stage, WaitPlan, WaitStrategy, monotonic_ns, poll_until};
use iceoryx2::prelude::*;
use iceoryx2::waitset::{WaitSetAttachmentId, WaitSetRunResult};

use crate::camera::CameraPorts;
use crate::camera_set::{Camera, EngineCatalog, lock_camera};
use crate::cell_output::{CameraShares, CellOutput};
use crate::config::DaemonConfig;
use crate::engine::EngineSpec;
use crate::interval_log::IntervalLog;
use crate::reload::ReloadContext;
use crate::schedule::{earliest_deadline, leave_room_for, slice_ns};

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

fn write_windows(log: &mut Option<IntervalLog>, cameras: &[Camera], end_ns: u64) {
    let Some(log) = log.as_mut() else { return };
    let names = fusepose_client::Stage::timeline_names();
    for state in cameras.iter().map(|c| &c.state) {
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
fn poll_frames(ports: &[Rc<CameraPorts>], until_ns: u64) -> Option<usize> {
    let ready = || Ok::<_, ()>(ports.iter().position(|p| p.frames.has_samples().unwrap_or(false)));
    poll_until(until_ns, true, ready).unwrap_or(None)
}

/// How the daemon is run besides its configuration.
#[derive(Default)]
pub struct RunOptions {
    /// Ends the loop when it becomes true (embedding, tests).
    pub stop: Option<Arc<AtomicBool>>,
    /// Re-read on SIGHUP: cameras are added, removed or changed without
    /// dropping the others (None: SIGHUP is not handled).
    pub config_path: Option<PathBuf>,
}

/// Runs the daemon until SIGINT/SIGTERM (or `stop` becomes true).
pub fn run(config: &DaemonConfig, spec: &EngineSpec, stop: Option<Arc<AtomicBool>>) -> anyhow::Result<RunReport> {
    run_with(config, spec, RunOptions { stop, config_path: None })
}

/// Processes pending frames, earliest deadline first, at most one per camera
/// (then the loop looks at its events: ticks, stats, termination); after
/// each frame the cell output is refreshed and every camera drained again
/// (newer frames replace the pending ones).
fn run_due(cameras: &mut [Camera], cell: &mut Option<CellOutput>) {
    for _ in 0..cameras.len() {
        let Some(i) = earliest_deadline(cameras.iter().map(|c| c.state.pending_deadline_ns())) else { return };
        let now = monotonic_ns();
        let active = cameras.iter().filter(|c| c.state.clock.is_active(now)).count();
        let mut slice_end = slice_ns(cameras[i].state.clock.period_ns(), active).map(|s| now + s);
        // Leave room for the other cameras' next frames (pending or about to
        // arrive) that are due before this one would end.
        if let Some(end) = slice_end.as_mut() {
            let own_min = cameras[i].state.min_frame_cost_ns();
            for (j, c) in cameras.iter().enumerate() {
                if j == i || !c.state.clock.is_active(now) {
                    continue;
                }
                if let Some(d) = c.state.next_deadline_ns() {
                    *end = (*end).min(leave_room_for(now, own_min, d, c.state.min_frame_cost_ns()));
                }
            }
        }
        let cam = &mut cameras[i];
        if cam.state.process_pending(&cam.ports, slice_end)
            && let Some(cell) = cell.as_mut()
        {
            cell.publish(cameras, i);
        }
        for c in cameras.iter_mut() {
            c.state.drain(&c.ports);
        }
    }
}

/// Why an epoch of the loop (one set of WaitSet attachments) ended.
enum EpochEnd {
    Stop,
    Reload,
}

/// Runs the daemon until SIGINT/SIGTERM, `options.stop`, or a fatal error.
pub fn run_with(config: &DaemonConfig, spec: &EngineSpec, options: RunOptions) -> anyhow::Result<RunReport> {
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
    let settings = config.camera_settings();
    let mut locks = Vec::with_capacity(settings.len());
    for s in &settings {
        locks.push(lock_camera(&root, &prefix, &node, &s.name)?);
    }
    let (removed, failed) = ipc.cleanup_dead_nodes();
    if removed + failed > 0 {
        tracing::info!(removed, failed, "removed iceoryx2 resources of dead processes at start");
    }
    let start_ns = monotonic_ns();
    let main_objects = Rc::new(crate::engine::load_objects(&config.estimator)?);
    let mut catalog = EngineCatalog::new(&config.estimator, spec, main_objects.clone());
    let mut cameras = Vec::with_capacity(settings.len());
    for (s, lock) in settings.iter().zip(locks) {
        cameras.push(Camera::open(&ipc, lock, s, &mut catalog, start_ns)?);
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
    let names = config.camera_names();
    let mut hlog = if config.stats.hlog_path.as_os_str().is_empty() {
        None
    } else {
        let comment = format!("fuseposed interval log; cameras {names:?}; estimator {}", spec.description);
        Some(IntervalLog::create(&config.stats.hlog_path, start_ns, &comment).map_err(|e| {
            anyhow::anyhow!("stats.hlog_path = {:?}: {e}", config.stats.hlog_path.display().to_string())
        })?)
    };
    let mut cell = CellOutput::open(&ipc, config, &catalog);

    let waitset = WaitSetBuilder::new()
        .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
        .create::<ipc::Service>()
        .map_err(|e| anyhow::anyhow!("cannot create the WaitSet: {e:?}"))?;
    let tick = waitset
        .attach_interval(Duration::from_millis(config.ipc.tick_ms))
        .map_err(|e| anyhow::anyhow!("WaitSet: {e:?}"))?;
    let reload_requested = Arc::new(AtomicBool::new(false));
    if options.config_path.is_some() {
        signal_hook::flag::register(signal_hook::consts::SIGHUP, reload_requested.clone())
            .map_err(|e| anyhow::anyhow!("cannot handle SIGHUP (configuration reload): {e}"))?;
    }

    if let Some(cost) = &spec.startup_cost {
        tracing::info!("budget: {}", cost.describe(config.deadline_ms));
    }
    tracing::info!(
        cameras = ?names,
        estimator = %spec.description,
        deadline_ms = config.deadline_ms,
        hlog = %config.stats.hlog_path.display(),
        cell = cell.is_some(),
        "fuseposed ready"
    );

    let mut running = config.clone();
    let window_ns = seconds_to_ns(config.stats.window_s);
    let summary_ns = seconds_to_ns(config.stats.summary_interval_s);
    let cleanup_ns = seconds_to_ns(config.ipc.cleanup_interval_s);
    let (mut last_summary, mut last_cleanup, mut window_start) = (start_ns, start_ns, start_ns);
    let mut shares = CameraShares::new(start_ns);
    // Spin-then-wait (client library): poll the frame queues from shortly
    // before a frame is due, saving the event wake-up — only when this loop
    // thread is pinned (`estimator.pin_cpus`); unpinned it gains nothing.
    let spin = Duration::from_micros(config.ipc.receive_spin_us);
    let strategy =
        if spin.is_zero() { WaitStrategy::Block } else { WaitStrategy::SpinIfPinned { margin: spin }.resolve() };
    loop {
        // One epoch per camera set: the WaitSet attachments borrow this epoch's ports.
        let ports: Vec<Rc<CameraPorts>> = cameras.iter().map(|c| c.ports.clone()).collect();
        let mut frame_guards = Vec::with_capacity(ports.len());
        for p in &ports {
            frame_guards
                .push(waitset.attach_notification(&p.frame_listener).map_err(|e| anyhow::anyhow!("WaitSet: {e:?}"))?);
        }
        let mut fired = vec![false; ports.len()];
        let mut arrivals = vec![ArrivalPredictor::default(); ports.len()];
        let end = loop {
            if reload_requested.swap(false, Ordering::Relaxed) {
                break EpochEnd::Reload;
            }
            let mut ticked = false;
            fired.iter_mut().for_each(|f| *f = false);
            // Frames already waiting: look at the events without blocking, then serve them.
            let busy = cameras.iter().any(|c| c.state.pending_deadline_ns().is_some());
            let now = monotonic_ns();
            let (mut spin_until, mut block_until) = (0u64, if busy { now } else { u64::MAX });
            for a in arrivals.iter().filter(|_| !busy) {
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
                cameras[i].state.drain(&ports[i]);
                run_due(&mut cameras, &mut cell);
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
            let result = if busy {
                waitset.wait_and_process_once_with_timeout(on_event, Duration::ZERO)
            } else if block_until == u64::MAX {
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
                    break EpochEnd::Stop;
                }
                // EINTR (e.g. SIGSTOP/SIGCONT, SIGHUP); a SIGINT/SIGTERM is reported on the next call.
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
                    // Consume the wake-ups; the subscriber is drained either way.
                    let _ = p.frame_listener.try_wait(|_| {});
                    cameras[i].state.drain(p);
                }
            }
            run_due(&mut cameras, &mut cell);
            if !ticked {
                continue;
            }
            let now = monotonic_ns();
            for c in cameras.iter_mut() {
                c.state.serve_stats(&c.ports);
                c.state.report_suppressed(now);
            }
            if now.saturating_sub(window_start) >= window_ns {
                write_windows(&mut hlog, &cameras, now);
                cameras.iter_mut().for_each(|c| c.state.latency.rotate(now));
                window_start = now;
            }
            if summary_ns > 0 && now.saturating_sub(last_summary) >= summary_ns {
                last_summary = now;
                for c in &cameras {
                    tracing::info!(camera = %c.state.name, "{}", c.state.summary_line(true));
                }
                if cameras.len() > 1 {
                    tracing::info!("{}", shares.line(&cameras, now));
                }
            }
            if now.saturating_sub(last_cleanup) >= cleanup_ns {
                last_cleanup = now;
                let (removed, failed) = ipc.cleanup_dead_nodes();
                if removed + failed > 0 {
                    tracing::info!(removed, failed, "removed iceoryx2 resources of dead processes");
                }
            }
            if options.stop.as_ref().is_some_and(|s| s.load(Ordering::Relaxed)) {
                tracing::info!("stop requested");
                break EpochEnd::Stop;
            }
        };
        drop(frame_guards);
        drop(ports);
        match end {
            EpochEnd::Stop => break,
            EpochEnd::Reload => {
                let Some(path) = options.config_path.as_deref() else { continue };
                let ctx = ReloadContext { ipc: &ipc, root: &root, prefix: &prefix, node: &node };
                if let Some(new) = crate::reload::reload(path, &running, &mut cameras, &mut catalog, &ctx) {
                    running = new;
                    if let Some(c) = cell.as_mut() {
                        c.configure(&running.cell, &catalog);
                    }
                }
            }
        }
    }

    let end = monotonic_ns();
    write_windows(&mut hlog, &cameras, end);
    // Suppressed lines not reported yet, whether or not their second is over.
    cameras.iter_mut().for_each(|c| c.state.report_suppressed(end.saturating_add(LOG_FLUSH_NS)));
    for s in cameras.iter().map(|c| &c.state) {
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
    drop(tick);
    Ok(RunReport {
        cameras: cameras.iter().map(|c| (c.state.name.clone(), c.state.counters.clone())).collect(),
        hlog_path,
    })
}
