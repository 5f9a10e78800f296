//! Soak and overload runs: `fuseposed` + a producer + a consumer, each a
//! separate process on a private iceoryx2 namespace, for a given time; reports
//! the daemon's RSS after warm-up and at the end, deadline misses, skipped
//! frames, end-to-end latency and whether anything crashed.
//!
//! ```text
//! cargo build -p fusepose-daemon -p fusepose-tests --bins      # (add --release for release numbers)
//! $CARGO_TARGET_DIR/debug/fp-soak run --seconds 3600 --fps 30 --estimator icp
//! ```
//!
//! `run` options: `--seconds N` (60), `--fps F` (30), `--estimator icp|none`
//! (icp), `--objects K` labelled objects per frame (2), `--warmup S`: the start
//! RSS is taken at the first sample after S seconds (default min(10 % of the
//! run, 30 s), at least 3 s) at which the daemon has processed 10 frames, so
//! buffers sized on the first frames are in it,
//! `--daemon PATH` (default: `fuseposed` next to this binary), `--log PATH`
//! (daemon log; default in the run's scratch directory, removed at the end).
//! Output: one `soak key=value ...` line, parsed by the CI test; exit status 1
//! when a process crashed or the daemon did not exit 0 on SIGTERM.
//!
//! The roles `producer` and `consumer` are this binary run by `run` itself.

use std::io::Write;
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use fusepose_client::{
    Consumer, DepthMut, FrameLayout, Ipc, IpcOptions, LabelFormat, LabelsMut, PoseStatus, Producer, STAGE_COUNT,
    StatsClient, monotonic_ns,
};
use fusepose_tests::{Proc, TestEnv, query_stats, rss_bytes};

const CAMERA: &str = "cam0";

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.first().map(String::as_str) {
        Some("run") => run(&args[1..]),
        Some("producer") => producer(&args[1..]),
        Some("consumer") => consumer(&args[1..]),
        _ => bail!(
            "usage: fp-soak run [--seconds N] [--fps F] [--estimator icp|none] [--objects K] [--warmup S] [--daemon PATH] [--log PATH]"
        ),
    }
}

/// Value of `--name` in `args`, parsed.
fn option<T: std::str::FromStr>(args: &[String], name: &str) -> anyhow::Result<Option<T>>
where
    T::Err: std::fmt::Display,
{
    match args.iter().position(|a| a == name) {
        None => Ok(None),
        Some(i) => {
            let v = args.get(i + 1).with_context(|| format!("{name} needs a value"))?;
            v.parse().map(Some).map_err(|e| anyhow::anyhow!("{name} {v}: {e}"))
        }
    }
}

