//! One camera in the daemon: its iceoryx2 ports, counters, histograms and
//! estimator, and the per-frame path drain → validate → estimate → publish.

use fusepose_client::{
    CameraServices, FRAME_MAGIC, FrameHeader, InvalidReason, Ipc, MAX_OBJECTS, PoseFlags, PoseMessage, PoseStatus,
    STAGE_COUNT, Stage, StatsRequest, StatsSnapshot, WireObjectPose, decode_frame, monotonic_ns,
};
use fusepose_estimator::verify::Verification;
use fusepose_estimator::{FrameError, ObjectPose};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::server::Server;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::sample::Sample;

use crate::confirm::Confirmations;
use crate::counters::{FrameCounters, SequenceEvent, SequenceTracker};
use crate::engine::{EngineFailure, PoseEngine, StageTimes};
use crate::frame_view::to_frame_view;
use crate::latency::{END_TO_END, LatencyBook};
use crate::rate_limited_log::{RateLimit, RateLimitByKind};
use crate::schedule::CameraClock;
use crate::stable_ids::StableIds;

const LOG_INTERVAL_NS: u64 = 1_000_000_000;

/// How far a frame's capture time may lie ahead of the daemon's clock. Both
/// read the same CLOCK_MONOTONIC, so any real frame is behind; more than this
/// means the producer stamps with another clock (e.g. wall time).
pub const MAX_CAPTURE_AHEAD_NS: u64 = 1_000_000;
/// Kept free after the estimate for publishing, with 1 ms for scheduling
/// jitter (replays of the tuning split ran up to 0.5 ms late with 0.3 ms;
/// docs/BENCHMARKS.md, "Instance budget").
const PUBLISH_MARGIN_NS: u64 = 1_300_000;

/// Oldest capture time still processed: a pose of an older frame is no use to
/// a controller (the daemon was stalled, or the producer stamps 0 / another clock).
pub const MAX_CAPTURE_AGE_NS: u64 = 2_000_000_000;

/// The ports of one camera, owned by the loop thread (iceoryx2 ipc ports are not Send).
pub struct CameraPorts {
    pub services: CameraServices,
    pub frames: Subscriber<ipc::Service, [u8], FrameHeader>,
    pub frame_listener: Listener<ipc::Service>,
    pub poses: Publisher<ipc::Service, PoseMessage, ()>,
    pub pose_notifier: Notifier<ipc::Service>,
    pub stats: Server<ipc::Service, StatsRequest, (), StatsSnapshot, ()>,
}

impl CameraPorts {
    pub fn open(ipc: &Ipc, camera: &str) -> anyhow::Result<Self> {
        let services = CameraServices::open(ipc, camera)?;
        // Typed errors (capacity limits name the service, the limit, the cause and the fix).
        let frames = services.frame_subscriber()?;
        let frame_listener = services.frame_listener()?;
        let poses = services.pose_publisher()?;
        let pose_notifier = services.pose_notifier()?;
        let stats = services.stats_server()?;
        Ok(Self { services, frames, frame_listener, poses, pose_notifier, stats })
    }
}

/// A camera's newest received frame, waiting for its turn on the loop.
struct Pending {
    sample: Sample<ipc::Service, [u8], FrameHeader>,
    sequence: SequenceEvent,
}

/// Everything the daemon knows about one camera, besides its ports.
pub struct CameraState {
    pub name: String,
    pub camera_id: u32,
    pub counters: FrameCounters,
    pub latency: LatencyBook,
    pub engine: PoseEngine,
    sequence: SequenceTracker,
    /// Whether the last estimated frame's colour was corrected before the
    /// networks (auto exposure or white balance); a change is logged.
    colour_corrected: bool,
    deadline_ns: u64,
    started_ns: u64,
    /// Per rejection reason: a burst of one kind never hides another.
    invalid_log: RateLimitByKind,
    transport_log: RateLimit,
    estimator_log: RateLimit,
    /// Largest label id producers may send (the object set's classes; 0 = any).
    label_classes: u16,
    pending: Option<Pending>,
    /// Frame period and activity, for the scheduler.
    pub clock: CameraClock,
    /// The last pose message published (the cell output reads it).
    pub last_message: PoseMessage,
    /// Loop time spent on this camera's frames since start, ns.
    pub busy_ns: u64,
    /// Tracking mode: instance ids that stay with their object from frame to frame.
    stable_ids: Option<StableIds>,
    /// Marks poses the previous frame saw too ([`PoseFlags::CONFIRMED`]).
    confirmations: Confirmations,
}

