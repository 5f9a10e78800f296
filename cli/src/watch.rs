//! `fusepose watch`: print pose messages as they arrive (object name, position
//! in mm, roll/pitch/yaw in degrees, confidence, capture → publish latency).
//!
//! Names are those of the built-in object set (`class <id>` beyond it).
//! The iceoryx2 namespace comes from `FUSEPOSE_IOX2_ROOT` / `FUSEPOSE_IOX2_PREFIX`.
//! `--overlay DIR` also writes a PNG per answered frame ([`overlay`]);
//! `--cell` prints the cell's fused objects instead ([`cell`]).

mod cell;
mod overlay;

use std::time::{Duration, Instant};

use fusepose_client::{Consumer, Ipc, IpcOptions, PoseMessage, PoseStatus, WireObjectPose};

#[derive(clap::Args)]
pub struct Args {
    /// Camera name.
    #[arg(long, default_value = "cam0")]
    pub name: String,
    /// Print the cell's objects instead (`fusepose/cell/poses`: every camera's
    /// poses in the cell frame, one entry per object).
    #[arg(long, conflicts_with_all = ["overlay", "name"])]
    pub cell: bool,
    /// One JSON object per message instead of text.
    #[arg(long)]
    pub json: bool,
    /// Exit after this many messages.
    #[arg(long)]
    pub count: Option<u64>,
    /// Exit after this many seconds without a message (default: wait forever).
    #[arg(long)]
    pub idle_timeout_s: Option<f64>,
    /// Write `frame_<sequence>.png` here per answered frame: frame, labels, poses drawn.
    #[arg(long)]
    pub overlay: Option<std::path::PathBuf>,
    /// With --overlay: network file with an embedded segmenter, to show labels of frames that carry
    /// none [default: models/builtin.safetensors, else the copy built into this binary].
    #[arg(long)]
    pub weights: Option<std::path::PathBuf>,
}

fn object_name(class_id: u16) -> String {
    let names = fusepose_scene::builtin::BUILTIN_NAMES;
    match (class_id as usize).checked_sub(1).and_then(|i| names.get(i)) {
        Some(name) => (*name).to_owned(),
        None => format!("class {class_id}"),
    }
}

/// Roll, pitch, yaw (rad) of a unit quaternion `[x, y, z, w]`, with R = Rz(yaw) · Ry(pitch) · Rx(roll).
pub fn rpy_from_quaternion(q: [f64; 4]) -> [f64; 3] {
    let [x, y, z, w] = q;
    let sin_pitch = (2.0 * (w * y - z * x)).clamp(-1.0, 1.0);
    let pitch = sin_pitch.asin();
    if sin_pitch.abs() > 1.0 - 1e-9 {
        // Gimbal lock: only yaw − roll is defined; report it all as yaw
        // (the general formulas turn rounding noise into ±π here).
        return [0.0, pitch, 2.0 * z.atan2(w)];
    }
    let roll = (2.0 * (w * x + y * z)).atan2(1.0 - 2.0 * (x * x + y * y));
    let yaw = (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z));
    [roll, pitch, yaw]
}

fn status_words(msg: &PoseMessage) -> Vec<&'static str> {
    let flags = [
        (PoseStatus::OK, "ok"),
        (PoseStatus::INVALID_FRAME, "invalid_frame"),
        (PoseStatus::DEADLINE_MISSED, "deadline_missed"),
        (PoseStatus::DEGRADED, "degraded"),
        (PoseStatus::ESTIMATOR_FAILED, "estimator_failed"),
    ];
    flags.iter().filter(|(bit, _)| msg.status & bit != 0).map(|(_, word)| *word).collect()
}

fn text(msg: &PoseMessage) -> String {
    let mut out = format!(
        "frame {:>6}  {:>7.2} ms  {}",
        msg.frame_sequence,
        msg.latency_ns() as f64 / 1e6,
        status_words(msg).join(",")
    );
    if let Some(reason) = msg.invalid() {
        out.push_str(&format!(" ({})", reason.name()));
    }
    for o in msg.objects() {
        out.push_str(&format!(
            "\n  {:<16} #{:<2} {}  conf {:.2}",
            object_name(o.class_id),
            o.instance_id,
            pose_text(o.translation_m, o.quaternion),
            o.confidence
        ));
    }
    out
}

/// `xyz [x y z] mm  rpy [roll pitch yaw] deg` of a pose (metres, quaternion `[x, y, z, w]`).
fn pose_text(translation_m: [f64; 3], quaternion: [f64; 4]) -> String {
    let t = translation_m.map(|v| v * 1e3);
    let rpy = rpy_from_quaternion(quaternion).map(f64::to_degrees);
    format!(
        "xyz [{:>8.1} {:>8.1} {:>8.1}] mm  rpy [{:>7.1} {:>7.1} {:>7.1}] deg",
        t[0], t[1], t[2], rpy[0], rpy[1], rpy[2]
    )
}

/// A float as JSON: `null` when NaN/infinite (not verified), else `decimals` places.
fn json_number(x: f32, decimals: usize) -> String {
    if x.is_finite() { format!("{x:.decimals$}") } else { "null".to_owned() }
}

