//! The three processes of `fusepose-bench e2e` besides the parent, as hidden
//! subcommands of the benchmark binary:
//!
//! - `e2e-daemon CONFIG LOG`: the daemon — exactly what `fuseposed --config
//!   CONFIG` runs (`engine::resolve` + `fusepose_daemon::run`), logging to LOG;
//! - `e2e-producer FPS FRAMES OBJECTS[:pair|:heap] SEED VIDEO_FRAMES [CAMERA [GO_FILE]]`:
//!   renders a video sequence, prints `ready`, waits for GO_FILE (when given:
//!   all producers start together), then publishes FRAMES frames at FPS
//!   (ping-pong over the video), capture time taken when each frame is loaned;
//! - `e2e-consumer FRAMES WARMUP FILE [CAMERA [OBJECTS SEED VIDEO_FRAMES]]`:
//!   receives every pose message through the client library (default wait
//!   strategy), writes capture → consumer latencies (ns, one per line) to
//!   FILE and prints `result <json>`; given the producer's video arguments,
//!   it renders the same video before the frames come and, once they are
//!   all in, scores each message's poses against its frame's truth
//!   ([`super::accuracy`]);
//! - `e2e-consumer-all SECONDS CAMERAS`: one process subscribed to every
//!   camera (comma-separated names) and to the cell; prints `result <json>`
//!   with the messages per camera, messages of a wrong camera, cell messages.

use std::io::Write;
use std::time::{Duration, Instant};

use fusepose_client::{
    Consumer, DepthMut, FrameLayout, Ipc, IpcOptions, LabelFormat, LabelsMut, PoseStatus, Producer, monotonic_ns,
};

use fusepose_scene::render::cast::Cast;

use crate::video::{self, DEPTH_SCALE_M};

/// The camera name every e2e process uses.
pub const CAMERA: &str = "cam0";

pub fn daemon_main(args: &[String]) -> anyhow::Result<()> {
    anyhow::ensure!(args.len() == 2, "usage: e2e-daemon CONFIG LOG");
    let config = fusepose_daemon::DaemonConfig::load(std::path::Path::new(&args[0]))?;
    let log = std::fs::File::create(&args[1])?;
    let filter = tracing_subscriber::EnvFilter::try_new(&config.log_level)?;
    tracing_subscriber::fmt().with_env_filter(filter).with_ansi(false).with_writer(std::sync::Mutex::new(log)).init();
    iceoryx2::prelude::set_log_level(iceoryx2::prelude::LogLevel::Warn);
    let spec = fusepose_daemon::engine::resolve(&config.estimator)?;
    println!("ready {}", spec.description);
    std::io::stdout().flush()?;
    fusepose_daemon::run(&config, &spec, None)?;
    Ok(())
}