/// A pose on the wire, with its verification when the daemon verifies
/// (`fit_score` and `depth_residual_m` NaN and [`PoseFlags::VERIFIED`] clear otherwise).
fn wire_pose(p: &ObjectPose, verdict: Option<&Verification>, flags: u16) -> WireObjectPose {
    let q = p.rotation.as_ref().coords; // [x, y, z, w]
    debug_assert!(pose_is_finite(p));
    WireObjectPose {
        class_id: p.class_id,
        instance_id: p.instance_id,
        refine_iterations: p.iterations,
        flags: flags | if verdict.is_some_and(|v| v.passed) { PoseFlags::VERIFIED } else { 0 },
        confidence: p.confidence,
        mask_pixels: p.mask_pixels,
        bbox: p.bbox,
        quaternion: [q.x, q.y, q.z, q.w],
        translation_m: [p.translation.x, p.translation.y, p.translation.z],
        fit_score: verdict.map_or(f32::NAN, |v| v.fit),
        depth_residual_m: verdict.map_or(f32::NAN, |v| v.depth_residual_m),
    }
}

/// Whether every number a pose puts on the wire is finite.
fn pose_is_finite(p: &ObjectPose) -> bool {
    p.rotation.as_ref().coords.iter().all(|v| v.is_finite())
        && p.translation.iter().all(|v| v.is_finite())
        && p.confidence.is_finite()
}

/// The stats reason of a frame-content refusal (the rest are the estimator's own).
fn content_reason(e: &FrameError) -> InvalidReason {
    match e {
        FrameError::DepthEmpty => InvalidReason::DepthEmpty,
        FrameError::DepthNonFinite { .. } => InvalidReason::DepthNonFinite,
        FrameError::LabelOutOfRange { .. } => InvalidReason::LabelOutOfRange,
        FrameError::InstanceBeyondTable { .. } => InvalidReason::InstanceBeyondTable,
        FrameError::InstanceClassUnknown { .. } => InvalidReason::InstanceClassUnknown,
        _ => InvalidReason::EstimatorRefused,
    }
}

/// Refuses a capture time ahead of `received_ns` or older than [`MAX_CAPTURE_AGE_NS`].
fn check_capture_time(capture_ns: u64, received_ns: u64) -> Result<(), (InvalidReason, String)> {
    if capture_ns > received_ns.saturating_add(MAX_CAPTURE_AHEAD_NS) {
        let ahead = (capture_ns - received_ns) as f64 / 1e6;
        return Err((
            InvalidReason::CaptureInFuture,
            format!("capture time {ahead:.3} ms ahead of the daemon's clock"),
        ));
    }
    let age = received_ns.saturating_sub(capture_ns);
    if age > MAX_CAPTURE_AGE_NS {
        return Err((InvalidReason::CaptureTooOld, format!("capture time {:.3} s old", age as f64 / 1e9)));
    }
    Ok(())
}

impl CameraState {
    pub fn new(name: &str, engine: PoseEngine, deadline_ns: u64, now_ns: u64) -> Self {
        let label_classes = engine.label_classes();
        Self {
            name: name.to_owned(),
            camera_id: fusepose_client::camera_id(name),
            counters: FrameCounters::default(),
            latency: LatencyBook::new(now_ns),
            engine,
            sequence: SequenceTracker::default(),
            colour_corrected: false,
            deadline_ns,
            started_ns: now_ns,
            invalid_log: RateLimitByKind::new(LOG_INTERVAL_NS, InvalidReason::COUNT),
            transport_log: RateLimit::new(LOG_INTERVAL_NS),
            estimator_log: RateLimit::new(LOG_INTERVAL_NS),
            label_classes,
            pending: None,
            clock: CameraClock::default(),
            last_message: PoseMessage::default(),
            busy_ns: 0,
            stable_ids: None,
            confirmations: Confirmations::new(crate::config::DEFAULT_CONFIRM_WITHIN_M, 1, label_classes),
        }
    }

    /// How near (metres; 0 = never) a pose of how many of the last frames confirms one.
    pub fn set_confirmation(&mut self, within_m: f64, frames: u32) {
        self.confirmations = Confirmations::new(within_m, frames, self.label_classes);
    }

