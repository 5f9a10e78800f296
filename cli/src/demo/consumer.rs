//! The demo's consumer process (`fusepose demo-consumer`, hidden): receives
//! pose messages over iceoryx2 like any client would, scores them against the
//! synthetic camera's ground truth, prints a line per second, then a summary
//! table, `summary.json` and overlay PNGs of a few frames.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::Context;
use fusepose_client::{Consumer, Ipc, IpcOptions, PoseMessage, PoseStatus, StatsClient, TIMELINE_COUNT};
use fusepose_scene::metrics::{MetricsTable, ObjectMetric};
use fusepose_scene::overlay::{self, OverlayObject, OverlayStyle};
use fusepose_scene::{Intrinsics, Pose};

use super::truth::{SyntheticTruth, match_truth, wire_pose};

#[derive(clap::Args)]
pub struct Args {
    /// Camera name to subscribe to.
    #[arg(long)]
    pub camera: String,
    /// Measurement length after the first pose message, seconds.
    #[arg(long)]
    pub seconds: f64,
    /// The camera's first scene seed (`fusepose camera --seed`).
    #[arg(long)]
    pub seed: u64,
    /// The camera's views per scene (`fusepose camera --views-per-scene`).
    #[arg(long)]
    pub views_per_scene: usize,
    /// The camera's pre-rendered loop length (`fusepose camera --preload`).
    #[arg(long)]
    pub preload: usize,
    /// Directory for overlay PNGs and summary.json (must exist).
    #[arg(long)]
    pub out: PathBuf,
    /// Number of overlay PNGs, spread over the run.
    #[arg(long)]
    pub overlays: usize,
    /// Give up when no pose message arrives within this many seconds of start.
    #[arg(long, default_value_t = 180.0)]
    pub startup_timeout_s: f64,
}

/// Percentile (0..=100) of an unsorted sample, nearest rank; 0 when empty.
fn percentile(values: &mut [u64], p: f64) -> u64 {
    if values.is_empty() {
        return 0;
    }
    values.sort_unstable();
    let rank = ((p / 100.0) * values.len() as f64).ceil().max(1.0) as usize;
    values[rank.min(values.len()) - 1]
}

fn ms(ns: u64) -> f64 {
    ns as f64 / 1e6
}

/// Running totals of the whole run.
#[derive(Default)]
struct Totals {
    messages: u64,
    latencies_ns: Vec<u64>,
    objects_posed: u64,
    objects_in_scene: u64,
    invalid: u64,
    deadline_missed: u64,
    estimator_failed: u64,
    non_finite: u64,
    first_sequence: Option<u64>,
    last_sequence: u64,
    /// ADD-S per estimate, metres.
    add_s_m: Vec<f64>,
}

/// One second of messages for the live line.
#[derive(Default)]
struct Window {
    messages: u64,
    latencies_ns: Vec<u64>,
    objects: u64,
}

struct Scorer {
    truth: SyntheticTruth,
    metrics: Vec<ObjectMetric>,
    table: MetricsTable,
    per_class_add_s: Vec<Vec<f64>>,
}

impl Scorer {
    fn new(truth: SyntheticTruth) -> anyhow::Result<Self> {
        let metrics = truth
            .objects()
            .objects
            .iter()
            .map(ObjectMetric::for_model)
            .collect::<Result<Vec<_>, _>>()
            .context("preparing ADD-S")?;
        let table = MetricsTable::for_objects(truth.objects());
        let n = metrics.len();
        Ok(Self { truth, metrics, table, per_class_add_s: vec![Vec::new(); n] })
    }

    /// Scores one message's poses; returns (objects in the scene, ADD-S values).
    fn score(&mut self, msg: &PoseMessage, totals: &mut Totals) -> anyhow::Result<()> {
        let truth = self.truth.frame(msg.frame_sequence)?;
        totals.objects_in_scene += truth.len() as u64;
        for o in msg.objects() {
            let Some(estimate) = wire_pose(o) else {
                totals.non_finite += 1;
                continue;
            };
            let (Some(t), Some(metric)) = (
                match_truth(&truth, o.class_id, &estimate),
                (o.class_id as usize).checked_sub(1).and_then(|i| self.metrics.get(i)),
            ) else {
                continue;
            };
            let errors = metric.errors(&estimate, &t.pose);
            self.table.record(o.class_id, Some(errors));
            self.per_class_add_s[o.class_id as usize - 1].push(errors.add_s);
            totals.add_s_m.push(errors.add_s);
        }
        Ok(())
    }
}

