//! Transport latency of one 640x480 RGB-D frame (1.5 MB): iceoryx2 zero-copy
//! (fusepose wire path: loan → fill in place → send → event wake-up →
//! receive → validate) versus a Unix-domain-socket copy of the same bytes, in
//! the same run, each to a separate receiver process.
//!
//! Latency = receiver's CLOCK_MONOTONIC after it holds a readable frame minus
//! the sender's clock just before `send` / `write_all` (the frame already in
//! the sender's memory in both cases).
//!
//! ```sh
//! cargo run --release -p fusepose-client --example transport_bench -- [FRAMES] [FPS]
//! ```

use std::io::{BufRead, BufReader, Read, Write};
use std::os::unix::net::{UnixListener, UnixStream};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use fusepose_client::{
    CameraServices, DepthMut, FrameLayout, Ipc, IpcOptions, Producer, decode_frame, monotonic_ns,
};
use hdrhistogram::Histogram;

fn summary(h: &Histogram<u64>) -> String {
    let us = |q: f64| h.value_at_quantile(q) as f64 / 1e3;
    format!(
        "n={} p50={:.1}us p90={:.1}us p99={:.1}us p99.9={:.1}us max={:.1}us",
        h.len(),
        us(0.5),
        us(0.9),
        us(0.99),
        us(0.999),
        h.max() as f64 / 1e3
    )
}

fn new_histogram() -> Histogram<u64> {
    Histogram::new_with_bounds(1, 10_000_000_000, 3).unwrap()
}

fn child_iceoryx(root: &str, prefix: &str, frames: u64) -> anyhow::Result<()> {
    let options = IpcOptions { root_path: Some(root.into()), prefix: Some(prefix.into()), ..Default::default() };
    let ipc = Ipc::new(&options)?;
    let services = CameraServices::open(&ipc, "bench")?;
    let subscriber = services.frames.subscriber_builder().create().map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let listener = services.frame_events.listener_builder().create().map_err(|e| anyhow::anyhow!("{e:?}"))?;
    println!("ready");
    let mut h = new_histogram();
    let mut checksum = 0u64;
    let mut last_sequence = 0;
    let mut idle_since = Instant::now();
    // Frames overwritten while this process was descheduled (safe overflow) never
    // arrive: stop at the last sequence or after 2 s without frames.
    while last_sequence + 1 < frames && idle_since.elapsed() < Duration::from_secs(2) {
        listener.timed_wait(|_| {}, Duration::from_millis(200)).map_err(|e| anyhow::anyhow!("{e:?}"))?;
        while let Some(sample) = subscriber.receive().map_err(|e| anyhow::anyhow!("{e:?}"))? {
            let planes = decode_frame(sample.user_header(), sample.payload(), None)?;
            let now = monotonic_ns();
            checksum = checksum.wrapping_add(planes.color[planes.color.len() / 2] as u64);
            h.saturating_record(now - planes.header.capture_time_ns);
            last_sequence = planes.header.sequence;
            idle_since = Instant::now();
        }
    }
    println!("result {} lost={} (checksum {checksum})", summary(&h), frames - h.len());
    Ok(())
}

fn child_socket(path: &str, frames: u64, frame_len: usize) -> anyhow::Result<()> {
    let mut stream = UnixStream::connect(path)?;
    println!("ready");
    let mut buf = vec![0u8; 8 + frame_len];
    let mut h = new_histogram();
    let mut checksum = 0u64;
    for _ in 0..frames {
        stream.read_exact(&mut buf)?;
        let now = monotonic_ns();
        let sent = u64::from_le_bytes(buf[..8].try_into().unwrap());
        checksum = checksum.wrapping_add(buf[8 + frame_len / 2] as u64);
        h.saturating_record(now - sent);
    }
    println!("result {} (checksum {checksum})", summary(&h));
    Ok(())
}

