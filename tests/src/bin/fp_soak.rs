//! Soak and overload runs: `fuseposed` + a producer + a consumer, each a
//! separate process on a private iceoryx2 namespace, for a given time;
//! reports the daemon's memory over the run, deadline misses, skipped
//! frames, end-to-end latency (overall and per report window) and whether
//! anything crashed.
//!
//! ```text
//! cargo build --release -p fusepose-daemon -p fusepose-tests --bins
//! $CARGO_TARGET_DIR/release/fp-soak run --seconds 3600 --fps 24 --estimator net --objects-per-frame 5 \
//!     --report-window-s 600 --rss-trace soak-rss.csv          # the 1-hour network soak (docs/RELIABILITY.md)
//! ```
//!
//! `run` options: `--seconds N` (60), `--fps F` (30), `--estimator
//! icp|none|net` (icp), `--objects-per-frame K` (alias `--objects`; 2),
//! `--frames rect|render`: K labelled rectangles at 0.8 m (default for icp
//! and none) or rendered tabletop scenes of the built-in objects with K
//! objects each (default for net: 24 frames rendered at start, then looped),
//! `--labels gt|none`: send the label plane or not (default: gt for icp and
//! none; none for net, so the daemon runs its segmenter), `--weights PATH`
//! (net; default: the checkout's models/builtin.safetensors), `--warmup S`:
//! the start RSS is taken at the first sample after S seconds (default
//! min(10 % of the run, 30 s), at least 3 s) at which the daemon has
//! processed 10 frames, `--settle S`: memory growth is judged only after S
//! seconds (default a third of the run, at most 10 minutes, at least the
//! warm-up), `--report-window-s S` (default a sixth of the run): latency and
//! deadline misses per window, from the daemon's interval log,
//! `--rss-trace PATH`: CSV of every memory sample, `--daemon PATH` (default:
//! `fuseposed` next to this binary), `--log PATH` (daemon log; default in the
//! run's scratch directory, removed at the end).
//!
//! Memory: the daemon's RSS holds its private memory (`RssAnon`: heap and
//! stacks, where a leak shows) and the pages of the cameras' shared-memory
//! frames it has read (`RssShmem`). The second grows in steps whenever the
//! producer first hands over a sample slot the daemon had not read before and
//! is bounded by the frame service's data segment, so growth is judged on
//! private memory after the settle period: `anon_growth_pct` compares the
//! highest private RSS of the second half of the settled run with that of
//! its first half; `anon_slope_kib_per_min` is the least-squares slope over
//! the settled run.
//!
//! Output: one `window …` line per report window, then one `soak key=value
//! ...` line, parsed by the CI tests; exit status 1 when a process crashed
//! or the daemon did not exit 0 on SIGTERM.
//!
//! The roles `producer` and `consumer` are this binary run by `run` itself.

use std::io::Write;
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use fusepose_client::{
    ColorFormat, Consumer, DepthFormat, DepthMut, FrameLayout, Ipc, IpcOptions, LabelFormat, LabelsMut, PoseStatus,
    Producer, STAGE_COUNT, StatsClient, monotonic_ns,
};
use fusepose_tests::{MemorySample, Proc, TestEnv, memory_sample, query_stats, read_hlog_intervals};

const CAMERA: &str = "cam0";
/// Seconds a role may take to start (the producer renders its frames first)
/// and the consumer may wait for its first pose message.
const STARTUP_LIMIT_S: u64 = 120;
/// Frames the `render` producer renders before it starts sending (then loops).
const RENDERED_FRAMES: usize = 24;
/// Views per rendered scene.
const VIEWS_PER_SCENE: usize = 4;
/// First scene seed of rendered frames: far from training and validation seeds.
const SCENE_SEED: u64 = 910_000_000;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.first().map(String::as_str) {
        Some("run") => run(&args[1..]),
        Some("producer") => producer(&args[1..]),
        Some("consumer") => consumer(&args[1..]),
        _ => bail!(
            "usage: fp-soak run [--seconds N] [--fps F] [--estimator icp|none|net] [--objects-per-frame K] \
             [--frames rect|render] [--labels gt|none] [--weights PATH] [--warmup S] [--settle S] \
             [--report-window-s S] [--rss-trace PATH] [--daemon PATH] [--log PATH]"
        ),
    }
}