fn mean(v: &[f64]) -> f64 {
    if v.is_empty() { f64::NAN } else { v.iter().sum::<f64>() / v.len() as f64 }
}

fn median(v: &[f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    s[s.len() / 2]
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let stop = Arc::new(AtomicBool::new(false));
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(signal, stop.clone()).context("installing the signal handler")?;
    }
    // iceoryx2 reports dead peers (a camera killed by Ctrl-C) at length on
    // stderr; the summary matters more here.
    iceoryx2::prelude::set_log_level(iceoryx2::prelude::LogLevel::Error);
    let ipc = Ipc::new(&IpcOptions::from_env().with_node_name("fusepose-demo-consumer"))?;
    let mut consumer = Consumer::open(&ipc, &args.camera)?;
    let objects = fusepose_scene::builtin::builtin_objects();
    let mut scorer = Scorer::new(SyntheticTruth::new(objects, args.seed, args.views_per_scene, args.preload))?;

    let started = Instant::now();
    let mut totals = Totals::default();
    let mut window = Window::default();
    let mut inbox = Vec::new();
    let mut first_at: Option<Instant> = None;
    let mut next_line = Duration::from_secs(1);
    let mut overlay_frames: Vec<PoseMessage> = Vec::new();
    let run_for = Duration::from_secs_f64(args.seconds);
    println!("waiting for the first poses (the daemon loads the network, the camera renders) ...");
    while !stop.load(Ordering::Relaxed) {
        if let Some(t0) = first_at {
            if t0.elapsed() >= run_for {
                break;
            }
        } else if started.elapsed().as_secs_f64() > args.startup_timeout_s {
            anyhow::bail!(
                "no pose message within {} s; see the daemon and camera logs in {}",
                args.startup_timeout_s,
                args.out.join("logs").display()
            );
        }
        match consumer.wait_ready(Duration::from_millis(100)) {
            Ok(_) => {}
            // Ctrl-C interrupts the wait itself; the flag is already set.
            Err(_) if stop.load(Ordering::Relaxed) => break,
            Err(e) => return Err(e.into()),
        }
        inbox.clear();
        consumer.drain(&mut inbox)?;
        for msg in &inbox {
            let t0 = *first_at.get_or_insert_with(Instant::now);
            totals.messages += 1;
            totals.first_sequence.get_or_insert(msg.frame_sequence);
            totals.last_sequence = totals.last_sequence.max(msg.frame_sequence);
            totals.invalid += (msg.status & PoseStatus::INVALID_FRAME != 0) as u64;
            totals.deadline_missed += (msg.status & PoseStatus::DEADLINE_MISSED != 0) as u64;
            totals.estimator_failed += (msg.status & PoseStatus::ESTIMATOR_FAILED != 0) as u64;
            totals.latencies_ns.push(msg.latency_ns());
            totals.objects_posed += msg.objects().len() as u64;
            window.messages += 1;
            window.latencies_ns.push(msg.latency_ns());
            window.objects += msg.objects().len() as u64;
            scorer.score(msg, &mut totals)?;
            // Overlay frames spread over the run: one at each (i + 0.5) / n of it.
            let due = overlay_frames.len() < args.overlays
                && t0.elapsed().as_secs_f64()
                    >= args.seconds * (overlay_frames.len() as f64 + 0.5) / args.overlays as f64;
            if due && msg.object_count > 0 {
                overlay_frames.push(*msg);
            }
        }
        if let Some(t0) = first_at
            && t0.elapsed() >= next_line
        {
            let n = window.messages.max(1) as f64;
            println!(
                "[{:>3} s] {:>5.1} fps  latency p50 {:>6.1} ms  p99 {:>6.1} ms  objects {:>4.1}/frame  ADD-S mean {:>6.1} mm  median {:>6.1} mm  (n {})",
                next_line.as_secs(),
                window.messages as f64,
                ms(percentile(&mut window.latencies_ns, 50.0)),
                ms(percentile(&mut window.latencies_ns, 99.0)),
                window.objects as f64 / n,
                mean(&totals.add_s_m) * 1e3,
                median(&totals.add_s_m) * 1e3,
                totals.add_s_m.len()
            );
            window = Window::default();
            next_line += Duration::from_secs(1);
        }
    }
    let elapsed = first_at.map_or(0.0, |t| t.elapsed().as_secs_f64());
    let interrupted = stop.load(Ordering::Relaxed);
    if interrupted {
        println!("interrupted after {elapsed:.1} s: summary so far");
    }
    // After Ctrl-C the daemon is shutting down too: do not ask it.
    let daemon_stats = if interrupted {
        None
    } else {
        StatsClient::open(&ipc, &args.camera).and_then(|c| c.query(Duration::from_secs(2))).ok()
    };
    let summary = summarise(&args, &scorer, &mut totals, elapsed, daemon_stats.as_ref());
    std::fs::write(args.out.join("summary.json"), serde_json::to_string_pretty(&summary)? + "\n")
        .with_context(|| format!("writing {}", args.out.join("summary.json").display()))?;
    write_overlays(&args.out, &mut scorer, &overlay_frames)?;
    Ok(())
}

