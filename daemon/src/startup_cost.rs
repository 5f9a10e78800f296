//! What a frame costs on this machine, measured once at start: the network
//! (pose net + refiner) on a synthetic 640×480 frame with a few labelled
//! rectangles, and the segmenter on the same frame; from that, how many
//! objects per frame fit the deadline. Logged when the daemon starts, so an
//! operator sees at once whether the configuration can meet its budget here.
//!
//! The numbers are taken on an idle daemon (no camera yet); a loaded
//! machine is slower. The network's own cost model
//! (`fusepose_estimator::net::budget`) keeps learning from every real frame.

use std::time::Instant;

use fusepose_estimator::net::NetEstimator;
use fusepose_estimator::seg::{Boundary, DepthRegionParams, DepthRegions, SegEngine, SegFile};
use fusepose_estimator::{
    ColorFormat, DepthPlane, Estimator, FrameView, LabelPlane, PoseSet, Workspace, WorkspaceConfig,
};
use fusepose_scene::Intrinsics;

/// Frames run before timing (first-touch allocations, caches).
const WARM_UP_FRAMES: usize = 2;
/// Frames timed; the median is kept.
const TIMED_FRAMES: usize = 5;
/// Share of the deadline a frame's work may fill: the same headroom the
/// deadline-aware plan keeps for noise (`net::budget`).
const FILL: f64 = 0.85;
/// Ingest, assembly and publishing of a frame besides the estimator, ns
/// (transport is microseconds; this is a generous allowance).
const FRAME_OVERHEAD_NS: f64 = 1.0e6;

/// Measured costs of one frame's parts.
#[derive(Clone, Debug, PartialEq)]
pub struct StartupCost {
    /// Threads the network runs a frame's objects on.
    pub threads: usize,
    /// Objects in the synthetic frame.
    pub objects: usize,
    /// One object through pose net and refiner (configured iterations), one thread, ns.
    pub per_object_ns: f64,
    /// One object through the pose net alone (no refiner), one thread, ns:
    /// what deadline-aware degradation falls back to.
    pub pose_only_ns: f64,
    /// Instances, point sampling and crops, per object, ns (loop thread).
    pub prepare_per_object_ns: f64,
    /// The whole estimate of the synthetic frame (median), ns.
    pub frame_ns: f64,
    /// The segmenter on one frame (None: frames are not segmented), ns.
    pub segment_ns: Option<f64>,
    /// The 1-minute load average when measured (`/proc/loadavg`): a loaded
    /// machine makes every number larger.
    pub load_average: Option<f64>,
}

impl StartupCost {
    /// Most objects per frame whose full estimate (every refiner iteration)
    /// fits `deadline_ns`, and most with the pose net alone (the
    /// deadline-aware fallback, messages flagged DEGRADED); segmentation
    /// counted when `segmented` (frames without a label plane).
    pub fn objects_fitting(&self, deadline_ns: f64, segmented: bool) -> (usize, usize) {
        let fixed = FRAME_OVERHEAD_NS + if segmented { self.segment_ns.unwrap_or(0.0) } else { 0.0 };
        let budget = deadline_ns * FILL - fixed;
        let fits = |per_object: f64| {
            (1..=fusepose_client::MAX_OBJECTS)
                .take_while(|&n| {
                    let rounds = n.div_ceil(self.threads.max(1)) as f64;
                    n as f64 * self.prepare_per_object_ns + rounds * per_object <= budget
                })
                .last()
                .unwrap_or(0)
        };
        (fits(self.per_object_ns), fits(self.pose_only_ns))
    }

    /// The start-up log line's text.
    pub fn describe(&self, deadline_ms: f64) -> String {
        let ms = |ns: f64| ns / 1e6;
        let fps = 1000.0 / deadline_ms;
        let (full, degraded) = self.objects_fitting(deadline_ms * 1e6, false);
        let mut text = format!(
            "measured cost per object {:.2} ms on one thread (pose net alone {:.2} ms; sampling and crops {:.2} ms), \
             {} network thread(s): a {}-object frame took {:.2} ms; within deadline_ms = {deadline_ms:.1} \
             (one frame per deadline = {fps:.1} FPS) fit {full} objects per frame with labels",
            ms(self.per_object_ns),
            ms(self.pose_only_ns),
            ms(self.prepare_per_object_ns),
            self.threads,
            self.objects,
            ms(self.frame_ns),
        );
        if let Some(seg) = self.segment_ns {
            let (seg_full, _) = self.objects_fitting(deadline_ms * 1e6, true);
            text += &format!(", {seg_full} when the daemon segments (segmenter {:.2} ms per frame)", ms(seg));
        }
        text += &format!("; up to {degraded} with the pose net alone (DEGRADED)");
        if let Some(load) = self.load_average {
            text += &format!(" [load average {load:.2} while measuring]");
        }
        text
    }
}