/// Value of `--name` (or its alias) in `args`, parsed.
fn option<T: std::str::FromStr>(args: &[String], names: &[&str]) -> anyhow::Result<Option<T>>
where
    T::Err: std::fmt::Display,
{
    match args.iter().position(|a| names.contains(&a.as_str())) {
        None => Ok(None),
        Some(i) => {
            let v = args.get(i + 1).with_context(|| format!("{} needs a value", names[0]))?;
            v.parse().map(Some).map_err(|e| anyhow::anyhow!("{} {v}: {e}", names[0]))
        }
    }
}

/// One frame's planes as the producer sends them.
struct FramePlanes {
    rgb: Vec<u8>,
    depth: Vec<u16>,
    labels: Vec<u16>,
}

/// K rectangles of classes 1.. (100×80 px) 3 cm proud of a table at 0.8 m on a 640×480 frame; depth in mm.
fn rectangle_frame(objects: u32) -> (FrameLayout, f64, FramePlanes) {
    let (w, h) = (640usize, 480usize);
    let mut labels = vec![0u16; w * h];
    for k in 0..objects as usize {
        let (u0, v0) = (40 + 140 * (k % 4), 60 + 200 * (k / 4 % 2));
        for v in v0..v0 + 80 {
            labels[v * w + u0..v * w + u0 + 100].fill((k % 8 + 1) as u16); // the built-in set has 8 classes
        }
    }
    // Each rectangle stands 3 cm proud of the table at 0.8 m (one lying in the
    // table's plane is the table to the daemon's support floor).
    let depth = labels.iter().map(|&l| if l == 0 { 800 } else { 770 }).collect();
    let planes = FramePlanes { rgb: vec![0; w * h * 3], depth, labels };
    (FrameLayout::vga_rgbd(), 525.0, planes)
}

/// Rendered tabletop scenes of the built-in objects, `objects` per scene, class-id labels; depth in 0.1 mm.
fn rendered_frames(objects: u32) -> anyhow::Result<(FrameLayout, fusepose_scene::Intrinsics, Vec<FramePlanes>)> {
    use fusepose_scene::render::{NoiseConfig, RenderTarget};
    use fusepose_scene::sampler::{LabelKind, SamplerConfig, render_view_labelled, sample_scene};
    let set = fusepose_scene::builtin::builtin_objects();
    let k = fusepose_scene::Intrinsics::YCB_VIDEO;
    let n = objects as usize;
    let cfg = SamplerConfig { min_objects: n, max_objects: n, views: VIEWS_PER_SCENE, ..SamplerConfig::default() };
    let mut target = RenderTarget::for_intrinsics(&k);
    let mut frames = Vec::with_capacity(RENDERED_FRAMES);
    let mut scene = None;
    for i in 0..RENDERED_FRAMES {
        if i % VIEWS_PER_SCENE == 0 {
            let seed = SCENE_SEED + (i / VIEWS_PER_SCENE) as u64;
            scene = Some(sample_scene(&set, &cfg, seed).map_err(|e| anyhow::anyhow!("scene {seed}: {e}"))?);
        }
        let scene = scene.as_ref().context("no scene")?;
        render_view_labelled(
            scene,
            &set,
            i % VIEWS_PER_SCENE,
            &k,
            &NoiseConfig::default(),
            LabelKind::Class,
            &mut target,
        )
        .map_err(|e| anyhow::anyhow!("rendering frame {i}: {e}"))?;
        frames.push(FramePlanes {
            rgb: target.rgb().to_vec(),
            depth: target.depth_u16().to_vec(),
            labels: target.labels().to_vec(),
        });
    }
    let layout = FrameLayout {
        width: k.width,
        height: k.height,
        color_format: ColorFormat::Rgb8,
        depth_format: DepthFormat::U16,
        depth_scale: 1e-4,
        labels: None,
    };
    Ok((layout, k, frames))
}