/// Prints the summary table and returns it as JSON.
fn summarise(
    args: &Args,
    scorer: &Scorer,
    totals: &mut Totals,
    elapsed_s: f64,
    daemon: Option<&fusepose_client::StatsSnapshot>,
) -> serde_json::Value {
    let frames_sent = totals.first_sequence.map_or(0, |f| totals.last_sequence - f + 1);
    let fps = totals.messages as f64 / elapsed_s.max(1e-9);
    let lat = &mut totals.latencies_ns;
    let (p50, p90, p99, max) =
        (percentile(lat, 50.0), percentile(lat, 90.0), percentile(lat, 99.0), lat.iter().copied().max().unwrap_or(0));
    let per_frame = |n: u64| n as f64 / totals.messages.max(1) as f64;
    println!();
    println!("=== fusepose demo summary ({elapsed_s:.1} s) ===");
    println!(
        "pose messages {}  ({fps:.1} per s; camera frames in that span {frames_sent}, {} not posed: the daemon keeps only the newest frame)",
        totals.messages,
        frames_sent.saturating_sub(totals.messages)
    );
    println!(
        "latency capture -> publish  p50 {:.1} ms  p90 {:.1} ms  p99 {:.1} ms  max {:.1} ms  (deadline missed {}, invalid {}, estimator failed {})",
        ms(p50),
        ms(p90),
        ms(p99),
        ms(max),
        totals.deadline_missed,
        totals.invalid,
        totals.estimator_failed
    );
    println!(
        "objects posed {:.2} per frame of {:.2} in the scene (hidden ones included)",
        per_frame(totals.objects_posed),
        per_frame(totals.objects_in_scene)
    );
    if let Some(s) = daemon {
        let e2e = s.since_start[TIMELINE_COUNT - 1];
        println!(
            "daemon: {} frames received, {} processed, {} skipped as stale; its capture -> publish p50 {:.1} ms p99 {:.1} ms",
            s.frames_received,
            s.frames_processed,
            s.frames_skipped_stale,
            ms(e2e.p50_ns),
            ms(e2e.p99_ns)
        );
    }
    println!();
    let rows = scorer.table.rows();
    let overall = scorer.table.overall();
    println!(
        "{:>3}  {:<16} {:>6}  {:>13}  {:>15}  {:>10}  {:>10}",
        "id", "object", "poses", "ADD-S mean mm", "ADD-S median mm", "ADD-S<2cm%", "ADD-S AUC%"
    );
    let mut json_rows = Vec::new();
    let all: Vec<f64> = totals.add_s_m.clone();
    for (row, add_s) in rows
        .iter()
        .map(|r| (r, r.class_id.map(|c| &scorer.per_class_add_s[c as usize - 1])))
        .chain([(&overall, Some(&all))])
    {
        let add_s = add_s.map(|v| v.as_slice()).unwrap_or(&[]);
        if add_s.is_empty() && row.class_id.is_some() {
            continue;
        }
        let id = row.class_id.map(|c| c.to_string()).unwrap_or_default();
        println!(
            "{:>3}  {:<16} {:>6}  {:>13.1}  {:>15.1}  {:>10.1}  {:>10.1}",
            id,
            row.name,
            add_s.len(),
            mean(add_s) * 1e3,
            median(add_s) * 1e3,
            row.add_s_lt_2cm,
            row.add_s_auc
        );
        json_rows.push(serde_json::json!({
            "class_id": row.class_id, "name": row.name, "poses": add_s.len(),
            "add_s_mean_mm": mean(add_s) * 1e3, "add_s_median_mm": median(add_s) * 1e3,
            "add_s_lt_2cm_percent": row.add_s_lt_2cm, "add_s_auc_percent": row.add_s_auc,
            "add_s_auc_symmetric_aware_percent": row.add_s_auc_symmetric_aware,
        }));
    }
    println!("(ADD-S over the poses published, each matched to the true pose of its class in that frame)");
    serde_json::json!({
        "seconds": elapsed_s,
        "pose_messages": totals.messages,
        "pose_messages_per_s": fps,
        "camera_frames_in_span": frames_sent,
        "latency_ms": { "p50": ms(p50), "p90": ms(p90), "p99": ms(p99), "max": ms(max) },
        "deadline_missed": totals.deadline_missed,
        "invalid": totals.invalid,
        "estimator_failed": totals.estimator_failed,
        "non_finite_poses": totals.non_finite,
        "objects_posed_per_frame": per_frame(totals.objects_posed),
        "objects_in_scene_per_frame": per_frame(totals.objects_in_scene),
        "camera": { "seed": args.seed, "views_per_scene": args.views_per_scene, "preload": args.preload },
        "objects": json_rows,
    })
}