/// Height of the synthetic frame's objects above its plane, 0.1 mm units.
const OBJECT_HEIGHT_UNITS: u16 = 400;

/// A 640×480 frame with `objects` labelled rectangles (classes 1..=objects)
/// standing 4 cm proud of a tilted plane 0.6–0.9 m away, textured colour.
pub struct SyntheticFrame {
    intrinsics: Intrinsics,
    color: Vec<u8>,
    depth: Vec<u16>,
    labels: Vec<u16>,
}

impl SyntheticFrame {
    pub fn new(objects: usize) -> Self {
        let intrinsics = Intrinsics::YCB_VIDEO;
        let (w, h) = (intrinsics.width as usize, intrinsics.height as usize);
        let color = (0..w * h * 3).map(|i| ((i * 7919) % 251) as u8).collect();
        let mut depth: Vec<u16> = (0..w * h).map(|i| 6000 + (i / w) as u16 * 6).collect(); // 0.1 mm units
        let mut labels = vec![0u16; w * h];
        for k in 0..objects {
            let (u0, v0) = (30 + 150 * (k % 4), 40 + 140 * (k / 4 % 3));
            for v in v0..v0 + 110 {
                labels[v * w + u0..v * w + u0 + 120].fill(k as u16 + 1);
                // Each object stands 4 cm proud of the plane: one lying in it
                // is the table to the support floor, and would not be measured.
                depth[v * w + u0..v * w + u0 + 120].iter_mut().for_each(|z| *z -= OBJECT_HEIGHT_UNITS);
            }
        }
        Self { intrinsics, color, depth, labels }
    }

    pub fn view(&self, with_labels: bool) -> FrameView<'_> {
        FrameView {
            intrinsics: self.intrinsics,
            color_format: ColorFormat::Rgb8,
            color: &self.color,
            depth: DepthPlane::U16 { data: &self.depth, scale: 1e-4 },
            labels: with_labels.then_some(LabelPlane::U16(&self.labels)),
        }
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(0.0)
}

/// Times `net` on a synthetic frame (full plan: no deadline) and leaves it
/// as it was besides the warmed caches and its learned cost model (tracks
/// are cleared). Objects: two per thread, within the workspace's limits.
pub fn measure_net(net: &mut NetEstimator, workspace: WorkspaceConfig) -> Result<StartupCost, String> {
    let threads = net.threads();
    let objects = (2 * threads).min(workspace.max_instances).min(workspace.num_classes as usize).max(1);
    let frame = SyntheticFrame::new(objects);
    let view = frame.view(true);
    let mut ws = Workspace::new(workspace).map_err(|e| e.to_string())?;
    let mut poses = PoseSet::with_capacity(workspace.max_instances);
    net.set_deadline(None);
    let (mut prepare, mut estimate) = (Vec::new(), Vec::new());
    for i in 0..WARM_UP_FRAMES + TIMED_FRAMES {
        let t0 = Instant::now();
        let found = ws.prepare(&view, i as u64).map_err(|e| format!("synthetic frame refused: {e}"))?;
        let t1 = Instant::now();
        net.estimate(&view, &mut ws, &mut poses).map_err(|e| format!("estimate failed: {e}"))?;
        let t2 = Instant::now();
        if found < objects {
            return Err(format!("the synthetic frame gave {found} of its {objects} instances"));
        }
        if i >= WARM_UP_FRAMES {
            prepare.push((t1 - t0).as_nanos() as f64 / found as f64);
            estimate.push((t2 - t1).as_nanos() as f64);
        }
    }
    net.reset_tracks();
    let costs = *net.costs();
    let iterations = net.refine_iterations() as f64;
    let (color, pose) = (costs.color_ns.unwrap_or(0.0), costs.pose_ns.unwrap_or(0.0));
    let refine = if iterations > 0.0 {
        costs.refine_setup_ns.unwrap_or(0.0) + iterations * costs.refine_iter_ns.unwrap_or(0.0)
    } else {
        0.0
    };
    let frame_ns = median(estimate);
    // The cost model times each object's stages alone; the frame time also
    // holds the hand-over to the worker thread. Take the larger of the two.
    let rounds = objects.div_ceil(threads) as f64;
    let per_object_ns = (color + pose + refine).max(frame_ns / rounds);
    Ok(StartupCost {
        threads,
        objects,
        per_object_ns,
        pose_only_ns: (color + pose).min(per_object_ns),
        prepare_per_object_ns: median(prepare),
        frame_ns,
        segment_ns: None,
        load_average: load_average(),
    })
}