    /// Publishes instance ids that stay with their object (tracking mode); `None`: per-frame indices.
    pub fn set_stable_ids(&mut self, ids: Option<StableIds>) {
        self.stable_ids = ids;
    }

    /// Changes the budget (configuration reload).
    pub fn set_deadline_ns(&mut self, deadline_ns: u64) {
        self.deadline_ns = deadline_ns;
    }

    /// Replaces the estimator side (configuration reload); counters and histograms stay.
    pub fn replace_engine(&mut self, engine: PoseEngine) {
        self.label_classes = engine.label_classes();
        self.engine = engine;
    }

    /// The least time a frame of this camera takes, ns, from its last posed
    /// frame: ingest, segmentation, sampling, one object of the network, and
    /// the publish margin (0 before the first posed frame).
    pub fn min_frame_cost_ns(&self) -> u64 {
        let m = &self.last_message;
        if m.status & PoseStatus::OK == 0 {
            return 0;
        }
        let t = |s: Stage| m.stage_ns[s as usize];
        let objects = (m.object_count as u64).max(1);
        t(Stage::Ingest) + t(Stage::Segmentation) + t(Stage::Sampling) + t(Stage::Network) / objects + PUBLISH_MARGIN_NS
    }

    /// The deadline of this camera's next frame: the pending one's, else the
    /// one expected next (capture learned from its period), ns.
    pub fn next_deadline_ns(&self) -> Option<u64> {
        self.pending_deadline_ns().or_else(|| Some(self.clock.next_capture_ns()?.saturating_add(self.deadline_ns)))
    }

    /// Deadline of the frame waiting for its turn (capture + budget), ns.
    pub fn pending_deadline_ns(&self) -> Option<u64> {
        self.pending.as_ref().map(|p| p.sample.user_header().capture_time_ns.saturating_add(self.deadline_ns))
    }

    /// Drains the frame subscriber keeping only the newest frame, processes it
    /// and publishes its pose message. Returns whether a frame was processed.
    pub fn process_newest(&mut self, ports: &CameraPorts) -> bool {
        self.drain(ports);
        self.process_pending(ports, None)
    }

    /// Takes every waiting frame from the subscriber and keeps the newest
    /// (with the one already pending) for [`CameraState::process_pending`];
    /// older ones count as skipped stale. Returns whether a frame is pending.
    pub fn drain(&mut self, ports: &CameraPorts) -> bool {
        let mut newest = self.pending.take().map(|p| (p.sample, p.sequence));
        loop {
            match ports.frames.receive() {
                Ok(Some(sample)) => {
                    let header = sample.user_header();
                    let mut event = SequenceEvent::InOrder;
                    if header.magic == FRAME_MAGIC {
                        event = self.sequence.observe(sample.header().publisher_id().value(), header.sequence);
                        match event {
                            SequenceEvent::InOrder | SequenceEvent::Regression { .. } => {}
                            SequenceEvent::Gap { missed } => self.counters.missed_sequence += missed,
                            SequenceEvent::Restart => {
                                self.counters.producer_restarts += 1;
                                tracing::info!(camera = %self.name, sequence = header.sequence, "frames from a new publisher (producer restarted)");
                            }
                        }
                        self.clock.observe(header.capture_time_ns, monotonic_ns());
                    }
                    // A frame counts as received once handled: processed, or
                    // replaced here by a newer one (stale), so that received =
                    // processed + stale + refused holds at every stats query.
                    if newest.replace((sample, event)).is_some() {
                        self.counters.received += 1;
                        self.counters.skipped_stale += 1;
                    }
                }
                Ok(None) => break,
                Err(e) => {
                    if let Some(suppressed) = self.transport_log.allow(monotonic_ns()) {
                        tracing::warn!(camera = %self.name, error = ?e, suppressed, "receiving frames failed");
                    }
                    break;
                }
            }
        }
        self.pending = newest.map(|(sample, sequence)| Pending { sample, sequence });
        self.pending.is_some()
    }

