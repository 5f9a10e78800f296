//! One camera in the daemon: its iceoryx2 ports, counters, histograms and
//! estimator, and the per-frame path drain → validate → estimate → publish.

use fusepose_client::{
    CameraServices, FRAME_MAGIC, FrameHeader, InvalidReason, Ipc, MAX_OBJECTS, PoseMessage, PoseStatus, STAGE_COUNT,
    Stage, StatsRequest, StatsSnapshot, WireObjectPose, decode_frame, monotonic_ns,
};
use fusepose_estimator::ObjectPose;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::server::Server;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;

use crate::counters::{FrameCounters, SequenceEvent, SequenceTracker};
use crate::engine::{EngineFailure, PoseEngine, StageTimes};
use crate::frame_view::to_frame_view;
use crate::latency::{END_TO_END, LatencyBook};
use crate::rate_limited_log::RateLimit;

const LOG_INTERVAL_NS: u64 = 1_000_000_000;

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
        let port = |what: &str, e: &dyn std::fmt::Debug| anyhow::anyhow!("camera {camera}: cannot create {what}: {e:?}");
        let frames = services.frames.subscriber_builder().create().map_err(|e| port("frame subscriber", &e))?;
        let frame_listener = services.frame_events.listener_builder().create().map_err(|e| port("frame listener", &e))?;
        let poses = services.poses.publisher_builder().create().map_err(|e| port("pose publisher", &e))?;
        let pose_notifier = services.pose_events.notifier_builder().create().map_err(|e| port("pose notifier", &e))?;
        let stats = services.stats.server_builder().create().map_err(|e| port("stats server", &e))?;
        Ok(Self { services, frames, frame_listener, poses, pose_notifier, stats })
    }
}

/// Everything the daemon knows about one camera, besides its ports.
pub struct CameraState {
    pub name: String,
    pub camera_id: u32,
    pub counters: FrameCounters,
    pub latency: LatencyBook,
    pub engine: PoseEngine,
    sequence: SequenceTracker,
    deadline_ns: u64,
    started_ns: u64,
    invalid_log: RateLimit,
    transport_log: RateLimit,
    estimator_log: RateLimit,
}

fn wire_pose(p: &ObjectPose) -> WireObjectPose {
    let q = p.rotation.as_ref().coords; // [x, y, z, w]
    WireObjectPose {
        class_id: p.class_id,
        instance_id: p.instance_id,
        refine_iterations: p.iterations,
        _reserved: 0,
        confidence: p.confidence,
        mask_pixels: p.mask_pixels,
        bbox: p.bbox,
        quaternion: [q.x, q.y, q.z, q.w],
        translation_m: [p.translation.x, p.translation.y, p.translation.z],
    }
}

impl CameraState {
    pub fn new(name: &str, engine: PoseEngine, deadline_ns: u64, now_ns: u64) -> Self {
        Self {
            name: name.to_owned(),
            camera_id: fusepose_client::camera_id(name),
            counters: FrameCounters::default(),
            latency: LatencyBook::new(now_ns),
            engine,
            sequence: SequenceTracker::default(),
            deadline_ns,
            started_ns: now_ns,
            invalid_log: RateLimit::new(LOG_INTERVAL_NS),
            transport_log: RateLimit::new(LOG_INTERVAL_NS),
            estimator_log: RateLimit::new(LOG_INTERVAL_NS),
        }
    }

    /// Drains the frame subscriber keeping only the newest frame, processes it
    /// and publishes its pose message. Returns whether a frame was processed.
    pub fn process_newest(&mut self, ports: &CameraPorts) -> bool {
        let mut newest = None;
        loop {
            match ports.frames.receive() {
                Ok(Some(sample)) => {
                    self.counters.received += 1;
                    let header = sample.user_header();
                    if header.magic == FRAME_MAGIC {
                        match self.sequence.observe(header.sequence) {
                            SequenceEvent::InOrder => {}
                            SequenceEvent::Gap { missed } => self.counters.missed_sequence += missed,
                            SequenceEvent::Restart => {
                                self.counters.producer_restarts += 1;
                                tracing::info!(camera = %self.name, sequence = header.sequence, "frame sequence restarted (producer restarted)");
                            }
                        }
                    }
                    if newest.replace(sample).is_some() {
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
        let Some(sample) = newest else { return false };
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
                times[Stage::Ingest as usize] = monotonic_ns() - received_ns;
                // A panic inside the estimator on odd input must not take the daemon down.
                let engine = &mut self.engine;
                let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                    engine.run(&view, header.sequence, &mut times)
                }))
                .unwrap_or(Err(EngineFailure::Panicked));
                match outcome {
                    Ok(()) => {
                        valid = true;
                        msg.status = PoseStatus::OK;
                        let poses = self.engine.poses();
                        let n = poses.len().min(MAX_OBJECTS);
                        for (slot, pose) in msg.objects.iter_mut().zip(&poses[..n]) {
                            *slot = wire_pose(pose);
                        }
                        msg.object_count = n as u16;
                        if poses.len() > MAX_OBJECTS {
                            msg.status |= PoseStatus::DEGRADED;
                        }
                    }
                    Err(EngineFailure::Refused(e)) => {
                        let reason = InvalidReason::EstimatorRefused;
                        self.reject(&mut msg, reason, &format_args!("{} ({})", e, e.reason()));
                    }
                    Err(e @ (EngineFailure::Estimate(_) | EngineFailure::Panicked)) => {
                        valid = true;
                        self.counters.estimator_failures += 1;
                        msg.status = PoseStatus::ESTIMATOR_FAILED;
                        if let Some(suppressed) = self.estimator_log.allow(monotonic_ns()) {
                            tracing::warn!(camera = %self.name, sequence = header.sequence, error = %e, suppressed, "estimator failed");
                        }
                    }
                }
            }
        }
        drop(sample); // give the frame back before publishing
        self.publish(ports, msg, times, valid);
        true
    }

    fn reject(&mut self, msg: &mut PoseMessage, reason: InvalidReason, detail: &dyn std::fmt::Display) {
        self.counters.count_invalid(reason);
        msg.status = PoseStatus::INVALID_FRAME;
        msg.invalid_reason = reason as u32;
        if let Some(suppressed) = self.invalid_log.allow(monotonic_ns()) {
            tracing::warn!(
                camera = %self.name,
                sequence = msg.frame_sequence,
                reason = reason.name(),
                suppressed,
                "frame rejected: {detail}"
            );
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
        times[Stage::Publish as usize] = monotonic_ns() - start;
        msg.stage_ns = times;
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