/// The 1-minute load average (first field of `/proc/loadavg`).
fn load_average() -> Option<f64> {
    std::fs::read_to_string("/proc/loadavg").ok()?.split_whitespace().next()?.parse().ok()
}

/// Times the segmenter of `file` on the synthetic frame (median of a few runs), ns.
pub fn measure_segmenter(
    file: &SegFile,
    boundary: Boundary,
    depth_regions: Option<&(Vec<f32>, DepthRegionParams)>,
) -> Result<f64, String> {
    let mut seg = SegEngine::new(file).map_err(|e| e.to_string())?;
    seg.set_boundary(boundary);
    seg.set_depth_regions(depth_regions.map(|(d, p)| DepthRegions::new(d, *p)));
    let frame = SyntheticFrame::new(1);
    let view = frame.view(false);
    let mut labels = vec![0u16; view.width() * view.height()];
    let mut times = Vec::new();
    for i in 0..WARM_UP_FRAMES + TIMED_FRAMES {
        let t0 = Instant::now();
        seg.segment(&view, &mut labels).map_err(|e| e.to_string())?;
        if i >= WARM_UP_FRAMES {
            times.push(t0.elapsed().as_nanos() as f64);
        }
    }
    Ok(median(times))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cost() -> StartupCost {
        StartupCost {
            threads: 2,
            objects: 4,
            per_object_ns: 5e6,
            pose_only_ns: 2e6,
            prepare_per_object_ns: 0.2e6,
            frame_ns: 10.4e6,
            segment_ns: Some(4e6),
            load_average: Some(0.5),
        }
    }

    #[test]
    fn objects_fitting_counts_rounds_over_threads_and_the_segmenter() {
        let c = cost();
        // 41.7 ms × 0.85 − 1 ms = 34.4 ms: n objects cost 0.2 n + 5 ceil(n / 2) ms.
        // n = 12: 2.4 + 30 = 32.4 fits; n = 13: 2.6 + 35 does not.
        assert_eq!(c.objects_fitting(41.666e6, false).0, 12);
        // Segmenting takes 4 ms more: n = 10 costs 2 + 25 = 27 ≤ 30.4; n = 11: 2.2 + 30 > 30.4.
        assert_eq!(c.objects_fitting(41.666e6, true).0, 10);
        // Pose net alone: 0.2 n + 2 ceil(n / 2) ≤ 34.4 → n = 28 (5.6 + 28 = 33.6).
        assert_eq!(c.objects_fitting(41.666e6, false).1, 28);
        let one = StartupCost { threads: 1, ..c };
        assert_eq!(one.objects_fitting(41.666e6, false).0, 6, "0.2 n + 5 n <= 34.4");
        assert_eq!(one.objects_fitting(1e6, false), (0, 0), "nothing fits 1 ms");
        let text = one.describe(41.666);
        assert!(text.contains("fit 6 objects per frame") && text.contains("24.0 FPS"), "{text}");
        assert!(text.contains("segmenter 4.00 ms") && text.contains("load average 0.50"), "{text}");
    }

    #[test]
    fn synthetic_frame_has_the_asked_objects_and_valid_depth() {
        let f = SyntheticFrame::new(3);
        let view = f.view(true);
        view.validate().unwrap();
        let mut ids: Vec<u16> = f.labels.clone();
        ids.sort_unstable();
        ids.dedup();
        assert_eq!(ids, [0, 1, 2, 3]);
        assert!(f.depth.iter().all(|&d| (5000..9000).contains(&d)));
        // With the daemon's support floor every object still has its points.
        let config = WorkspaceConfig {
            num_classes: 3,
            support_floor_m: fusepose_estimator::workspace::DEFAULT_SUPPORT_FLOOR_M,
            ..WorkspaceConfig::default()
        };
        let mut ws = Workspace::new(config).unwrap();
        assert_eq!(ws.prepare(&view, 0).unwrap(), 3);
        assert!(ws.support_plane().is_some(), "the plane behind them is found");
    }
}