/// Producer role: `producer FPS SECONDS OBJECTS FRAMES(rect|render) LABELS(gt|none)`;
/// prints `sent N` at the end.
fn producer(args: &[String]) -> anyhow::Result<()> {
    let [fps, seconds, objects, kind, labels] = args else { bail!("producer FPS SECONDS OBJECTS FRAMES LABELS") };
    let (fps, seconds, objects): (f64, f64, u32) = (fps.parse()?, seconds.parse()?, objects.parse()?);
    let send_labels = labels == "gt";
    let (mut layout, k, frames) = match kind.as_str() {
        "rect" => {
            let (layout, f, planes) = rectangle_frame(objects);
            let k = fusepose_scene::Intrinsics { fx: f, fy: f, cx: 319.5, cy: 239.5, width: 640, height: 480 };
            (layout, k, vec![planes])
        }
        "render" => rendered_frames(objects)?,
        other => bail!("frames {other:?}: rect or render"),
    };
    layout.labels = send_labels.then_some(LabelFormat::U16);
    let ipc = Ipc::new(&IpcOptions::from_env().with_node_name("fp-soak-producer"))?;
    let mut producer = Producer::create(&ipc, CAMERA, layout)?;
    println!("ready");
    std::io::stdout().flush()?;
    let period = Duration::from_secs_f64(1.0 / fps);
    let (t0, end) = (Instant::now(), Instant::now() + Duration::from_secs_f64(seconds));
    let mut sent = 0u64;
    while Instant::now() < end {
        let src = &frames[sent as usize % frames.len()];
        let mut frame = producer.loan()?;
        frame.set_intrinsics(k.fx, k.fy, k.cx, k.cy);
        let planes = frame.planes_mut();
        planes.color.copy_from_slice(&src.rgb);
        if kind == "rect" {
            planes.color.fill((sent % 251) as u8);
        }
        if let DepthMut::U16(depth) = planes.depth {
            depth.copy_from_slice(&src.depth);
        }
        if let Some(LabelsMut::U16(labels)) = planes.labels {
            labels.copy_from_slice(&src.labels);
        }
        frame.send()?;
        sent += 1;
        if let Some(wait) = (t0 + period.mul_f64(sent as f64)).checked_duration_since(Instant::now()) {
            std::thread::sleep(wait);
        }
    }
    println!("sent {sent}");
    std::thread::sleep(Duration::from_millis(300)); // let the daemon take the last frame
    Ok(())
}

/// Consumer role: `consumer SECONDS` — counts pose messages; prints
/// `consumed messages=.. ok=.. objects=.. degraded=.. deadline_missed=.. p50_us=.. p99_us=.. max_us=..`
/// (flags counted per message; latency capture → received here).
fn consumer(args: &[String]) -> anyhow::Result<()> {
    let [seconds] = args else { bail!("consumer SECONDS") };
    let seconds: f64 = seconds.parse()?;
    let ipc = Ipc::new(&IpcOptions::from_env().with_node_name("fp-soak-consumer"))?;
    let mut consumer = Consumer::open(&ipc, CAMERA)?;
    println!("ready");
    std::io::stdout().flush()?;
    let mut latency = hdrhistogram::Histogram::<u64>::new_with_bounds(1_000, 600_000_000_000, 3)?;
    let (mut messages, mut ok, mut objects, mut degraded, mut late) = (0u64, 0u64, 0u64, 0u64, 0u64);
    // The run's clock starts at the first pose message, not at "ready": the
    // producer starts after this process and may take seconds to render its
    // frames, and a clock started here would end before the run does.
    let first_message_by = Instant::now() + Duration::from_secs(STARTUP_LIMIT_S);
    let mut end: Option<Instant> = None;
    let mut batch = Vec::with_capacity(16);
    while Instant::now() < end.unwrap_or(first_message_by) {
        if !consumer.wait_ready(Duration::from_millis(50))? {
            continue;
        }
        batch.clear();
        consumer.drain(&mut batch)?;
        if end.is_none() && !batch.is_empty() {
            end = Some(Instant::now() + Duration::from_secs_f64(seconds));
        }
        let now = monotonic_ns();
        for msg in &batch {
            messages += 1;
            degraded += u64::from(msg.status & PoseStatus::DEGRADED != 0);
            late += u64::from(msg.status & PoseStatus::DEADLINE_MISSED != 0);
            if msg.status & PoseStatus::OK != 0 {
                ok += 1;
                objects += msg.objects().len() as u64;
                latency.saturating_record(now.saturating_sub(msg.capture_time_ns).max(1_000));
            }
        }
    }
    let us = |q: f64| latency.value_at_quantile(q) as f64 / 1e3;
    println!(
        "consumed messages={messages} ok={ok} objects={objects} degraded={degraded} deadline_missed={late} \
         p50_us={:.0} p99_us={:.0} max_us={:.0}",
        us(0.5),
        us(0.99),
        latency.max() as f64 / 1e3
    );
    Ok(())
}