/// Producer role: `producer FPS SECONDS OBJECTS` — 640x480 RGB8 + u16 depth +
/// u8 labels, `OBJECTS` rectangles of classes 1.. at 0.8 m; prints `sent N` at the end.
fn producer(args: &[String]) -> anyhow::Result<()> {
    let [fps, seconds, objects] = args else { bail!("producer FPS SECONDS OBJECTS") };
    let (fps, seconds, objects): (f64, f64, u32) = (fps.parse()?, seconds.parse()?, objects.parse()?);
    let ipc = Ipc::new(&IpcOptions::from_env().with_node_name("fp-soak-producer"))?;
    let layout = FrameLayout { labels: Some(LabelFormat::U8), ..FrameLayout::vga_rgbd() };
    let mut producer = Producer::create(&ipc, CAMERA, layout)?;
    println!("ready");
    std::io::stdout().flush()?;
    let period = Duration::from_secs_f64(1.0 / fps);
    let (t0, end) = (Instant::now(), Instant::now() + Duration::from_secs_f64(seconds));
    let mut sent = 0u64;
    while Instant::now() < end {
        let mut frame = producer.loan()?;
        frame.set_intrinsics(525.0, 525.0, 319.5, 239.5);
        let planes = frame.planes_mut();
        planes.color.fill((sent % 251) as u8);
        if let DepthMut::U16(depth) = planes.depth {
            depth.fill(800);
        }
        if let Some(LabelsMut::U8(labels)) = planes.labels {
            labels.fill(0);
            for k in 0..objects {
                let (u0, v0) = (40 + 140 * (k % 4), 60 + 200 * (k / 4 % 2));
                for v in v0..v0 + 80 {
                    labels[(v * 640 + u0) as usize..(v * 640 + u0 + 100) as usize].fill((k % 8 + 1) as u8); // the built-in set has at least 8 classes
                }
            }
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
/// `consumed messages=.. ok=.. p50_us=.. p99_us=.. max_us=..` (capture → received here).
fn consumer(args: &[String]) -> anyhow::Result<()> {
    let [seconds] = args else { bail!("consumer SECONDS") };
    let seconds: f64 = seconds.parse()?;
    let ipc = Ipc::new(&IpcOptions::from_env().with_node_name("fp-soak-consumer"))?;
    let mut consumer = Consumer::open(&ipc, CAMERA)?;
    println!("ready");
    std::io::stdout().flush()?;
    let mut latency = hdrhistogram::Histogram::<u64>::new_with_bounds(1_000, 600_000_000_000, 3)?;
    let (mut messages, mut ok) = (0u64, 0u64);
    let end = Instant::now() + Duration::from_secs_f64(seconds);
    let mut batch = Vec::with_capacity(16);
    while Instant::now() < end {
        if !consumer.wait_ready(Duration::from_millis(50))? {
            continue;
        }
        batch.clear();
        consumer.drain(&mut batch)?;
        let now = monotonic_ns();
        for msg in &batch {
            messages += 1;
            if msg.status & PoseStatus::OK != 0 {
                ok += 1;
                latency.saturating_record(now.saturating_sub(msg.capture_time_ns).max(1_000));
            }
        }
    }
    let us = |q: f64| latency.value_at_quantile(q) as f64 / 1e3;
    println!(
        "consumed messages={messages} ok={ok} p50_us={:.0} p99_us={:.0} max_us={:.0}",
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
    p.wait_for_line("ready", Duration::from_secs(20))?;
    Ok(p)
}

fn run(args: &[String]) -> anyhow::Result<()> {
    let seconds: f64 = option(args, "--seconds")?.unwrap_or(60.0);
    let fps: f64 = option(args, "--fps")?.unwrap_or(30.0);
    let objects: u32 = option(args, "--objects")?.unwrap_or(2);
    let estimator: String = option(args, "--estimator")?.unwrap_or_else(|| "icp".to_owned());
    let warmup: f64 = option(args, "--warmup")?.unwrap_or((seconds * 0.1).clamp(3.0, 30.0));
    anyhow::ensure!(["icp", "none"].contains(&estimator.as_str()), "--estimator is icp or none");
    anyhow::ensure!(seconds > warmup + 1.0, "--seconds must exceed --warmup by more than 1 s");
    let daemon_path: PathBuf = match option::<PathBuf>(args, "--daemon")? {
        Some(p) => p,
        None => std::env::current_exe()?.parent().context("no binary directory")?.join("fuseposed"),
    };
    anyhow::ensure!(
        daemon_path.exists(),
        "{} missing: cargo build -p fusepose-daemon (or pass --daemon)",
        daemon_path.display()
    );

    let env = TestEnv::new("soak")?;
    let config = env.write_daemon_config(&format!("kind = {estimator:?}"))?;
    let log: PathBuf = option(args, "--log")?.unwrap_or_else(|| env.dir.path().join("fuseposed.log"));
    let mut cmd = Command::new(&daemon_path);
    cmd.arg("--config").arg(&config).current_dir(env.dir.path());
    let mut daemon = Proc::spawn_with_stderr("fuseposed", cmd, Stdio::from(std::fs::File::create(&log)?))?;
    query_stats(&env, Duration::from_secs(30)).context("fuseposed never answered")?;
    let ipc = Ipc::new(&env.ipc_options())?;
    let stats_client = StatsClient::open(&ipc, CAMERA)?;

    let mut consumer = spawn_role(&env, &["consumer".into(), format!("{}", seconds + 2.0)])?;
    let mut producer =
        spawn_role(&env, &["producer".into(), fps.to_string(), seconds.to_string(), objects.to_string()])?;
    let started = Instant::now();
    let mut rss_start = None;
    let (mut rss_end, mut rss_peak) = (0u64, 0u64);
    let mut crashed: Vec<String> = Vec::new();
    while started.elapsed() < Duration::from_secs_f64(seconds) {
        std::thread::sleep(Duration::from_millis(500));
        for p in [&mut daemon, &mut consumer] {
            if let Some(status) = p.child.try_wait()? {
                crashed.push(format!("{} exited early ({status})", p.name));
            }
        }
        if !crashed.is_empty() {
            break;
        }
        rss_end = rss_bytes(daemon.pid())?;
        rss_peak = rss_peak.max(rss_end);
        if rss_start.is_none()
            && started.elapsed() >= Duration::from_secs_f64(warmup)
            && stats_client.query(Duration::from_secs(1)).is_ok_and(|s| s.frames_processed >= 10)
        {
            rss_start = Some(rss_end);
        }
    }
    let stats = stats_client.query(Duration::from_secs(5));
    let producer_status = producer.wait_timeout(Duration::from_secs(10));
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
    let consumed = consumer.wait_for_line("consumed ", Duration::from_secs(10)).unwrap_or_else(|e| {
        crashed.push(format!("consumer: {e}"));
        String::new()
    });

    let stats = stats?;
    let e2e = stats.since_start[STAGE_COUNT];
    let sent = producer_lines.iter().find_map(|l| l.strip_prefix("sent ")).unwrap_or("0");
    if rss_start.is_none() {
        crashed.push("the daemon never processed 10 frames after warm-up: no start RSS".to_owned());
    }
    let rss_start = rss_start.unwrap_or(rss_end);
    let growth = (rss_end as f64 - rss_start as f64) / rss_start.max(1) as f64 * 100.0;
    println!(
        "soak seconds={seconds} fps={fps} estimator={estimator} objects={objects} sent={sent} received={} processed={} \
         skipped_stale={} missed_sequence={} invalid={} deadline_misses={} estimator_failures={} \
         e2e_p50_ms={:.3} e2e_p99_ms={:.3} e2e_max_ms={:.3} rss_start_kib={} rss_end_kib={} rss_peak_kib={} \
         rss_growth_pct={growth:.2} crashes={} {}",
        stats.frames_received,
        stats.frames_processed,
        stats.frames_skipped_stale,
        stats.frames_missed_sequence,
        stats.frames_invalid,
        stats.deadline_misses,
        stats.estimator_failures,
        e2e.p50_ns as f64 / 1e6,
        e2e.p99_ns as f64 / 1e6,
        e2e.max_ns as f64 / 1e6,
        rss_start / 1024,
        rss_end / 1024,
        rss_peak / 1024,
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
