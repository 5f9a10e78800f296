//! `fusepose-bench transport`: one-way latency of a 640×480 RGB-D frame
//! (1.5 MB) through the client library over iceoryx2 (loan → fill in place →
//! send + event → receiver wakes → `decode_frame`) against a Unix-domain-socket
//! copy of the same bytes, in the same run, each to a receiver process.
//!
//! iceoryx2 is measured with the three receive strategies of the client
//! library ([`WaitStrategy`]): blocking on the event (wake-up through the
//! kernel and scheduler), spin-then-wait near the predicted arrival (the
//! library default) and permanent busy polling (the payload path alone). The
//! difference between the first and the last is what the wake-up costs.
//!
//! Latency = receiver's `CLOCK_MONOTONIC` once it holds a validated, readable
//! frame minus the sender's clock just before `send` / `write_all`.

pub mod receiver;

use std::io::Write;
use std::os::unix::net::UnixListener;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use fusepose_client::{DepthMut, FrameLayout, Ipc, Producer, WaitStrategy, monotonic_ns};
use hdrhistogram::Histogram;

use crate::child::{ChildProcess, IpcNamespace};
use crate::latency::{self, Percentiles};
use crate::loadavg;

/// Options of `fusepose-bench transport`.
#[derive(Clone, Debug, clap::Args)]
pub struct TransportArgs {
    /// Frames sent per transport.
    #[arg(long, default_value_t = 1200)]
    pub frames: u64,
    /// Send rate, frames per second (a camera: 30).
    #[arg(long, default_value_t = 60.0)]
    pub fps: f64,
    /// First frames of each transport not counted (connection set-up, period learning).
    #[arg(long, default_value_t = 30)]
    pub warmup: u64,
    /// A short run (seconds; for CI).
    #[arg(long)]
    pub smoke: bool,
    /// Pin the sender to CPU 0 and each receiver to CPU 1 (as a deployment
    /// pins a camera driver and a consumer). Unpinned, a receiver polling near
    /// the arrival often shares a core with the woken sender and delays it.
    #[arg(long)]
    pub pin: bool,
    /// Folder for the table, PNG and `.hlog`.
    #[arg(long, default_value = "scratch/bench/transport")]
    pub out: PathBuf,
}

impl Default for TransportArgs {
    fn default() -> Self {
        Self { frames: 1200, fps: 60.0, warmup: 30, smoke: false, pin: false, out: "scratch/bench/transport".into() }
    }
}

/// One transport's result.
#[derive(Clone, Debug)]
pub struct ModeResult {
    pub name: String,
    pub tag: &'static str,
    pub latency: Percentiles,
    pub histogram: Histogram<u64>,
    /// Frames sent (after warm-up) that the receiver never saw (overwritten while it was descheduled).
    pub lost: u64,
    /// Receiver process CPU time over its wall time, percent of one core.
    pub receiver_cpu_percent: f64,
    /// Sender side: duration of the send call (iceoryx2: `send` + notify; socket: `write_all`).
    pub send_call: Percentiles,
    /// Receiver's own account: frames caught while polling, percent (iceoryx2 only),
    /// and its learned arrival jitter and timed wake-up lateness (µs).
    pub polled_percent: Option<f64>,
    pub jitter_us: Option<f64>,
    pub wake_delay_us: Option<f64>,
}

/// Everything one run measured.
#[derive(Clone, Debug)]
pub struct TransportReport {
    pub frame_bytes: usize,
    pub frames: u64,
    pub warmup: u64,
    pub fps: f64,
    pub modes: Vec<ModeResult>,
    pub load_before: String,
    pub load_after: String,
    pub png: Option<PathBuf>,
    pub hlog: Option<PathBuf>,
    pub pinned: bool,
}

impl TransportReport {
    pub fn mode(&self, tag: &str) -> Option<&ModeResult> {
        self.modes.iter().find(|m| m.tag == tag)
    }

    /// Unix-socket p50 over the p50 of iceoryx2 mode `tag`.
    pub fn ratio(&self, tag: &str) -> Option<f64> {
        let uds = self.mode("uds")?.latency.p50_ns as f64;
        let iox = self.mode(tag)?.latency.p50_ns.max(1) as f64;
        Some(uds / iox)
    }
}

/// Iceoryx2 receive strategies measured, with their table names.
pub const IOX_MODES: [(&str, &str, WaitStrategy); 3] = [
    ("iox-spin", "iceoryx2, spin-then-wait", WaitStrategy::DEFAULT_SPIN),
    ("iox-block", "iceoryx2, block on event", WaitStrategy::Block),
    ("iox-busy", "iceoryx2, busy poll (payload path only)", WaitStrategy::BusyPoll),
];

fn pace(t0: Instant, i: u64, period: Duration) {
    if let Some(wait) = (t0 + period.mul_f64(i as f64 + 1.0)).checked_duration_since(Instant::now()) {
        std::thread::sleep(wait);
    }
}