fn spawn_role(env: &TestEnv, role_args: &[String]) -> anyhow::Result<Proc> {
    let mut cmd = Command::new(std::env::current_exe()?);
    env.apply(&mut cmd);
    cmd.args(role_args);
    let name = if role_args[0] == "producer" { "fp-soak producer" } else { "fp-soak consumer" };
    let p = Proc::spawn_with_stderr(name, cmd, Stdio::inherit())?;
    p.wait_for_line("ready", Duration::from_secs(STARTUP_LIMIT_S))?;
    Ok(p)
}

/// Private-memory growth over the settled run: highest `RssAnon` of its second
/// half against its first half (%), and the least-squares slope (KiB per minute).
pub fn settled_growth(samples: &[MemorySample], settle_s: f64) -> Option<(f64, f64)> {
    let settled: Vec<&MemorySample> = samples.iter().filter(|s| s.t_s >= settle_s).collect();
    if settled.len() < 4 {
        return None;
    }
    let mid = settled[0].t_s + (settled[settled.len() - 1].t_s - settled[0].t_s) / 2.0;
    let max = |it: &mut dyn Iterator<Item = &&MemorySample>| it.map(|s| s.anon_kib).max().unwrap_or(0);
    let first = max(&mut settled.iter().filter(|s| s.t_s < mid));
    let second = max(&mut settled.iter().filter(|s| s.t_s >= mid));
    let growth = (second as f64 - first as f64) / first.max(1) as f64 * 100.0;
    let n = settled.len() as f64;
    let (mt, ma) =
        (settled.iter().map(|s| s.t_s).sum::<f64>() / n, settled.iter().map(|s| s.anon_kib as f64).sum::<f64>() / n);
    let (mut sxy, mut sxx) = (0.0, 0.0);
    for s in &settled {
        sxy += (s.t_s - mt) * (s.anon_kib as f64 - ma);
        sxx += (s.t_s - mt) * (s.t_s - mt);
    }
    let slope_per_min = if sxx > 0.0 { sxy / sxx * 60.0 } else { 0.0 };
    Some((growth, slope_per_min))
}

