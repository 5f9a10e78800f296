//! What the daemon publishes across cameras: the cell's poses on
//! `fusepose/cell/poses` after every posed frame, and the daemon-wide log
//! line of frames per camera per second and each camera's share of the loop.

use fusepose_client::{CellPoseMessage, CellServices, Ipc, monotonic_ns};
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::prelude::*;

use crate::camera_set::{Camera, EngineCatalog, merge_distances};
use crate::cell::{CellFuser, CellSource};
use crate::config::{CellConfig, DaemonConfig};
use crate::rate_limited_log::RateLimit;

/// The cell publisher with its fuser and message buffer.
pub struct CellOutput {
    _services: CellServices,
    publisher: Publisher<ipc::Service, CellPoseMessage, ()>,
    notifier: Notifier<ipc::Service>,
    fuser: CellFuser,
    msg: Box<CellPoseMessage>,
    max_age_ns: u64,
    log: RateLimit,
}

impl CellOutput {
    /// Opens the cell service when `[cell] enabled`; a second daemon in the
    /// namespace gets a warning and publishes no cell poses.
    pub fn open(ipc: &Ipc, config: &DaemonConfig, catalog: &EngineCatalog<'_>) -> Option<Self> {
        if !config.cell.enabled {
            return None;
        }
        let opened = CellServices::open(ipc).and_then(|services| {
            let publisher = services.publisher()?;
            let notifier = services.notifier()?;
            Ok((services, publisher, notifier))
        });
        match opened {
            Ok((services, publisher, notifier)) => {
                let mut out = Self {
                    _services: services,
                    publisher,
                    notifier,
                    fuser: CellFuser::new(Vec::new(), 0.0),
                    msg: Box::default(),
                    max_age_ns: 0,
                    log: RateLimit::new(1_000_000_000),
                };
                out.configure(&config.cell, catalog);
                Some(out)
            }
            Err(e) => {
                tracing::warn!("no cell poses from this daemon: {e}");
                None
            }
        }
    }

    /// Applies `[cell]` settings (start and reload).
    pub fn configure(&mut self, cell: &CellConfig, catalog: &EngineCatalog<'_>) {
        // Checked by the config's validation.
        let fusion = cell.fusion.parse().unwrap_or_default();
        self.fuser =
            CellFuser::new(merge_distances(catalog.cell_objects(), cell.merge_distance_m), cell.max_rotation_deg)
                .with_fusion(fusion);
        self.max_age_ns = (cell.max_age_ms * 1e6) as u64;
    }

    /// Fuses every camera's latest poses and publishes them (after a frame of `trigger`).
    pub fn publish(&mut self, cameras: &[Camera], trigger: usize) {
        let sources = cameras.iter().map(|c| CellSource {
            msg: &c.state.last_message,
            cell_from_camera: &c.cell_from_camera,
            class_map: &c.class_map,
        });
        self.fuser.fuse(sources, monotonic_ns(), self.max_age_ns, cameras[trigger].state.camera_id, &mut self.msg);
        self.msg.published_time_ns = monotonic_ns();
        let sent = self
            .publisher
            .loan_uninit()
            .map_err(|e| format!("loan: {e:?}"))
            .and_then(|s| s.write_payload(*self.msg).send().map_err(|e| format!("send: {e:?}")))
            .and_then(|_| self.notifier.notify().map_err(|e| format!("notify: {e:?}")));
        if let Err(e) = sent
            && let Some(suppressed) = self.log.allow(monotonic_ns())
        {
            tracing::warn!(error = %e, suppressed, "publishing cell poses failed");
        }
    }
}

/// Frames per camera per second and each camera's share of the loop's
/// time between two daemon-wide log lines.
pub struct CameraShares {
    since_ns: u64,
    /// Per camera name: (processed, busy ns) at the last line.
    last: Vec<(String, u64, u64)>,
}

impl CameraShares {
    pub fn new(now_ns: u64) -> Self {
        Self { since_ns: now_ns, last: Vec::new() }
    }

    /// "cameras: cam0 24.0 fps 47.9 % of the loop, …; loop idle 4.2 %" since the last line.
    pub fn line(&mut self, cameras: &[Camera], now_ns: u64) -> String {
        let span_ns = now_ns.saturating_sub(self.since_ns).max(1) as f64;
        let mut parts = Vec::with_capacity(cameras.len());
        let mut busy_total = 0.0;
        for c in cameras {
            let (processed, busy) = (c.state.counters.processed, c.state.busy_ns);
            let (p0, b0) = self.last.iter().find(|(n, _, _)| *n == c.state.name).map_or((0, 0), |&(_, p, b)| (p, b));
            let busy_share = busy.saturating_sub(b0) as f64 / span_ns;
            busy_total += busy_share;
            let fps = processed.saturating_sub(p0) as f64 / (span_ns / 1e9);
            parts.push(format!("{} {fps:.1} fps {:.1} % of the loop", c.state.name, 100.0 * busy_share));
        }
        self.last =
            cameras.iter().map(|c| (c.state.name.clone(), c.state.counters.processed, c.state.busy_ns)).collect();
        self.since_ns = now_ns;
        format!("cameras: {}; loop idle {:.1} %", parts.join(", "), 100.0 * (1.0 - busy_total).max(0.0))
    }
}