fn collect(
    name: &str,
    tag: &'static str,
    child: ChildProcess,
    file: &std::path::Path,
    counted: u64,
    send_call: &Histogram<u64>,
) -> anyhow::Result<ModeResult> {
    let mut child = child;
    let line = child.expect_line("result", Duration::from_secs(30))?;
    child.finish(Duration::from_secs(10))?;
    let cpu_percent: f64 = line.split_whitespace().next().and_then(|s| s.parse().ok()).unwrap_or(f64::NAN);
    let field = |key: &str| -> Option<f64> {
        let mut it = line.split_whitespace();
        it.find(|w| *w == key)?;
        it.next()?.parse().ok()
    };
    let (polled_percent, jitter_us, wake_delay_us) =
        (field("polled_percent"), field("jitter_us"), field("wake_delay_us"));
    let mut histogram = latency::histogram();
    for value in std::fs::read_to_string(file)?.lines().filter_map(|l| l.parse::<u64>().ok()) {
        histogram.saturating_record(value.max(1));
    }
    let _ = std::fs::remove_file(file);
    Ok(ModeResult {
        name: name.to_owned(),
        tag,
        latency: Percentiles::of(&histogram),
        lost: counted.saturating_sub(histogram.len()),
        histogram,
        receiver_cpu_percent: cpu_percent,
        send_call: Percentiles::of(send_call),
        polled_percent,
        jitter_us,
        wake_delay_us,
    })
}

fn run_iceoryx(
    args: &TransportArgs,
    frames: u64,
    tag: &'static str,
    name: &str,
    strategy: &str,
) -> anyhow::Result<ModeResult> {
    let ns = IpcNamespace::new(tag.trim_start_matches("iox-"))?;
    let ipc = Ipc::new(&ns.options())?;
    let layout = FrameLayout::vga_rgbd();
    let mut producer = Producer::create(&ipc, "bench", layout)?;
    let file = ns.dir.join("latencies.txt");
    let child_args = [
        "transport-receiver",
        "iox",
        strategy,
        &frames.to_string(),
        &args.warmup.to_string(),
        &file.display().to_string(),
    ]
    .map(String::from);
    let child =
        ChildProcess::spawn("iceoryx2 receiver", &child_args, &receiver_env(args, ns.env()), Duration::from_secs(20))?;
    std::thread::sleep(Duration::from_millis(200));
    let period = Duration::from_secs_f64(1.0 / args.fps);
    let mut send_call = latency::histogram();
    let t0 = Instant::now();
    for i in 0..frames {
        let mut frame = producer.loan()?;
        frame.set_intrinsics(525.0, 525.0, 319.5, 239.5);
        let planes = frame.planes_mut();
        planes.color.fill(i as u8);
        if let DepthMut::U16(d) = planes.depth {
            d.fill(1000);
        }
        // Send on the camera's clock: filling 1.5 MB took 0.1–1.9 ms here, and
        // a camera delivers at its frame rate, not when a copy happens to end.
        pace(t0, i, period);
        let start = monotonic_ns();
        frame.set_capture_time_ns(start);
        frame.send()?;
        if i >= args.warmup {
            send_call.saturating_record((monotonic_ns() - start).max(1));
        }
    }
    collect(name, tag, child, &file, frames.saturating_sub(args.warmup), &send_call)
}

fn run_socket(args: &TransportArgs, frames: u64) -> anyhow::Result<ModeResult> {
    let ns = IpcNamespace::new("uds")?;
    let socket = ns.dir.join("bench.sock");
    let listener = UnixListener::bind(&socket)?;
    let file = ns.dir.join("latencies.txt");
    let child_args = [
        "transport-receiver",
        "uds",
        &socket.display().to_string(),
        &frames.to_string(),
        &args.warmup.to_string(),
        &file.display().to_string(),
    ]
    .map(String::from);
    let child =
        ChildProcess::spawn("socket receiver", &child_args, &receiver_env(args, Vec::new()), Duration::from_secs(20))?;
    let (mut stream, _) = listener.accept()?;
    let frame_len = FrameLayout::vga_rgbd().payload_len();
    let mut buf = vec![0u8; 8 + frame_len];
    let period = Duration::from_secs_f64(1.0 / args.fps);
    let mut send_call = latency::histogram();
    let t0 = Instant::now();
    for i in 0..frames {
        buf[8..8 + frame_len * 3 / 5].fill(i as u8);
        buf[8 + frame_len * 3 / 5..].fill(0xe8);
        pace(t0, i, period);
        let now = monotonic_ns();
        buf[..8].copy_from_slice(&now.to_le_bytes());
        stream.write_all(&buf)?;
        if i >= args.warmup {
            send_call.saturating_record((monotonic_ns() - now).max(1));
        }
    }
    collect("Unix socket, copy", "uds", child, &file, frames.saturating_sub(args.warmup), &send_call)
}

/// Runs every transport in turn; progress on stderr.
/// Environment variable telling a receiver process which CPU to pin itself to.
pub const PIN_ENV: &str = "FUSEPOSE_BENCH_RECEIVER_CPU";