fn run(args: &[String]) -> anyhow::Result<()> {
    let seconds: f64 = option(args, &["--seconds"])?.unwrap_or(60.0);
    let fps: f64 = option(args, &["--fps"])?.unwrap_or(30.0);
    let objects: u32 = option(args, &["--objects-per-frame", "--objects"])?.unwrap_or(2);
    let estimator: String = option(args, &["--estimator"])?.unwrap_or_else(|| "icp".to_owned());
    anyhow::ensure!(["icp", "none", "net"].contains(&estimator.as_str()), "--estimator is icp, none or net");
    let net = estimator == "net";
    let frames: String = option(args, &["--frames"])?.unwrap_or_else(|| if net { "render" } else { "rect" }.into());
    let labels: String = option(args, &["--labels"])?.unwrap_or_else(|| if net { "none" } else { "gt" }.into());
    anyhow::ensure!(["gt", "none"].contains(&labels.as_str()), "--labels is gt or none");
    let warmup: f64 = option(args, &["--warmup"])?.unwrap_or((seconds * 0.1).clamp(3.0, 30.0));
    let settle: f64 = option(args, &["--settle"])?.unwrap_or((seconds / 3.0).min(600.0)).max(warmup);
    let report_window: f64 = option(args, &["--report-window-s"])?.unwrap_or(seconds / 6.0).max(1.0);
    let rss_trace: Option<PathBuf> = option(args, &["--rss-trace"])?;
    anyhow::ensure!(seconds > warmup + 1.0, "--seconds must exceed --warmup by more than 1 s");
    let daemon_path: PathBuf = match option::<PathBuf>(args, &["--daemon"])? {
        Some(p) => p,
        None => std::env::current_exe()?.parent().context("no binary directory")?.join("fuseposed"),
    };
    anyhow::ensure!(
        daemon_path.exists(),
        "{} missing: cargo build -p fusepose-daemon (or pass --daemon)",
        daemon_path.display()
    );
    let estimator_config = if net {
        let weights: PathBuf = option(args, &["--weights"])?
            .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../models/builtin.safetensors"));
        let weights = weights.canonicalize().with_context(|| format!("--weights {}", weights.display()))?;
        format!("kind = \"net\"\nweights = {:?}\nmasks = \"auto\"", weights.display().to_string())
    } else {
        format!("kind = {estimator:?}")
    };

    let env = TestEnv::new("soak")?;
    let config = env.write_daemon_config(&estimator_config)?;
    let log: PathBuf = option(args, &["--log"])?.unwrap_or_else(|| env.dir.path().join("fuseposed.log"));
    let mut cmd = Command::new(&daemon_path);
    cmd.arg("--config").arg(&config).current_dir(env.dir.path());
    let mut daemon = Proc::spawn_with_stderr("fuseposed", cmd, Stdio::from(std::fs::File::create(&log)?))?;
    query_stats(&env, Duration::from_secs(60)).context("fuseposed never answered")?;
    let ipc = Ipc::new(&env.ipc_options())?;
    let stats_client = StatsClient::open(&ipc, CAMERA)?;

    let mut consumer = spawn_role(&env, &["consumer".into(), format!("{}", seconds + 2.0)])?;
    let mut producer = spawn_role(
        &env,
        &["producer".into(), fps.to_string(), seconds.to_string(), objects.to_string(), frames.clone(), labels.clone()],
    )?;
    let started = Instant::now();
    let mut samples: Vec<MemorySample> = Vec::new();
    let mut rss_start = None;
    let mut rss_1min = None;
    let mut crashed: Vec<String> = Vec::new();
    // Memory is sampled while the producer still sends: once it exits, its
    // frame segment is unmapped and the daemon's RSS drops by those pages.
    let sample_until = Duration::from_secs_f64((seconds - 1.0).max(warmup));
    while started.elapsed() < sample_until {
        std::thread::sleep(Duration::from_millis(500));
        for p in [&mut daemon, &mut consumer] {
            if let Some(status) = p.child.try_wait()? {
                crashed.push(format!("{} exited early ({status})", p.name));
            }
        }
        if !crashed.is_empty() {
            break;
        }
        let t_s = started.elapsed().as_secs_f64();
        let sample = memory_sample(daemon.pid(), t_s)?;
        if rss_start.is_none()
            && t_s >= warmup
            && stats_client.query(Duration::from_secs(1)).is_ok_and(|s| s.frames_processed >= 10)
        {
            rss_start = Some(sample.rss_kib);
        }
        if rss_1min.is_none() && t_s >= 60.0 {
            rss_1min = Some(sample);
        }
        samples.push(sample);
    }
    let stats = stats_client.query(Duration::from_secs(5));
    let producer_status = producer.wait_timeout(Duration::from_secs(30));
    let mut producer_lines = Vec::new();
    producer.collect_until(&mut producer_lines, Duration::from_secs(1), |l| l.iter().any(|x| x.starts_with("sent ")));
    match producer_status {
        Ok(s) if s.success() => {}
        Ok(s) => crashed.push(format!("producer exited with {s}")),
        Err(e) => crashed.push(format!("producer: {e}")),
    }
    daemon.signal(libc::SIGTERM);
    match daemon.wait_timeout(Duration::from_secs(10)) {
        Ok(s) if s.code() == Some(0) => {}
        Ok(s) => crashed.push(format!("fuseposed exited with {s} on SIGTERM")),
        Err(e) => crashed.push(format!("fuseposed: {e}")),
    }
    let consumed = consumer.wait_for_line("consumed ", Duration::from_secs(30)).unwrap_or_else(|e| {
        crashed.push(format!("consumer: {e}"));
        String::new()
    });
    if let Some(path) = &rss_trace {
        let mut text = String::from("t_s,rss_kib,anon_kib,shmem_kib,file_kib\n");
        for s in &samples {
            text += &format!("{:.1},{},{},{},{}\n", s.t_s, s.rss_kib, s.anon_kib, s.shmem_kib, s.file_kib);
        }
        std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))?;
    }

    // Latency and deadline misses per report window, from the daemon's interval log.
    let stats = stats?;
    let deadline_ns = stats.deadline_ns;
    let intervals = read_hlog_intervals(&env.hlog_path()).unwrap_or_default();
    let windows = latency_windows(&intervals, report_window, deadline_ns);
    for (i, w) in windows.iter().enumerate() {
        println!(
            "window index={i} start_s={:.0} frames={} p50_ms={:.3} p99_ms={:.3} max_ms={:.3} deadline_misses={}",
            w.start_s,
            w.histogram.len(),
            w.histogram.value_at_quantile(0.5) as f64 / 1e6,
            w.histogram.value_at_quantile(0.99) as f64 / 1e6,
            w.histogram.max() as f64 / 1e6,
            w.late,
        );
    }
    let p99 = |w: &Window| w.histogram.value_at_quantile(0.99) as f64 / 1e6;
    // Drift compares whole windows: a trailing part-window (the last seconds
    // after the final full window) holds too few frames for a p99.
    let most = windows.iter().map(|w| w.histogram.len()).max().unwrap_or(0);
    let full: Vec<&Window> =
        windows.iter().filter(|w| !w.histogram.is_empty() && 2 * w.histogram.len() >= most).collect();
    let (p99_first, p99_last) = (full.first().map_or(0.0, |w| p99(w)), full.last().map_or(0.0, |w| p99(w)));
    let p99_max = full.iter().map(|w| p99(w)).fold(0.0, f64::max);
    let p99_drift = if p99_first > 0.0 { (p99_last - p99_first) / p99_first * 100.0 } else { 0.0 };

    let e2e = stats.since_start[STAGE_COUNT];
    let sent = producer_lines.iter().find_map(|l| l.strip_prefix("sent ")).unwrap_or("0");
    if rss_start.is_none() {
        crashed.push("the daemon never processed 10 frames after warm-up: no start RSS".to_owned());
    }
    let last = samples.last().copied().unwrap_or_default();
    let rss_start = rss_start.unwrap_or(last.rss_kib);
    let rss_peak = samples.iter().map(|s| s.rss_kib).max().unwrap_or(0);
    let growth = (last.rss_kib as f64 - rss_start as f64) / rss_start.max(1) as f64 * 100.0;
    let (anon_growth, anon_slope) = settled_growth(&samples, settle).unwrap_or((f64::NAN, f64::NAN));
    let settled_anon = samples.iter().find(|s| s.t_s >= settle).map_or(0, |s| s.anon_kib);
    let one_minute = rss_1min.unwrap_or_default();
    // NaN when the run ended before minute 1.
    let growth_since_1min = |now: u64, then: u64| {
        if then == 0 { f64::NAN } else { (now as f64 - then as f64) / then as f64 * 100.0 }
    };
    println!(
        "soak seconds={seconds} fps={fps} estimator={estimator} objects={objects} frames={frames} labels={labels} \
         sent={sent} received={} processed={} skipped_stale={} missed_sequence={} invalid={} deadline_misses={} \
         estimator_failures={} objects_shed={} poses_failed_verification={} frames_degraded={} e2e_p50_ms={:.3} e2e_p99_ms={:.3} e2e_max_ms={:.3} \
         rss_start_kib={rss_start} rss_end_kib={} rss_peak_kib={rss_peak} rss_growth_pct={growth:.2} \
         settle_s={settle:.0} anon_settled_kib={settled_anon} anon_end_kib={} anon_growth_pct={anon_growth:.2} \
         anon_slope_kib_per_min={anon_slope:.1} shmem_end_kib={} rss_1min_kib={} anon_1min_kib={} \
         rss_growth_since_1min_pct={:.2} anon_growth_since_1min_pct={:.2} \
         windows={} p99_first_window_ms={p99_first:.3} p99_last_window_ms={p99_last:.3} \
         p99_max_window_ms={p99_max:.3} p99_drift_pct={p99_drift:.1} crashes={} {}",
        stats.frames_received,
        stats.frames_processed,
        stats.frames_skipped_stale,
        stats.frames_missed_sequence,
        stats.frames_invalid,
        stats.deadline_misses,
        stats.estimator_failures,
        stats.objects_shed,
        stats.poses_failed_verification,
        stats.frames_degraded,
        e2e.p50_ns as f64 / 1e6,
        e2e.p99_ns as f64 / 1e6,
        e2e.max_ns as f64 / 1e6,
        last.rss_kib,
        last.anon_kib,
        last.shmem_kib,
        one_minute.rss_kib,
        one_minute.anon_kib,
        growth_since_1min(last.rss_kib, one_minute.rss_kib),
        growth_since_1min(last.anon_kib, one_minute.anon_kib),
        full.len(),
        crashed.len(),
        consumed.replace("consumed ", "consumer_").replace(' ', " consumer_"),
    );
    for c in &crashed {
        eprintln!("fp-soak: {c}");
    }
    if !crashed.is_empty() {
        std::process::exit(1);
    }
    Ok(())
}