    /// Processes the pending frame, if any, and publishes its pose message;
    /// with `slice_end_ns` the estimator also fits the frame into the time
    /// before it (the camera's share of the loop). Returns whether a frame was processed.
    pub fn process_pending(&mut self, ports: &CameraPorts, slice_end_ns: Option<u64>) -> bool {
        let Some(Pending { sample, sequence: newest_sequence }) = self.pending.take() else { return false };
        self.counters.received += 1;
        let received_ns = monotonic_ns();
        let header = *sample.user_header();
        let mut times: StageTimes = [0; STAGE_COUNT];
        let mut msg = PoseMessage {
            camera_id: self.camera_id,
            frame_sequence: header.sequence,
            capture_time_ns: header.capture_time_ns,
            received_time_ns: received_ns,
            ..PoseMessage::default()
        };
        let mut valid = false;
        match decode_frame(&header, sample.payload(), Some(self.camera_id)) {
            Err(rejection) => {
                times[Stage::Ingest as usize] = monotonic_ns() - received_ns;
                self.reject(&mut msg, rejection.reason(), &rejection);
            }
            Ok(planes) => {
                let view = to_frame_view(&planes);
                let checked = self.check_stream(newest_sequence, &header, received_ns).and_then(|()| {
                    view.check_content(self.label_classes).map(|_| ()).map_err(|e| (content_reason(&e), e.to_string()))
                });
                times[Stage::Ingest as usize] = monotonic_ns() - received_ns;
                match checked {
                    Err((reason, detail)) => self.reject(&mut msg, reason, &detail),
                    Ok(()) => valid = self.estimate(&view, &header, slice_end_ns, &mut msg, &mut times),
                }
            }
        }
        drop(sample); // give the frame back before publishing
        self.publish(ports, msg, times, valid);
        self.busy_ns += monotonic_ns().saturating_sub(received_ns);
        true
    }

    /// Sequence and capture-time checks of a decoded frame.
    fn check_stream(
        &self,
        sequence: SequenceEvent,
        header: &FrameHeader,
        received_ns: u64,
    ) -> Result<(), (InvalidReason, String)> {
        if let SequenceEvent::Regression { last } = sequence {
            let detail =
                format!("sequence {} after {last} from the same publisher (repeated or backwards)", header.sequence);
            return Err((InvalidReason::SequenceRegression, detail));
        }
        check_capture_time(header.capture_time_ns, received_ns)
    }

    /// Logs when the camera's frames start or stop being corrected before the
    /// networks (a dim or tinted camera), once per change, not per frame.
    fn log_colour_correction(&mut self, sequence: u64) {
        let gain = self.engine.exposure_gain();
        let balance = self.engine.white_balance_gains();
        let corrected = gain > 1.0 || balance != [1.0; 3];
        if corrected != self.colour_corrected {
            self.colour_corrected = corrected;
            if corrected {
                tracing::info!(camera = %self.name, sequence, exposure_gain = gain, white_balance_gains = ?balance,
                    "frames are dim or tinted: colour corrected before the networks (estimator.auto_exposure / white_balance)");
            } else {
                tracing::info!(camera = %self.name, sequence, "frames well exposed again: colour no longer corrected");
            }
        }
    }