fn receiver_env(args: &TransportArgs, mut env: Vec<(&'static str, String)>) -> Vec<(&'static str, String)> {
    if args.pin {
        env.push((PIN_ENV, "1".into()));
    }
    env
}

pub fn run(args: &TransportArgs) -> anyhow::Result<TransportReport> {
    let load_before = loadavg::loadavg();
    if args.pin {
        fusepose_estimator::cpu_pin::pin_current_thread(0)
            .map_err(|e| anyhow::anyhow!("pinning the sender to CPU 0: {e}"))?;
    }
    let frames = if args.smoke { 60.min(args.frames).max(args.warmup + 10) } else { args.frames.max(args.warmup + 1) };
    let mut modes = Vec::new();
    for (tag, name, _) in IOX_MODES {
        eprintln!("transport: {name}, {frames} frames at {} fps ...", args.fps);
        modes.push(run_iceoryx(args, frames, tag, name, tag)?);
    }
    eprintln!("transport: Unix socket copy, {frames} frames ...");
    modes.push(run_socket(args, frames)?);

    std::fs::create_dir_all(&args.out)?;
    let series: Vec<(String, Percentiles)> = modes.iter().map(|m| (m.name.clone(), m.latency)).collect();
    let png = args.out.join("transport.png");
    let png =
        latency::plot_percentiles(&png, "640x480 RGB-D frame, one-way latency", "µs", 1e3, &series).ok().map(|_| png);
    let hlog = args.out.join("transport.hlog");
    let tagged: Vec<(String, &Histogram<u64>)> =
        modes.iter().map(|m| (format!("transport.{}", m.tag), &m.histogram)).collect();
    let duration_ns = (frames as f64 / args.fps * 1e9) as u64;
    let hlog = latency::write_hlog(&hlog, "fusepose-bench transport: one-way frame latency, ns", &tagged, duration_ns)
        .ok()
        .map(|_| hlog);
    Ok(TransportReport {
        frame_bytes: FrameLayout::vga_rgbd().payload_len(),
        frames,
        warmup: args.warmup,
        fps: args.fps,
        modes,
        load_before,
        load_after: loadavg::loadavg(),
        png,
        hlog,
        pinned: args.pin,
    })
}

/// The printed table.
pub fn render(r: &TransportReport) -> String {
    let mut s = String::new();
    s.push_str(&format!(
        "transport: 640x480 RGB8 + u16 depth = {} bytes per frame, {} frames per transport at {} fps (first {} not counted){}\n",
        r.frame_bytes,
        r.frames,
        r.fps,
        r.warmup,
        if r.pinned { "; sender pinned to CPU 0, receivers to CPU 1" } else { "; unpinned" }
    ));
    s.push_str(&format!("loadavg before: {}   cpus: {}\n\n", r.load_before, loadavg::cpus()));
    s.push_str(&format!(
        "{:<44} {:>6} {:>10} {:>10} {:>10} {:>10} {:>6} {:>12} {:>13} {:>9}\n",
        "transport", "n", "p50 µs", "p99 µs", "p99.9 µs", "max µs", "lost", "recv CPU %", "send p50 µs", "polled %"
    ));
    for m in &r.modes {
        let [p50, p99, p999, max] = m.latency.scaled(1e3);
        s.push_str(&format!(
            "{:<44} {:>6} {:>10.1} {:>10.1} {:>10.1} {:>10.1} {:>6} {:>12.1} {:>13.1} {:>9}\n",
            m.name,
            m.latency.count,
            p50,
            p99,
            p999,
            max,
            m.lost,
            m.receiver_cpu_percent,
            m.send_call.p50_ns as f64 / 1e3,
            m.polled_percent.map_or("-".to_owned(), |p| format!("{p:.1}"))
        ));
    }
    s.push('\n');
    for (tag, name, _) in IOX_MODES {
        if let Some(ratio) = r.ratio(tag) {
            s.push_str(&format!("ratio p50 Unix socket / {name}: {ratio:.1}x\n"));
        }
    }
    if let (Some(block), Some(busy)) = (r.mode("iox-block"), r.mode("iox-busy")) {
        s.push_str(&format!(
            "event wake-up cost (p50 block - p50 busy poll): {:.1} µs; payload path (busy poll p50): {:.1} µs\n",
            (block.latency.p50_ns as f64 - busy.latency.p50_ns as f64) / 1e3,
            busy.latency.p50_ns as f64 / 1e3
        ));
    }
    if let Some(m) = r.mode("iox-spin") {
        s.push_str(&format!(
            "spin-then-wait receiver: arrival jitter {:.1} µs, timed wake-up lateness {:.1} µs (learned)\n",
            m.jitter_us.unwrap_or(f64::NAN),
            m.wake_delay_us.unwrap_or(f64::NAN)
        ));
    }
    s.push_str("polled % = frames the receiver found while polling (the rest woke it through the event).\n");
    s.push_str(
        "send p50 = the sender's send call (iceoryx2: send + event notify; socket: write_all), part of the latency.\n",
    );
    if let Some(p) = &r.png {
        s.push_str(&format!("png: {}\n", p.display()));
    }
    if let Some(p) = &r.hlog {
        s.push_str(&format!("hlog: {}\n", p.display()));
    }
    s.push_str(&format!("loadavg after: {}\n", r.load_after));
    s
}