/// End-to-end latency of one report window.
struct Window {
    start_s: f64,
    histogram: hdrhistogram::Histogram<u64>,
    /// Frames later than the deadline.
    late: u64,
}

/// The `cam0.end_to_end` intervals of the daemon's log merged into windows of `length_s`.
fn latency_windows(intervals: &[fusepose_tests::HlogInterval], length_s: f64, deadline_ns: u64) -> Vec<Window> {
    let mut windows: Vec<Window> = Vec::new();
    for iv in intervals.iter().filter(|iv| iv.tag == format!("{CAMERA}.end_to_end")) {
        let index = (iv.start_s / length_s).floor().max(0.0) as usize;
        while windows.len() <= index {
            let start_s = windows.len() as f64 * length_s;
            let histogram = hdrhistogram::Histogram::new_with_bounds(1, 60_000_000_000, 3).expect("constant bounds");
            windows.push(Window { start_s, histogram, late: 0 });
        }
        let w = &mut windows[index];
        let _ = w.histogram.add(&iv.histogram);
        w.late += iv
            .histogram
            .iter_recorded()
            .filter(|v| v.value_iterated_to() > deadline_ns)
            .map(|v| v.count_at_value())
            .sum::<u64>();
    }
    windows
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(t_s: f64, anon_kib: u64) -> MemorySample {
        MemorySample { t_s, anon_kib, ..MemorySample::default() }
    }

    #[test]
    fn growth_is_judged_after_the_settle_period_only() {
        // A step before settling (allocator warm-up) does not count; flat afterwards.
        let flat: Vec<MemorySample> =
            (0..120).map(|i| sample(i as f64 * 0.5, if i < 20 { 10_000 } else { 12_000 })).collect();
        let (growth, slope) = settled_growth(&flat, 20.0).unwrap();
        assert_eq!(growth, 0.0);
        assert!(slope.abs() < 1e-9, "{slope}");
        // A leak of 100 KiB per minute after settling shows in both numbers.
        let leak: Vec<MemorySample> =
            (0..120).map(|i| sample(i as f64 * 0.5, 12_000 + (i as f64 * 0.5 / 60.0 * 100.0) as u64)).collect();
        let (growth, slope) = settled_growth(&leak, 20.0).unwrap();
        assert!(growth > 0.2 && (slope - 100.0).abs() < 5.0, "{growth} {slope}");
        assert!(settled_growth(&leak, 1000.0).is_none(), "nothing settled");
    }
}