fn spawn_child(args: &[&str]) -> anyhow::Result<(std::process::Child, BufReader<std::process::ChildStdout>)> {
    let mut child = Command::new(std::env::current_exe()?).args(args).stdout(Stdio::piped()).spawn()?;
    let mut out = BufReader::new(child.stdout.take().unwrap());
    let mut line = String::new();
    out.read_line(&mut line)?;
    anyhow::ensure!(line.trim() == "ready", "child said {line:?}");
    Ok((child, out))
}

fn finish(mut child: std::process::Child, mut out: BufReader<std::process::ChildStdout>) -> anyhow::Result<String> {
    let mut line = String::new();
    out.read_line(&mut line)?;
    child.wait()?;
    Ok(line.trim().trim_start_matches("result ").to_owned())
}

fn pace(t0: Instant, i: u64, period: Duration) {
    if let Some(wait) = (t0 + period.mul_f64(i as f64 + 1.0)).checked_duration_since(Instant::now()) {
        std::thread::sleep(wait);
    }
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let layout = FrameLayout::vga_rgbd();
    match args.first().map(String::as_str) {
        Some("child-iox") => return child_iceoryx(&args[1], &args[2], args[3].parse()?),
        Some("child-uds") => return child_socket(&args[1], args[2].parse()?, layout.payload_len()),
        _ => {}
    }
    let frames: u64 = args.first().map_or(Ok(2000), |s| s.parse())?;
    let fps: f64 = args.get(1).map_or(Ok(200.0), |s| s.parse())?;
    let period = Duration::from_secs_f64(1.0 / fps);
    let dir = tempfile::tempdir()?;
    let root = dir.path().join("iox2");
    std::fs::create_dir_all(&root)?;
    let prefix = format!("fpbench{}_", std::process::id());
    let frames_arg = frames.to_string();
    println!("{frames} frames of {} bytes (640x480 RGB8 + u16 depth) at {fps} fps", layout.payload_len());

    // iceoryx2
    let options = IpcOptions { root_path: Some(root.clone()), prefix: Some(prefix.clone()), ..Default::default() };
    let ipc = Ipc::new(&options)?;
    let mut producer = Producer::create(&ipc, "bench", layout)?;
    let (child, out) = spawn_child(&["child-iox", root.to_str().unwrap(), &prefix, &frames_arg])?;
    std::thread::sleep(Duration::from_millis(200));
    let t0 = Instant::now();
    for i in 0..frames {
        let mut frame = producer.loan()?;
        frame.set_intrinsics(525.0, 525.0, 319.5, 239.5);
        let planes = frame.planes_mut();
        planes.color.fill(i as u8);
        if let DepthMut::U16(d) = planes.depth {
            d.fill(1000);
        }
        frame.set_capture_time_ns(monotonic_ns());
        frame.send()?;
        pace(t0, i, period);
    }
    let iceoryx = finish(child, out)?;

    // Unix domain socket: same bytes, copied through the kernel.
    let socket = dir.path().join("bench.sock");
    let listener = UnixListener::bind(&socket)?;
    let (child, out) = spawn_child(&["child-uds", socket.to_str().unwrap(), &frames_arg])?;
    let (mut stream, _) = listener.accept()?;
    let mut buf = vec![0u8; 8 + layout.payload_len()];
    let t0 = Instant::now();
    for i in 0..frames {
        buf[8..].fill(i as u8);
        let now = monotonic_ns();
        buf[..8].copy_from_slice(&now.to_le_bytes());
        stream.write_all(&buf)?;
        pace(t0, i, period);
    }
    let uds = finish(child, out)?;

    drop(producer);
    drop(ipc);
    // iceoryx2 leaves a node-management object per prefix in /dev/shm: remove ours.
    for entry in std::fs::read_dir("/dev/shm")?.flatten() {
        if entry.file_name().to_string_lossy().starts_with(&prefix) {
            let _ = std::fs::remove_file(entry.path());
        }
    }
    println!("iceoryx2 (zero-copy, event wake-up): {iceoryx}");
    println!("unix socket (copy):                  {uds}");
    Ok(())
}