/// Re-renders the chosen frames and writes `frame_<sequence>.png`: labels
/// tinted, true poses outlined in white, estimates in class colours with axes.
fn write_overlays(out: &Path, scorer: &mut Scorer, frames: &[PoseMessage]) -> anyhow::Result<()> {
    let k = Intrinsics::YCB_VIDEO;
    for msg in frames {
        let target = scorer.truth.render(msg.frame_sequence, &k)?;
        let truth = scorer.truth.frame(msg.frame_sequence)?;
        let set = scorer.truth.objects();
        let mut img = overlay::rgb_image(k.width, k.height, target.rgb())?;
        overlay::tint_labels(&mut img, target.labels(), 0.25)?;
        let estimates: Vec<(u16, Pose)> =
            msg.objects().iter().filter_map(|o| Some((o.class_id, wire_pose(o)?))).collect();
        let truths: Vec<OverlayObject> = estimates
            .iter()
            .filter_map(|(c, p)| {
                let t = match_truth(&truth, *c, p)?;
                Some(OverlayObject::new(set.by_class(*c)?, *c, t.pose).with_colour([255, 255, 255]))
            })
            .collect();
        let thin = OverlayStyle { axis_fraction: 0.0, thickness: 1, ..OverlayStyle::default() };
        overlay::draw_poses(&mut img, &k, &truths, &thin);
        let drawn: Vec<OverlayObject> =
            estimates.iter().filter_map(|(c, p)| Some(OverlayObject::new(set.by_class(*c)?, *c, *p))).collect();
        overlay::draw_poses(&mut img, &k, &drawn, &OverlayStyle::default());
        let classes: Vec<u16> = drawn.iter().map(|o| o.class_id).collect();
        overlay::draw_legend(&mut img, &classes);
        let path = out.join(format!("frame_{:06}.png", msg.frame_sequence));
        overlay::save_png(&img, &path).with_context(|| format!("writing {}", path.display()))?;
        println!("overlay: {}", path.display());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_rank_percentiles() {
        let mut v: Vec<u64> = (1..=100).rev().collect();
        assert_eq!(percentile(&mut v, 50.0), 50);
        assert_eq!(percentile(&mut v, 99.0), 99);
        assert_eq!(percentile(&mut v, 100.0), 100);
        assert_eq!(percentile(&mut [], 50.0), 0);
        assert_eq!(percentile(&mut [7], 1.0), 7);
    }
}