    /// Runs the engine on a checked frame and fills `msg`; returns whether
    /// the frame counts as processed (OK or estimator failure, not refused).
    fn estimate(
        &mut self,
        view: &fusepose_estimator::FrameView<'_>,
        header: &FrameHeader,
        slice_end_ns: Option<u64>,
        msg: &mut PoseMessage,
        times: &mut StageTimes,
    ) -> bool {
        // The estimator fits its work into what is left of the deadline, minus
        // the publish margin (and, once the frame's instances are known, the
        // verification they will take: `PoseEngine::run`).
        let reserve_ns = PUBLISH_MARGIN_NS;
        let end_ns = header.capture_time_ns.saturating_add(self.deadline_ns).min(slice_end_ns.unwrap_or(u64::MAX));
        let left_ns = end_ns.saturating_sub(monotonic_ns() + reserve_ns);
        self.engine.set_deadline(Some(std::time::Instant::now() + std::time::Duration::from_nanos(left_ns)));
        // A panic inside the estimator on odd input must not take the daemon down.
        let engine = &mut self.engine;
        let outcome =
            std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| engine.run(view, header.sequence, times)))
                .unwrap_or(Err(EngineFailure::Panicked));
        match outcome {
            Ok(()) => {
                self.log_colour_correction(header.sequence);
                // The frame's own instance plane defined every mask (unless the segmenter replaced it).
                let from_instances = view.labels.is_some_and(|l| l.is_instances()) && self.engine.uses_frame_labels();
                let flags = if from_instances { PoseFlags::FROM_INSTANCE_LABELS } else { 0 };
                let poses = self.engine.poses();
                // Non-finite poses (e.g. a network fed extreme input) are never published.
                let mut finite = 0;
                let verdicts = self.engine.verdicts();
                for (i, pose) in poses.iter().enumerate().filter(|(_, p)| pose_is_finite(p)).take(MAX_OBJECTS) {
                    msg.objects[finite] = wire_pose(pose, verdicts.get(i), flags);
                    finite += 1;
                }
                let non_finite = poses.iter().filter(|p| !pose_is_finite(p)).count();
                let engine = &self.engine;
                if let Some(ids) = self.stable_ids.as_mut() {
                    ids.assign(&mut msg.objects[..finite], |class_id| engine.class_shed(class_id));
                }
                self.confirmations.mark(&mut msg.objects[..finite], |class_id| engine.class_shed(class_id));
                msg.object_count = finite as u16;
                msg.status = PoseStatus::OK;
                if self.engine.degraded() {
                    msg.status |= PoseStatus::DEGRADED;
                }
                if poses.len() - non_finite > MAX_OBJECTS {
                    msg.status |= PoseStatus::DEGRADED;
                }
                self.counters.poses_failed_verification += self.engine.failed_verification() as u64;
                self.counters.objects_shed += self.engine.shed() as u64;
                if non_finite > 0 {
                    self.counters.poses_non_finite += non_finite as u64;
                    msg.status =
                        if finite > 0 { msg.status | PoseStatus::DEGRADED } else { PoseStatus::ESTIMATOR_FAILED };
                    if finite == 0 {
                        self.counters.estimator_failures += 1;
                    }
                    if let Some(suppressed) = self.estimator_log.allow(monotonic_ns()) {
                        tracing::warn!(camera = %self.name, sequence = header.sequence, non_finite, suppressed, "estimator returned non-finite poses; dropped");
                    }
                }
                true
            }
            Err(EngineFailure::Refused(e)) => {
                let reason = content_reason(&e);
                self.reject(msg, reason, &format_args!("{} ({})", e, e.reason()));
                false
            }
            // Estimate, segmentation or a panic: the frame was fine, the engine failed.
            Err(e) => {
                self.confirmations.forget();
                self.counters.estimator_failures += 1;
                msg.status = PoseStatus::ESTIMATOR_FAILED;
                if let Some(suppressed) = self.estimator_log.allow(monotonic_ns()) {
                    tracing::warn!(camera = %self.name, sequence = header.sequence, error = %e, suppressed, "estimator failed");
                }
                true
            }
        }
    }

    fn reject(&mut self, msg: &mut PoseMessage, reason: InvalidReason, detail: &dyn std::fmt::Display) {
        self.confirmations.forget();
        self.counters.count_invalid(reason);
        msg.status = PoseStatus::INVALID_FRAME;
        msg.invalid_reason = reason as u32;
        if let Some(suppressed) = self.invalid_log.allow(reason as usize, monotonic_ns()) {
            tracing::warn!(
                camera = %self.name,
                sequence = msg.frame_sequence,
                reason = reason.name(),
                suppressed,
                "frame rejected: {detail}"
            );
        }
    }

    /// Logs what the rate limits suppressed and no later line reported (called every tick and at exit).
    pub fn report_suppressed(&mut self, now_ns: u64) {
        let camera = &self.name;
        self.invalid_log.take_overdue(now_ns, |kind, n| {
            let reason = InvalidReason::from_code(kind as u32).map_or("unknown", InvalidReason::name);
            tracing::warn!(camera = %camera, reason, suppressed = n, "frames rejected: {n} more frames for {reason} (lines suppressed)");
        });
        if let Some(n) = self.transport_log.take_overdue(now_ns) {
            tracing::warn!(camera = %camera, suppressed = n, "iceoryx2 transfer failures: {n} more (lines suppressed)");
        }
        if let Some(n) = self.estimator_log.take_overdue(now_ns) {
            tracing::warn!(camera = %camera, suppressed = n, "estimator failures: {n} more (lines suppressed)");
        }
    }

    fn publish(&mut self, ports: &CameraPorts, mut msg: PoseMessage, mut times: StageTimes, valid: bool) {
        let start = monotonic_ns();
        msg.published_time_ns = start;
        let end_to_end = msg.published_time_ns.checked_sub(msg.capture_time_ns);
        if valid && end_to_end.is_some_and(|e2e| e2e > self.deadline_ns) {
            msg.status |= PoseStatus::DEADLINE_MISSED;
            self.counters.deadline_misses += 1;
        }
        if msg.status & PoseStatus::DEGRADED != 0 {
            self.counters.frames_degraded += 1;
        }
        times[Stage::Publish as usize] = monotonic_ns() - start;
        msg.stage_ns = times;
        self.last_message = msg;
        let sent = ports
            .poses
            .loan_uninit()
            .map_err(|e| format!("loan: {e:?}"))
            .and_then(|s| s.write_payload(msg).send().map_err(|e| format!("send: {e:?}")))
            .and_then(|_| ports.pose_notifier.notify().map_err(|e| format!("notify: {e:?}")));
        let done = monotonic_ns();
        if let Err(e) = sent
            && let Some(suppressed) = self.transport_log.allow(done)
        {
            tracing::warn!(camera = %self.name, error = %e, suppressed, "publishing poses failed");
        }
        times[Stage::Publish as usize] = done - start;
        for (stage, &ns) in times.iter().enumerate() {
            if ns > 0 || stage == Stage::Ingest as usize || stage == Stage::Publish as usize {
                self.latency.record(stage, ns);
            }
        }
        if valid {
            self.counters.processed += 1;
            if let Some(e2e) = end_to_end {
                self.latency.record(END_TO_END, e2e);
            }
        }
    }

    /// Answers every pending stats request.
    pub fn serve_stats(&mut self, ports: &CameraPorts) {
        loop {
            match ports.stats.receive() {
                Ok(Some(request)) => {
                    let snapshot = self.snapshot(monotonic_ns());
                    if let Err(e) = request.send_copy(snapshot)
                        && let Some(suppressed) = self.transport_log.allow(monotonic_ns())
                    {
                        tracing::warn!(camera = %self.name, error = ?e, suppressed, "answering a stats request failed");
                    }
                }
                Ok(None) => break,
                Err(e) => {
                    if let Some(suppressed) = self.transport_log.allow(monotonic_ns()) {
                        tracing::warn!(camera = %self.name, error = ?e, suppressed, "receiving stats requests failed");
                    }
                    break;
                }
            }
        }
    }

    pub fn snapshot(&self, now_ns: u64) -> StatsSnapshot {
        let c = &self.counters;
        StatsSnapshot {
            camera_id: self.camera_id,
            uptime_ns: now_ns.saturating_sub(self.started_ns),
            window_ns: self.latency.last_window_ns,
            deadline_ns: self.deadline_ns,
            frames_received: c.received,
            frames_processed: c.processed,
            frames_skipped_stale: c.skipped_stale,
            frames_missed_sequence: c.missed_sequence,
            frames_invalid: c.invalid,
            invalid_by_reason: c.invalid_by_reason,
            deadline_misses: c.deadline_misses,
            estimator_failures: c.estimator_failures,
            poses_non_finite: c.poses_non_finite,
            producer_restarts: c.producer_restarts,
            poses_failed_verification: c.poses_failed_verification,
            objects_shed: c.objects_shed,
            frames_degraded: c.frames_degraded,
            since_start: self.latency.since_start.summaries(),
            last_window: self.latency.last_window.summaries(),
            ..StatsSnapshot::default()
        }
    }

    /// One human-readable line: counters and end-to-end percentiles (ms).
    pub fn summary_line(&self, window: bool) -> String {
        let c = &self.counters;
        let (label, e2e) = if window {
            ("window", self.latency.last_window.summary(END_TO_END))
        } else {
            ("since start", self.latency.since_start.summary(END_TO_END))
        };
        let ms = |ns: u64| ns as f64 / 1e6;
        format!(
            "received {} processed {} stale {} missed {} invalid {} deadline_misses {} estimator_failures {} | end-to-end ({label}, {} frames) p50 {:.2} ms p99 {:.2} ms p99.9 {:.2} ms max {:.2} ms",
            c.received,
            c.processed,
            c.skipped_stale,
            c.missed_sequence,
            c.invalid,
            c.deadline_misses,
            c.estimator_failures,
            e2e.count,
            ms(e2e.p50_ns),
            ms(e2e.p99_ns),
            ms(e2e.p999_ns),
            ms(e2e.max_ns),
        )
    }
}