fn json_object(o: &WireObjectPose) -> String {
    let t = o.translation_m.map(|v| v * 1e3);
    let rpy = rpy_from_quaternion(o.quaternion).map(f64::to_degrees);
    let q = o.quaternion;
    format!(
        "{{\"class_id\":{},\"name\":{:?},\"instance_id\":{},\"xyz_mm\":[{:.3},{:.3},{:.3}],\"rpy_deg\":[{:.3},{:.3},{:.3}],\"quaternion_xyzw\":[{:.6},{:.6},{:.6},{:.6}],\"confidence\":{:.4},\"refine_iterations\":{},\"mask_pixels\":{},\"bbox\":[{},{},{},{}],\"flags\":{},\"fit_score\":{},\"depth_residual_m\":{}}}",
        o.class_id,
        object_name(o.class_id),
        o.instance_id,
        t[0],
        t[1],
        t[2],
        rpy[0],
        rpy[1],
        rpy[2],
        q[0],
        q[1],
        q[2],
        q[3],
        o.confidence,
        o.refine_iterations,
        o.mask_pixels,
        o.bbox[0],
        o.bbox[1],
        o.bbox[2],
        o.bbox[3],
        o.flags,
        json_number(o.fit_score, 4),
        json_number(o.depth_residual_m, 6)
    )
}

fn json(msg: &PoseMessage) -> String {
    let objects: Vec<String> = msg.objects().iter().map(json_object).collect();
    let status: Vec<String> = status_words(msg).iter().map(|s| format!("{s:?}")).collect();
    format!(
        "{{\"camera_id\":{},\"frame_sequence\":{},\"status\":[{}],\"invalid_reason\":{:?},\"capture_time_ns\":{},\"received_time_ns\":{},\"published_time_ns\":{},\"latency_ms\":{:.3},\"stage_ns\":{:?},\"objects\":[{}]}}",
        msg.camera_id,
        msg.frame_sequence,
        status.join(","),
        msg.invalid().map_or("", |r| r.name()),
        msg.capture_time_ns,
        msg.received_time_ns,
        msg.published_time_ns,
        msg.latency_ns() as f64 / 1e6,
        msg.stage_ns,
        objects.join(",")
    )
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let ipc = Ipc::new(&IpcOptions::from_env().with_node_name("fusepose-watch"))?;
    if args.cell {
        return cell::run(&ipc, args.json, args.count, args.idle_timeout_s.map(Duration::from_secs_f64));
    }
    let mut consumer = Consumer::open(&ipc, &args.name)?;
    // With --overlay: a frame subscriber next to the daemon's, and the writer keeping recent frames.
    let mut overlay = match &args.overlay {
        Some(dir) => {
            let services = fusepose_client::CameraServices::open(&ipc, &args.name)?;
            let frames = services.frame_subscriber()?;
            let objects = fusepose_scene::builtin::builtin_objects();
            let weights = crate::weights::resolve_weights(args.weights.as_deref())?;
            Some((frames, overlay::OverlayWriter::new(dir, objects, Some(&weights))?))
        }
        None => None,
    };
    let idle = args.idle_timeout_s.map(Duration::from_secs_f64);
    let mut last = Instant::now();
    let mut seen = 0u64;
    while args.count.is_none_or(|n| seen < n) {
        match consumer.wait(Duration::from_millis(500))? {
            Some(msg) => {
                last = Instant::now();
                seen += 1;
                println!("{}", if args.json { json(&msg) } else { text(&msg) });
                if let Some((frames, writer)) = &mut overlay {
                    while let Some(sample) =
                        frames.receive().map_err(|e| anyhow::anyhow!("receiving a frame: {e:?}"))?
                    {
                        writer.push(*sample.user_header(), sample.payload());
                    }
                    match writer.write(&msg) {
                        Ok(Some(path)) => eprintln!("wrote {}", path.display()),
                        Ok(None) => eprintln!("frame {} no longer held; no overlay", msg.frame_sequence),
                        Err(e) => eprintln!("overlay of frame {}: {e:#}", msg.frame_sequence),
                    }
                }
            }
            None => {
                if idle.is_some_and(|d| last.elapsed() >= d) {
                    anyhow::bail!("no pose message on camera {} for {:?}", args.name, idle.unwrap_or_default());
                }
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rpy_of_basic_rotations() {
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let close = |a: [f64; 3], b: [f64; 3]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-9);
        assert!(close(rpy_from_quaternion([0.0, 0.0, 0.0, 1.0]), [0.0; 3]));
        assert!(close(rpy_from_quaternion([h, 0.0, 0.0, h]), [std::f64::consts::FRAC_PI_2, 0.0, 0.0]));
        assert!(close(rpy_from_quaternion([0.0, 0.0, h, h]), [0.0, 0.0, std::f64::consts::FRAC_PI_2]));
        assert!(close(rpy_from_quaternion([0.0, 0.5f64.sqrt(), 0.0, h]), [0.0, std::f64::consts::FRAC_PI_2, 0.0]));
        // Gimbal lock with yaw: qz(60°)·qy(90°) = h·[−sin30°, cos30°, sin30°, cos30°].
        let (s30, c30) = (0.5, 0.75f64.sqrt());
        let r = rpy_from_quaternion([-h * s30, h * c30, h * s30, h * c30]);
        assert!(close(r, [0.0, std::f64::consts::FRAC_PI_2, std::f64::consts::FRAC_PI_3]), "{r:?}");
    }

    #[test]
    fn json_writes_unverified_scores_as_null() {
        let o = WireObjectPose { flags: 2, fit_score: f32::NAN, depth_residual_m: f32::NAN, ..Default::default() };
        assert!(
            json_object(&o).ends_with(r#""flags":2,"fit_score":null,"depth_residual_m":null}"#),
            "{}",
            json_object(&o)
        );
        let v = WireObjectPose { flags: 1, fit_score: 0.875, depth_residual_m: 0.0015, ..o };
        assert!(json_object(&v).ends_with(r#""flags":1,"fit_score":0.8750,"depth_residual_m":0.001500}"#));
    }
}