pub fn producer_main(args: &[String]) -> anyhow::Result<()> {
    anyhow::ensure!(
        (6..=8).contains(&args.len()),
        "usage: e2e-producer FPS FRAMES SOURCE SEED VIDEO_FRAMES CAST [CAMERA [GO_FILE]] \
         (SOURCE: OBJECTS[:pair|:heap] or bop:HOLD:DIR; CAST: none, warm, cool or dim)"
    );
    let cast: Cast = args[5].parse().map_err(|e: String| anyhow::anyhow!(e))?;
    let camera = args.get(6).map_or(CAMERA, String::as_str);
    // With several producers: start sending only once every one has rendered its video.
    let go_file = args.get(7).map(std::path::PathBuf::from);
    let fps: f64 = args[0].parse()?;
    let frames: u64 = args[1].parse()?;
    // `N:pair` / `N:heap`: N classes, one of them standing twice as a
    // touching pair, or as a heap of copies; `bop:HOLD:DIR`: a BOP split.
    let source = video::Source::parse_arg(&args[2])?;
    let seed: u64 = args[3].parse()?;
    let video_frames: usize = args[4].parse()?;
    let set = fusepose_scene::builtin::builtin_objects();
    let mut video = source.load(&set, seed, video_frames)?;
    // The cast's noise is drawn once per video frame (a held image repeats it).
    for (i, f) in video.frames.iter_mut().enumerate() {
        cast.apply(&mut f.rgb, seed.wrapping_add(i as u64));
    }
    let k = video.intrinsics;
    let layout = FrameLayout {
        width: k.width,
        height: k.height,
        depth_scale: DEPTH_SCALE_M,
        labels: Some(LabelFormat::U16),
        ..FrameLayout::vga_rgbd()
    };
    let ipc = Ipc::new(&IpcOptions::from_env().with_node_name("e2e-producer"))?;
    let mut producer = Producer::create(&ipc, camera, layout)?;
    println!("ready");
    std::io::stdout().flush()?;
    if let Some(go) = &go_file {
        let waited = Instant::now();
        while !go.exists() {
            anyhow::ensure!(waited.elapsed() < Duration::from_secs(600), "{} never appeared", go.display());
            std::thread::sleep(Duration::from_millis(1));
        }
    }
    let period = Duration::from_secs_f64(1.0 / fps);
    let t0 = Instant::now();
    for i in 0..frames {
        let source = video.frame_at(i as usize);
        // Capture time = when the frame is loaned: copying it in counts as latency.
        let mut frame = producer.loan()?;
        frame.set_intrinsics(k.fx, k.fy, k.cx, k.cy);
        let planes = frame.planes_mut();
        planes.color.copy_from_slice(&source.rgb);
        if let DepthMut::U16(d) = planes.depth {
            d.copy_from_slice(&source.depth);
        }
        if let Some(LabelsMut::U16(l)) = planes.labels {
            l.copy_from_slice(&source.labels);
        }
        frame.send()?;
        if let Some(wait) = (t0 + period.mul_f64(i as f64 + 1.0)).checked_duration_since(Instant::now()) {
            std::thread::sleep(wait);
        }
    }
    let seconds = t0.elapsed().as_secs_f64();
    println!("done {frames} {seconds:.3}");
    // Linger so the last frame is not torn down before the daemon took it.
    std::thread::sleep(Duration::from_millis(500));
    Ok(())
}

/// What the consumer counted (frames with sequence ≥ WARMUP only).
#[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize)]
pub struct ConsumerCounts {
    pub messages: u64,
    pub ok: u64,
    pub deadline_missed: u64,
    pub degraded: u64,
    pub invalid: u64,
    pub estimator_failed: u64,
    pub objects: u64,
    pub refine_iterations: u64,
    /// Seconds between the first and the last counted message.
    pub span_s: f64,
    /// Messages whose camera id is not this consumer's camera (must stay 0).
    #[serde(default)]
    pub foreign: u64,
    /// The poses against the video's truth, when the consumer was given it.
    #[serde(default)]
    pub accuracy: Option<super::accuracy::AccuracyCounts>,
}

