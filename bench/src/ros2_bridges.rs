//! `fusepose-bench ros2`: the latency and CPU cost of the two ROS 2 bridges
//! at a camera's rate, with a real daemon between them.
//!
//! This process plays the ROS 2 graph (ros2-client on a private domain): it
//! publishes a rendered video as realsense2_camera would (rgb8 colour, 16UC1
//! millimetre depth aligned to it, CameraInfo; best-effort, keep last 5) and
//! subscribes to the detections. `fusepose-ros2 ros2-camera` and
//! `fusepose-ros2 ros2` run as their own processes beside the daemon (network
//! + built-in segmenter, no label planes: the path a ROS camera takes).
//!
//! Every time is `CLOCK_MONOTONIC` on this one machine:
//! - **frames in**: the image stamp (taken just before publishing, mapped to
//!   MONOTONIC by the bridge: the frame's capture time) → the daemon took the
//!   frame from shared memory (`received_time_ns` of the pose message). DDS
//!   serialisation, the loopback hop of ~1.5 MB, pairing and the copy into
//!   the frame all count.
//! - **poses out**: the daemon published the pose message
//!   (`published_time_ns`) → this process took the `Detection3DArray` from
//!   its DDS reader.
//! - **ROS → ROS**: image stamp → detections taken; the daemon's own time included.
//!
//! Bridge CPU is `utime + stime` from `/proc/<pid>/stat` over the measured
//! seconds, as a share of one core.

use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::Context as _;
use fusepose_client::{Consumer, PoseMessage, monotonic_ns};
use fusepose_ros2::clock::ClockMap;
use fusepose_ros2::msg::{ByteBuf, CameraInfo, Detection3DArray, Header, Image, Time};
use fusepose_ros2::node::{open_node, topic};
use fusepose_ros2::qos::{DurabilityArg, ReliabilityArg, profile};
use ros2_client::dds::rustdds::mio1::{Events, Interest, Poll, Token};

use crate::child::IpcNamespace;
use crate::e2e::processes::CAMERA;
use crate::latency::{self, Percentiles};
use crate::loadavg;

/// Options of `fusepose-bench ros2`.
#[derive(Clone, Debug, clap::Args)]
pub struct Ros2Args {
    /// Frames per second the ROS side publishes.
    #[arg(long, default_value_t = 24.0)]
    pub fps: f64,
    /// Measured seconds (after 2 s of warm-up).
    #[arg(long, default_value_t = 30.0)]
    pub seconds: f64,
    /// Objects per frame.
    #[arg(long, alias = "objects", default_value_t = 5)]
    pub objects_per_frame: usize,
    /// Distinct rendered frames of the video (played back and forth).
    #[arg(long, default_value_t = 24)]
    pub video_frames: usize,
    /// Scene seed.
    #[arg(long, default_value_t = 7)]
    pub seed: u64,
    /// Network weights of the daemon.
    #[arg(long, default_value = "models/builtin.safetensors")]
    pub weights: PathBuf,
    /// The `fusepose-ros2` executable [default: beside this one].
    #[arg(long)]
    pub bridge: Option<PathBuf>,
    /// Folder for the table and the daemon log.
    #[arg(long, default_value = "scratch/bench/ros2")]
    pub out: PathBuf,
}

/// What one run measured.
pub struct Ros2Report {
    pub args: Ros2Args,
    pub sent: u64,
    pub frames_in: Percentiles,
    pub poses_out: Percentiles,
    pub ros_to_ros: Percentiles,
    /// Share of one core, % (camera bridge, pose bridge).
    pub cpu_percent: [f64; 2],
    pub load_before: String,
    pub load_after: String,
}

/// `utime + stime` of a process, seconds.
fn process_cpu_s(pid: u32) -> anyhow::Result<f64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat"))?;
    // Fields after the parenthesised command name; utime and stime are fields 14 and 15.
    let rest = stat.rsplit_once(')').map(|(_, r)| r).context("malformed /proc stat")?;
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks: f64 = f[11].parse::<f64>()? + f[12].parse::<f64>()?;
    // SAFETY: sysconf has no preconditions.
    let hz = unsafe { libc::sysconf(libc::_SC_CLK_TCK) } as f64;
    Ok(ticks / hz)
}