pub fn consumer_main(args: &[String]) -> anyhow::Result<()> {
    anyhow::ensure!(
        matches!(args.len(), 3 | 4 | 7),
        "usage: e2e-consumer FRAMES WARMUP FILE [CAMERA [SOURCE SEED VIDEO_FRAMES]]"
    );
    let frames: u64 = args[0].parse()?;
    let warmup: u64 = args[1].parse()?;
    let camera = args.get(3).map_or(CAMERA, String::as_str);
    let truths = match args.get(4..7) {
        Some([source, seed, video_frames]) => {
            Some(super::accuracy::Truths::load(source, seed.parse()?, video_frames.parse()?)?)
        }
        _ => None,
    };
    let mut accuracy = super::accuracy::AccuracyCounts::default();
    let mut received = Vec::with_capacity(if truths.is_some() { frames as usize } else { 0 });
    let own_id = fusepose_client::camera_id(camera);
    let ipc = Ipc::new(&IpcOptions::from_env().with_node_name("e2e-consumer"))?;
    let mut consumer = Consumer::open(&ipc, camera)?;
    println!("ready");
    std::io::stdout().flush()?;
    let mut latencies = Vec::with_capacity(frames as usize);
    let mut counts = ConsumerCounts::default();
    let mut batch = Vec::with_capacity(8);
    let (mut first, mut last) = (None, 0u64);
    let started = Instant::now();
    let mut idle_since = Instant::now();
    loop {
        let idle = idle_since.elapsed();
        if (first.is_some() && idle > Duration::from_secs(3)) || started.elapsed() > Duration::from_secs(3600) {
            break;
        }
        if first.is_none() && idle > Duration::from_secs(120) {
            anyhow::bail!("no pose message within 120 s");
        }
        if !consumer.wait_ready(Duration::from_millis(200))? {
            continue;
        }
        batch.clear();
        consumer.drain(&mut batch)?;
        let now = monotonic_ns();
        idle_since = Instant::now();
        let mut done = false;
        for msg in &batch {
            if msg.camera_id != own_id {
                counts.foreign += 1;
                continue;
            }
            done |= msg.frame_sequence + 1 >= frames;
            if msg.frame_sequence < warmup {
                continue;
            }
            first.get_or_insert(now);
            last = now;
            latencies.push(now.saturating_sub(msg.capture_time_ns));
            counts.messages += 1;
            counts.ok += msg.is_ok() as u64;
            counts.deadline_missed += (msg.status & PoseStatus::DEADLINE_MISSED != 0) as u64;
            counts.degraded += (msg.status & PoseStatus::DEGRADED != 0) as u64;
            counts.invalid += (msg.status & PoseStatus::INVALID_FRAME != 0) as u64;
            counts.estimator_failed += (msg.status & PoseStatus::ESTIMATOR_FAILED != 0) as u64;
            counts.objects += msg.objects().len() as u64;
            counts.refine_iterations += msg.objects().iter().map(|o| o.refine_iterations as u64).sum::<u64>();
            // Scored after the run: scoring now would take the CPU from the daemon.
            if truths.is_some() && msg.is_ok() && received.len() < received.capacity() {
                received.push((msg.frame_sequence, msg.objects().to_vec()));
            }
        }
        if done {
            break;
        }
    }
    counts.span_s = first.map_or(0.0, |f| (last - f) as f64 / 1e9);
    if let Some(t) = &truths {
        let mut last_ids = Vec::new();
        for (sequence, poses) in &received {
            t.score(*sequence, poses, &mut accuracy, &mut last_ids);
        }
    }
    counts.accuracy = truths.map(|_| accuracy);
    let text: String = latencies.iter().map(|v| format!("{v}\n")).collect();
    std::fs::write(&args[2], text)?;
    println!("result {}", serde_json::to_string(&counts)?);
    Ok(())
}

/// What the all-cameras consumer counted.
#[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize)]
pub struct AllCounts {
    /// Pose messages per camera, in the order given.
    pub per_camera: Vec<u64>,
    /// Messages whose camera id did not match the service they came on.
    pub foreign: u64,
    /// Cell messages, and the most cameras one of them combined.
    pub cell_messages: u64,
    pub cell_max_cameras: u16,
}

pub fn consumer_all_main(args: &[String]) -> anyhow::Result<()> {
    anyhow::ensure!(args.len() == 2, "usage: e2e-consumer-all SECONDS CAMERAS");
    let seconds: f64 = args[0].parse()?;
    let names: Vec<&str> = args[1].split(',').collect();
    let ipc = Ipc::new(&IpcOptions::from_env().with_node_name("e2e-consumer-all"))?;
    let mut consumers = names.iter().map(|n| Consumer::open(&ipc, n)).collect::<Result<Vec<_>, _>>()?;
    let mut cell = fusepose_client::CellConsumer::open(&ipc)?;
    println!("ready");
    std::io::stdout().flush()?;
    let mut counts = AllCounts { per_camera: vec![0; names.len()], ..AllCounts::default() };
    let (mut batch, mut cells) = (Vec::with_capacity(8), Vec::with_capacity(8));
    let end = Instant::now() + Duration::from_secs_f64(seconds);
    while Instant::now() < end {
        for (i, c) in consumers.iter_mut().enumerate() {
            batch.clear();
            c.drain(&mut batch)?;
            let id = fusepose_client::camera_id(names[i]);
            for msg in &batch {
                if msg.camera_id == id {
                    counts.per_camera[i] += 1;
                } else {
                    counts.foreign += 1;
                }
            }
        }
        cells.clear();
        cell.drain(&mut cells)?;
        counts.cell_messages += cells.len() as u64;
        counts.cell_max_cameras = cells.iter().map(|m| m.camera_count).fold(counts.cell_max_cameras, u16::max);
        std::thread::sleep(Duration::from_millis(5));
    }
    println!("result {}", serde_json::to_string(&counts)?);
    Ok(())
}