/// A bridge process, killed when dropped.
struct Bridge(Child);

impl Drop for Bridge {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// The ROS 2 messages of one rendered frame (stamps set when sent).
struct RosFrame {
    color: Image,
    depth: Image,
}

fn ros_frames(args: &Ros2Args) -> anyhow::Result<(Vec<RosFrame>, CameraInfo)> {
    let set = fusepose_scene::builtin::builtin_objects();
    let video = crate::video::render_video(&set, args.objects_per_frame, args.video_frames.max(1), 0.5, args.seed)?;
    let k = video.intrinsics;
    let header = Header { stamp: Time::default(), frame_id: "camera_color_optical_frame".into() };
    let frames = video
        .frames
        .iter()
        .map(|f| RosFrame {
            color: Image {
                header: header.clone(),
                height: k.height,
                width: k.width,
                encoding: "rgb8".into(),
                is_bigendian: 0,
                step: k.width * 3,
                data: ByteBuf(f.rgb.clone()),
            },
            // Renderer depth is in 0.1 mm; ROS 16UC1 depth is in mm (REP 118).
            depth: Image {
                header: header.clone(),
                height: k.height,
                width: k.width,
                encoding: "16UC1".into(),
                is_bigendian: 0,
                step: k.width * 2,
                data: ByteBuf(f.depth.iter().flat_map(|&d| (((d as u32 + 5) / 10) as u16).to_le_bytes()).collect()),
            },
        })
        .collect();
    let info = CameraInfo {
        header,
        height: k.height,
        width: k.width,
        distortion_model: "plumb_bob".into(),
        d: vec![0.0; 5],
        k: [k.fx, 0.0, k.cx, 0.0, k.fy, k.cy, 0.0, 0.0, 1.0],
        r: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        p: [k.fx, 0.0, k.cx, 0.0, 0.0, k.fy, k.cy, 0.0, 0.0, 0.0, 1.0, 0.0],
        ..CameraInfo::default()
    };
    Ok((frames, info))
}

/// Runs the daemon, both bridges and the ROS side; progress on stderr.
pub fn run(args: &Ros2Args) -> anyhow::Result<Ros2Report> {
    anyhow::ensure!(args.fps.is_finite() && args.fps > 0.0, "--fps must be positive");
    anyhow::ensure!(args.weights.exists(), "{} does not exist (the network weights)", args.weights.display());
    let bridge_exe = match &args.bridge {
        Some(p) => p.clone(),
        None => std::env::current_exe()?.with_file_name("fusepose-ros2"),
    };
    anyhow::ensure!(
        bridge_exe.exists(),
        "{} not found: build it (cargo build --release -p fusepose-ros2) or pass --bridge",
        bridge_exe.display()
    );
    std::fs::create_dir_all(&args.out)?;
    let (frames, info) = ros_frames(args)?;
    let load_before = loadavg::loadavg();

    // The daemon, exactly as `e2e` runs it, but the frames carry no labels: its segmenter runs.
    let ns = IpcNamespace::new("ros2")?;
    let e2e = crate::e2e::E2eArgs { weights: args.weights.clone(), ..Default::default() };
    let config_path = ns.dir.join("fuseposed.toml");
    let deadline_ms = 1000.0 / args.fps;
    std::fs::write(&config_path, crate::e2e::daemon_config(&e2e, &ns, deadline_ms, &ns.dir.join("d.hlog")))?;
    let log = args.out.join("ros2.daemon.log");
    let env = ns.env();
    let (_daemon, ipc, _stats) = crate::e2e::start_daemon(&ns, &config_path, &log)?;
    let mut consumer = Consumer::open(&ipc, CAMERA)?;

    let domain = 1 + (std::process::id() % 200) as u16;
    let bridge = |sub: &str, extra: &[&str]| -> anyhow::Result<Bridge> {
        let mut cmd = Command::new(&bridge_exe);
        cmd.arg(sub).args(["--name", CAMERA, "--domain-id", &domain.to_string()]).args(extra);
        cmd.envs(env.iter().map(|(k, v)| (*k, v.as_str()))).env("FUSEPOSE_LOG", "warn,rustdds=error");
        cmd.stdout(Stdio::null()).stderr(Stdio::inherit());
        Ok(Bridge(cmd.spawn().with_context(|| format!("starting {}", bridge_exe.display()))?))
    };
    let camera_bridge = bridge("ros2-camera", &[])?;
    let pose_bridge = bridge("ros2", &[])?;

    // The ROS side.
    let mut node = open_node(domain, "bench_ros_side")?;
    let sensor = profile(ReliabilityArg::BestEffort, 5, DurabilityArg::Volatile);
    let pub_of = |node: &mut ros2_client::Node, name: &str, ty: &str| {
        topic(node, name, "sensor_msgs", ty, &sensor).map_err(|e| anyhow::anyhow!("{e:#}"))
    };
    let color_t = pub_of(&mut node, "/camera/camera/color/image_raw", "Image")?;
    let depth_t = pub_of(&mut node, "/camera/camera/aligned_depth_to_color/image_raw", "Image")?;
    let info_t = pub_of(&mut node, "/camera/camera/color/camera_info", "CameraInfo")?;
    let color_pub = node.create_publisher::<Image>(&color_t, None).map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let depth_pub = node.create_publisher::<Image>(&depth_t, None).map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let info_pub = node.create_publisher::<CameraInfo>(&info_t, None).map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let det_qos = profile(ReliabilityArg::Reliable, 10, DurabilityArg::Volatile);
    let det_t =
        topic(&mut node, &format!("/fusepose/{CAMERA}/detections"), "vision_msgs", "Detection3DArray", &det_qos)?;
    let mut det_sub =
        node.create_subscription::<Detection3DArray>(&det_t, None).map_err(|e| anyhow::anyhow!("{e:?}"))?;

    // Detections are taken on their own thread, so that arrival times are not those of the publish loop.
    let arrivals: Arc<Mutex<Vec<(i64, u64)>>> = Arc::default();
    let stop = Arc::new(AtomicBool::new(false));
    let receiver = {
        let (arrivals, stop) = (arrivals.clone(), stop.clone());
        std::thread::spawn(move || -> anyhow::Result<()> {
            let mut poll = Poll::new()?;
            poll.registry().register(&mut det_sub, Token(0), Interest::READABLE)?;
            let mut events = Events::with_capacity(4);
            while !stop.load(Ordering::Relaxed) {
                let _ = poll.poll(&mut events, Some(Duration::from_millis(20)));
                while let Ok(Some((array, _))) = det_sub.take() {
                    arrivals.lock().expect("not poisoned").push((array.header.stamp.to_ns(), monotonic_ns()));
                }
            }
            Ok(())
        })
    };

    // Discovery: publish until the first detections come back (at most 30 s), then measure.
    let mut clock = ClockMap::new();
    let period = Duration::from_secs_f64(1.0 / args.fps);
    let warmup = (2.0 * args.fps).ceil() as u64;
    let measured = (args.seconds * args.fps).round() as u64;
    let mut sent_stamps = Vec::new();
    let mut messages: Vec<PoseMessage> = Vec::new();
    let mut cpu_start = [0.0; 2];
    let mut measure_start = Instant::now();
    let (mut i, mut measuring_from) = (0u64, None);
    eprintln!("ros2: {measured} frames at {} FPS on domain {domain} ...", args.fps);
    let t_start = Instant::now();
    loop {
        let tick = Instant::now();
        let f = &frames[crate::video::ping_pong(i as usize, frames.len())];
        let stamp = Time::from_ns(clock.monotonic_to_ros(monotonic_ns()));
        let mut color = f.color.clone();
        let mut depth = f.depth.clone();
        let mut ci = info.clone();
        (color.header.stamp, depth.header.stamp, ci.header.stamp) = (stamp, stamp, stamp);
        let _ = info_pub.publish(ci);
        let _ = color_pub.publish(color);
        let _ = depth_pub.publish(depth);
        i += 1;
        consumer.drain(&mut messages)?;
        if measuring_from.is_none() {
            let answered = !arrivals.lock().expect("not poisoned").is_empty();
            if answered && i >= warmup {
                measuring_from = Some(i);
                measure_start = Instant::now();
                cpu_start = [process_cpu_s(camera_bridge.0.id())?, process_cpu_s(pose_bridge.0.id())?];
            } else {
                anyhow::ensure!(
                    t_start.elapsed() < Duration::from_secs(30),
                    "no detections within 30 s: DDS discovery failed"
                );
            }
        } else {
            sent_stamps.push(stamp.to_ns());
            if sent_stamps.len() as u64 >= measured {
                break;
            }
        }
        if let Some(wait) = period.checked_sub(tick.elapsed()) {
            std::thread::sleep(wait);
        }
    }
    let wall = measure_start.elapsed().as_secs_f64();
    let cpu_end = [process_cpu_s(camera_bridge.0.id())?, process_cpu_s(pose_bridge.0.id())?];
    std::thread::sleep(Duration::from_millis(500));
    consumer.drain(&mut messages)?;
    stop.store(true, Ordering::Relaxed);
    receiver.join().map_err(|_| anyhow::anyhow!("detections thread panicked"))??;
    let load_after = loadavg::loadavg();

    // Join the three views of each measured frame by its stamp.
    let offset = clock.monotonic_to_ros(0);
    let arrivals = arrivals.lock().expect("not poisoned").clone();
    let (mut fin, mut pout, mut r2r) = (latency::histogram(), latency::histogram(), latency::histogram());
    let near = |a: i64, b: i64| (a - b).abs() < 1_000_000;
    for &stamp in &sent_stamps {
        let Some(msg) = messages.iter().find(|m| near(m.capture_time_ns as i64 + offset, stamp)) else { continue };
        fin.saturating_record(msg.received_time_ns.saturating_sub(msg.capture_time_ns).max(1));
        if let Some(&(_, at)) = arrivals.iter().find(|(s, _)| near(*s, stamp)) {
            pout.saturating_record(at.saturating_sub(msg.published_time_ns).max(1));
            r2r.saturating_record(at.saturating_sub(msg.capture_time_ns).max(1));
        }
    }
    let cpu = |k: usize| 100.0 * (cpu_end[k] - cpu_start[k]) / wall;
    Ok(Ros2Report {
        args: args.clone(),
        sent: sent_stamps.len() as u64,
        frames_in: Percentiles::of(&fin),
        poses_out: Percentiles::of(&pout),
        ros_to_ros: Percentiles::of(&r2r),
        cpu_percent: [cpu(0), cpu(1)],
        load_before,
        load_after,
    })
}

/// The report as a Markdown table.
pub fn render(r: &Ros2Report) -> String {
    let mut s = format!(
        "# fusepose-bench ros2: {} FPS, 640x480 rgb8 + 16UC1, {} objects, daemon with its segmenter\n\
         load before: {}  after: {}\n\n\
         | path | frames | p50 ms | p99 ms | p99.9 ms | max ms |\n|---|---|---|---|---|---|\n",
        r.args.fps, r.args.objects_per_frame, r.load_before, r.load_after
    );
    for (name, p) in [
        ("frames in: ROS image publish → daemon has the frame", &r.frames_in),
        ("poses out: daemon publishes → ROS subscriber has the detections", &r.poses_out),
        ("ROS → ROS: image publish → detections (daemon included)", &r.ros_to_ros),
    ] {
        let [a, b, c, d] = p.scaled(1e6);
        s += &format!("| {name} | {} of {} | {a:.2} | {b:.2} | {c:.2} | {d:.2} |\n", p.count, r.sent);
    }
    s += &format!(
        "\nCPU (share of one core over the measured {:.0} s): camera bridge {:.1} %, pose bridge {:.1} %\n",
        r.args.seconds, r.cpu_percent[0], r.cpu_percent[1]
    );
    s
}
