//! `fusepose-bench e2e`: the daemon, a producer replaying a rendered video
//! (K objects, label planes) and a consumer, each its own process, at one or
//! more frame rates. Reports capture → consumer latency (p50/p99/p99.9/max),
//! achieved FPS, skipped frames (sent but never posed), deadline-missed and
//! degraded messages, and the refiner iterations the deadline left.
//!
//! Capture time is taken when the producer loans the frame, so the copy into
//! shared memory, the transport, the daemon, the pose message and the
//! consumer's wake-up all count. The first second of frames is warm-up.
//!
//! `--cameras N`: one daemon serving cameras cam0…cam(N−1), a producer and a
//! consumer per camera (each its own scene), and one consumer subscribed to
//! every camera and the cell; one row per camera, and the daemon's RSS.

pub mod accuracy;
pub mod processes;

use std::path::PathBuf;
use std::time::Duration;

use fusepose_client::{Ipc, StatsClient};
use fusepose_scene::render::cast::Cast;
use hdrhistogram::Histogram;

use crate::child::{ChildProcess, IpcNamespace};
use crate::latency::{self, Percentiles};
use crate::loadavg;
use processes::{CAMERA, ConsumerCounts};

/// Options of `fusepose-bench e2e`.
#[derive(Clone, Debug, clap::Args)]
pub struct E2eArgs {
    /// Frame rates to run, comma separated.
    #[arg(long, value_delimiter = ',', default_value = "24,30,60")]
    pub fps: Vec<f64>,
    /// Objects per frame.
    #[arg(long, alias = "objects", default_value_t = 5)]
    pub objects_per_frame: usize,
    /// One of the drawn classes stands twice, the copies side by side and
    /// touching (a frame then holds objects-per-frame + 1 objects).
    #[arg(long, conflicts_with = "heap")]
    pub pair: bool,
    /// One of the drawn classes is a heap of 4–8 copies touching and lying
    /// on each other.
    #[arg(long)]
    pub heap: bool,
    /// Cameras served by the one daemon, each with its own producer and consumer (1..=8).
    #[arg(long, default_value_t = 1)]
    pub cameras: usize,
    /// Measured seconds per frame rate (after 1 s of warm-up).
    #[arg(long, default_value_t = 20.0)]
    pub seconds: f64,
    /// Capture → publish deadline, ms (default: one frame period, 1000/fps).
    #[arg(long)]
    pub deadline_ms: Option<f64>,
    /// Network weights.
    #[arg(long, default_value = "models/builtin.safetensors")]
    pub weights: PathBuf,
    /// Network threads per frame, 1 or 2 (the daemon's `estimator.worker_threads`)
    /// [default: the daemon's own: the machine's CPUs, at most 2].
    #[arg(long)]
    pub threads: Option<usize>,
    /// Refiner iterations at most per object.
    #[arg(long, default_value_t = 2)]
    pub refine_iterations: usize,
    /// Turn deadline-aware degradation off (every frame in full).
    #[arg(long)]
    pub no_degrade: bool,
    /// Tracking mode on (`[estimator.tracking] enabled = true`).
    #[arg(long)]
    pub tracking: bool,
    /// Pin the daemon's loop and network worker to CPUs 0 and 1.
    #[arg(long)]
    pub pin: bool,
    /// The daemon's frame receive spin (`ipc.receive_spin_us`), µs.
    #[arg(long, default_value_t = 200)]
    pub receive_spin_us: u64,
    /// Distinct rendered frames of the video (played back and forth).
    #[arg(long, default_value_t = 48)]
    pub video_frames: usize,
    /// Replay the `test` split of this BOP dataset instead of a rendered
    /// video (e.g. a path-traced split of `tools/blender/render_bop_split.py`:
    /// images fusepose did not render); its frames in order, each held
    /// `--hold` frames, looping. `--objects-per-frame`, `--pair`, `--heap`,
    /// `--seed` and `--video-frames` do not apply.
    #[arg(long, conflicts_with_all = ["pair", "heap"])]
    pub source: Option<PathBuf>,
    /// With `--source`: frames each split image is sent for in a row (a still
    /// camera on each scene; `CONFIRMED` and stable ids need repeats).
    #[arg(long, default_value_t = 12)]
    pub hold: usize,
    /// Colour cast the producers apply to every frame (`none`, `warm`,
    /// `cool`, `dim`: as `fusepose eval --cast`), for a robustness column.
    #[arg(long, default_value = "none", value_parser = cast_arg())]
    pub cast: Cast,
    /// Scene seed.
    #[arg(long, default_value_t = 7)]
    pub seed: u64,
    /// Extra lines for the daemon config's `[estimator]` table (e.g. `masks = "net"`).
    #[arg(long, default_value = "")]
    pub estimator_extra: String,
    /// A short run (seconds; for CI).
    #[arg(long)]
    pub smoke: bool,
    /// Folder for the table, PNG, `.hlog` and daemon logs.
    #[arg(long, default_value = "scratch/bench/e2e")]
    pub out: PathBuf,
}

impl Default for E2eArgs {
    fn default() -> Self {
        Self {
            fps: vec![24.0, 30.0, 60.0],
            objects_per_frame: 5,
            pair: false,
            heap: false,
            cameras: 1,
            seconds: 20.0,
            deadline_ms: None,
            weights: "models/builtin.safetensors".into(),
            threads: None,
            refine_iterations: 2,
            no_degrade: false,
            tracking: false,
            pin: false,
            receive_spin_us: 200,
            video_frames: 48,
            source: None,
            hold: 12,
            cast: Cast::None,
            seed: 7,
            estimator_extra: String::new(),
            smoke: false,
            out: "scratch/bench/e2e".into(),
        }
    }
}

/// `--cast`'s parser: the casts' names as clap's possible values.
fn cast_arg() -> impl clap::builder::TypedValueParser<Value = Cast> {
    use clap::builder::TypedValueParser;
    clap::builder::PossibleValuesParser::new(Cast::ALL.map(Cast::name))
        .map(|s| s.parse::<Cast>().expect("a possible value names a cast"))
}

impl E2eArgs {
    /// The producers' video source.
    pub fn video_source(&self) -> crate::video::Source {
        match &self.source {
            Some(root) => crate::video::Source::Bop { root: root.clone(), hold: self.hold.max(1) },
            None => crate::video::Source::Rendered { objects: self.objects_per_frame, copies: self.copies() },
        }
    }

    /// The copies of one class in the producers' scenes.
    pub fn copies(&self) -> crate::video::Copies {
        use crate::video::Copies;
        match (self.pair, self.heap) {
            (_, true) => Copies::Heap,
            (true, false) => Copies::Pair,
            (false, false) => Copies::None,
        }
    }
}

/// One frame rate's result.
#[derive(Clone, Debug)]
pub struct RateResult {
    /// The camera of this row.
    pub camera: String,
    pub fps: f64,
    pub deadline_ms: f64,
    pub sent: u64,
    pub counts: ConsumerCounts,
    pub latency: Percentiles,
    pub histogram: Histogram<u64>,
    /// Consumer-side: messages later than the deadline at the consumer.
    pub late_at_consumer: u64,
    /// The daemon's own count of frames it dropped as stale (a newer one was waiting).
    pub daemon_stale: Option<u64>,
    pub estimator: String,
    /// The daemon's resident memory at the end of the run, KiB: whole, private,
    /// shared memory (same for every camera row).
    pub daemon_rss_kib: Option<[u64; 3]>,
    /// `--cameras N > 1`: what the consumer of all cameras counted (same for every row).
    pub all: Option<processes::AllCounts>,
}

impl RateResult {
    pub fn achieved_fps(&self) -> f64 {
        if self.counts.span_s > 0.0 {
            (self.counts.messages.saturating_sub(1)) as f64 / self.counts.span_s
        } else {
            0.0
        }
    }
    /// Frames sent (after warm-up) that got no pose message.
    pub fn skipped(&self) -> u64 {
        self.sent.saturating_sub(self.counts.messages)
    }
}

/// Everything one run measured.
#[derive(Clone, Debug)]
pub struct E2eReport {
    pub args: E2eArgs,
    pub rates: Vec<RateResult>,
    pub load_before: String,
    pub load_after: String,
    pub png: Option<PathBuf>,
    pub hlog: Option<PathBuf>,
}

/// The daemon's config of one run (also used by `ros2`).
pub fn daemon_config(args: &E2eArgs, ns: &IpcNamespace, deadline_ms: f64, hlog: &std::path::Path) -> String {
    let pins = if args.pin { "[0, 1]" } else { "[]" };
    format!(
        "cameras = {:?}\nlog_level = \"info\"\ndeadline_ms = {deadline_ms}\n\n[estimator]\nkind = \"net\"\nweights = {:?}\nmax_instances = 8\nrefine_iterations = {}\n{}deadline_aware = {}\npin_cpus = {pins}\n{}\n\n[estimator.tracking]\nenabled = {}\n\n[stats]\nwindow_s = 1.0\nsummary_interval_s = 0.0\nhlog_path = {:?}\n\n[ipc]\nroot_path = {:?}\nprefix = {:?}\nreceive_spin_us = {}\n",
        camera_names(args.cameras),
        args.weights.display().to_string(),
        args.refine_iterations,
        args.threads.map_or(String::new(), |t| format!("worker_threads = {}\n", t.clamp(1, 2))),
        !args.no_degrade,
        args.estimator_extra,
        args.tracking,
        hlog.display().to_string(),
        ns.root.display().to_string(),
        ns.prefix,
        args.receive_spin_us,
    )
}

/// The camera names of a run with `n` cameras (`cam0` first, as with one).
pub fn camera_names(n: usize) -> Vec<String> {
    (0..n.max(1)).map(|i| format!("cam{i}")).collect()
}

/// Resident memory of process `pid`, KiB: whole (`VmRSS`), private (`RssAnon`), shared memory (`RssShmem`).
fn rss_kib(pid: u32) -> Option<[u64; 3]> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let field = |name: &str| -> Option<u64> {
        status.lines().find_map(|l| l.strip_prefix(name))?.split_whitespace().next()?.parse().ok()
    };
    Some([field("VmRSS:")?, field("RssAnon:")?, field("RssShmem:")?])
}

/// Starts the daemon process of `config` (logging to `log`) in `ns` and
/// waits until it answers a stats query: then its services exist.
pub fn start_daemon(
    ns: &IpcNamespace,
    config: &std::path::Path,
    log: &std::path::Path,
) -> anyhow::Result<(ChildProcess, Ipc, StatsClient)> {
    let daemon = ChildProcess::spawn(
        "daemon",
        &["e2e-daemon".into(), config.display().to_string(), log.display().to_string()],
        &ns.env(),
        Duration::from_secs(120),
    )?;
    let ipc = Ipc::new(&ns.options())?;
    let stats = StatsClient::open(&ipc, CAMERA)?;
    let t0 = std::time::Instant::now();
    while stats.query(Duration::from_millis(300)).is_err() {
        anyhow::ensure!(
            t0.elapsed() < Duration::from_secs(60),
            "the daemon did not answer within 60 s (log: {})",
            log.display()
        );
    }
    Ok((daemon, ipc, stats))
}

/// One frame rate: a row per camera.
fn run_rate(args: &E2eArgs, fps: f64) -> anyhow::Result<Vec<RateResult>> {
    let seconds = if args.smoke { args.seconds.min(2.0) } else { args.seconds };
    let warmup = fps.ceil() as u64;
    let frames = warmup + (fps * seconds).round() as u64;
    let deadline_ms = args.deadline_ms.unwrap_or(1000.0 / fps);
    let ns = IpcNamespace::new(&format!("e2e{}", fps as u64))?;
    let tag = format!("{}fps", fps as u64);
    let config_path = ns.dir.join("fuseposed.toml");
    std::fs::write(
        &config_path,
        daemon_config(args, &ns, deadline_ms, &args.out.join(format!("e2e-{tag}.daemon.hlog"))),
    )?;
    let log = args.out.join(format!("e2e-{tag}.daemon.log"));
    let env = ns.env();

    let (daemon, ipc, _stats) = start_daemon(&ns, &config_path, &log)?;
    let names = camera_names(args.cameras);
    let files: Vec<PathBuf> = names.iter().map(|n| ns.dir.join(format!("latencies-{n}.txt"))).collect();
    let video_frames = if args.smoke { 4 } else { args.video_frames };
    let objects = args.video_source().arg();
    // Each consumer renders (or loads) its producer's video again to score the poses against its truth.
    let mut consumers = Vec::with_capacity(names.len());
    for (i, (name, file)) in names.iter().zip(&files).enumerate() {
        consumers.push(ChildProcess::spawn(
            "consumer",
            &[
                "e2e-consumer".into(),
                frames.to_string(),
                warmup.to_string(),
                file.display().to_string(),
                name.clone(),
                objects.clone(),
                (args.seed + i as u64).to_string(),
                video_frames.to_string(),
            ],
            &env,
            Duration::from_secs(300),
        )?);
    }
    let mut all = if names.len() > 1 {
        let seconds = frames as f64 / fps + 3.0;
        Some(ChildProcess::spawn(
            "consumer-all",
            &["e2e-consumer-all".into(), seconds.to_string(), names.join(",")],
            &env,
            Duration::from_secs(30),
        )?)
    } else {
        None
    };
    // Producers render their videos first and start together: a producer
    // still rendering must not load the machine while another one's frames count.
    let go = ns.dir.join("go");
    let mut producers = Vec::with_capacity(names.len());
    for (i, name) in names.iter().enumerate() {
        producers.push(ChildProcess::spawn(
            "producer",
            &[
                "e2e-producer".into(),
                fps.to_string(),
                frames.to_string(),
                objects.clone(),
                (args.seed + i as u64).to_string(),
                video_frames.to_string(),
                args.cast.name().into(),
                name.clone(),
                go.display().to_string(),
            ],
            &env,
            Duration::from_secs(600),
        )?);
    }
    std::fs::write(&go, b"")?;
    eprintln!(
        "e2e {fps} fps, {} camera(s): {frames} frames ({warmup} warm-up), deadline {deadline_ms:.1} ms ...",
        names.len()
    );
    let run_time = Duration::from_secs_f64(frames as f64 / fps + 60.0);
    for p in &mut producers {
        p.expect_line("done", run_time)?;
    }
    let mut counts = Vec::with_capacity(names.len());
    for c in &mut consumers {
        counts.push(serde_json::from_str::<ConsumerCounts>(&c.expect_line("result", Duration::from_secs(30))?)?);
    }
    let all_counts = match all.as_mut() {
        Some(a) => {
            Some(serde_json::from_str::<processes::AllCounts>(&a.expect_line("result", Duration::from_secs(30))?)?)
        }
        None => None,
    };
    let daemon_rss_kib = rss_kib(daemon.pid());
    let mut stale = Vec::with_capacity(names.len());
    for name in &names {
        let client = StatsClient::open(&ipc, name)?;
        stale.push(client.query(Duration::from_secs(1)).ok().map(|s| s.frames_skipped_stale));
    }
    daemon.interrupt();
    let _ = daemon.finish(Duration::from_secs(10));
    for p in producers.into_iter().chain(consumers).chain(all) {
        let _ = p.finish(Duration::from_secs(5));
    }
    let estimator = std::fs::read_to_string(&log)
        .ok()
        .and_then(|l| l.lines().find(|x| x.contains("fuseposed ready")).map(|x| x.to_owned()))
        .and_then(|l| l.split("estimator=").nth(1).map(|s| s.split(" deadline_ms").next().unwrap_or(s).to_owned()))
        .unwrap_or_default();

    let deadline_ns = (deadline_ms * 1e6) as u64;
    let mut rows = Vec::with_capacity(names.len());
    for (i, (name, counts)) in names.iter().zip(counts).enumerate() {
        let mut histogram = latency::histogram();
        let mut late = 0;
        for v in std::fs::read_to_string(&files[i])?.lines().filter_map(|l| l.parse::<u64>().ok()) {
            histogram.saturating_record(v.max(1));
            late += (v > deadline_ns) as u64;
        }
        rows.push(RateResult {
            camera: name.clone(),
            fps,
            deadline_ms,
            sent: frames - warmup,
            latency: Percentiles::of(&histogram),
            histogram,
            counts,
            late_at_consumer: late,
            daemon_stale: stale[i],
            estimator: estimator.clone(),
            daemon_rss_kib,
            all: all_counts.clone(),
        });
    }
    Ok(rows)
}

/// Runs every frame rate in turn; progress on stderr.
pub fn run(args: &E2eArgs) -> anyhow::Result<E2eReport> {
    anyhow::ensure!(args.weights.exists(), "{} does not exist (the network weights)", args.weights.display());
    anyhow::ensure!(args.fps.iter().all(|f| f.is_finite() && *f > 0.0), "--fps must be positive");
    anyhow::ensure!((1..=8).contains(&args.cameras), "--cameras must be in 1..=8");
    std::fs::create_dir_all(&args.out)?;
    let load_before = loadavg::loadavg();
    let mut rates = Vec::new();
    for &fps in &args.fps {
        rates.extend(run_rate(args, fps)?);
    }
    let series: Vec<(String, Percentiles)> = rates
        .iter()
        .map(|r| (format!("{} {} FPS, {} objects", r.camera, r.fps, args.objects_per_frame), r.latency))
        .collect();
    let png = args.out.join("e2e.png");
    let png = latency::plot_percentiles(
        &png,
        "capture -> consumer latency (daemon + network, 5 objects)",
        "ms",
        1e6,
        &series,
    )
    .ok()
    .map(|_| png);
    let hlog = args.out.join("e2e.hlog");
    let tagged: Vec<(String, &Histogram<u64>)> =
        rates.iter().map(|r| (format!("e2e.{}.{}fps", r.camera, r.fps), &r.histogram)).collect();
    let duration_ns = (args.seconds * 1e9) as u64;
    let hlog = latency::write_hlog(&hlog, "fusepose-bench e2e: capture -> consumer latency, ns", &tagged, duration_ns)
        .ok()
        .map(|_| hlog);
    Ok(E2eReport { args: args.clone(), rates, load_before, load_after: loadavg::loadavg(), png, hlog })
}

/// The printed table.
pub fn render(r: &E2eReport) -> String {
    let a = &r.args;
    let mut s = format!(
        "e2e: daemon (net, {} thread(s), refine <= {}, deadline-aware {}, tracking {}, pinned {}) + {} camera(s), each a producer ({}; colour cast {}) + consumer\n",
        a.threads.map_or_else(|| "machine's".to_owned(), |t| t.clamp(1, 2).to_string()),
        a.refine_iterations,
        !a.no_degrade,
        a.tracking,
        a.pin,
        a.cameras,
        a.video_source().describe(),
        a.cast.name()
    );
    if let Some(e) = r.rates.first().map(|r| &r.estimator).filter(|e| !e.is_empty()) {
        s.push_str(&format!("estimator: {e}\n"));
    }
    s.push_str(&format!("loadavg before: {}   cpus: {}\n\n", r.load_before, loadavg::cpus()));
    s.push_str(&format!(
        "{:>6} {:>6} {:>9} {:>8} {:>6} {:>6} {:>8} {:>8} {:>9} {:>8} {:>8} {:>8} {:>8} {:>8} {:>7}\n",
        "camera",
        "fps",
        "achieved",
        "deadline",
        "sent",
        "posed",
        "skipped",
        "missed",
        "late@cons",
        "degraded",
        "p50 ms",
        "p99 ms",
        "p99.9 ms",
        "max ms",
        "iters"
    ));
    for x in &r.rates {
        let [p50, p99, p999, max] = x.latency.scaled(1e6);
        let iters =
            if x.counts.objects > 0 { x.counts.refine_iterations as f64 / x.counts.objects as f64 } else { f64::NAN };
        s.push_str(&format!(
            "{:>6} {:>6.1} {:>9.2} {:>8.1} {:>6} {:>6} {:>8} {:>8} {:>9} {:>8} {:>8.2} {:>8.2} {:>8.2} {:>8.2} {:>7.2}\n",
            x.camera,
            x.fps,
            x.achieved_fps(),
            x.deadline_ms,
            x.sent,
            x.counts.messages,
            x.skipped(),
            x.counts.deadline_missed,
            x.late_at_consumer,
            x.counts.degraded,
            p50,
            p99,
            p999,
            max,
            iters
        ));
    }
    s.push_str("\nachieved = posed messages per second at the consumer; skipped = sent but never posed (the daemon keeps only the newest frame);\n");
    s.push_str("missed = DEADLINE_MISSED flags (capture -> publish > deadline); late@cons = capture -> consumer > deadline; iters = mean refiner iterations per object.\n");
    for x in &r.rates {
        let objects = if x.counts.messages > 0 { x.counts.objects as f64 / x.counts.messages as f64 } else { 0.0 };
        s.push_str(&format!(
            "{} {} fps: {:.2} objects per message, invalid {}, estimator failed {}, daemon stale drops {}, messages of another camera {}\n",
            x.camera,
            x.fps,
            objects,
            x.counts.invalid,
            x.counts.estimator_failed,
            x.daemon_stale.map_or("n/a".into(), |v| v.to_string()),
            x.counts.foreign
        ));
        if let Some(a) = &x.counts.accuracy {
            s.push_str(&format!(
                "{} {} fps: of {} true objects >= {:.0} % visible, {} found ({:.1} %: ADD-S < {:.0} % of the diameter), {} right by ADD(S) too ({:.1} %); wrong poses {} ({:.2} per message) of {} received, {} of them stray (near no object of their class); confirmed poses {}, {} of them wrong, {} stray; instance ids of found objects: {} kept, {} switched\n",
                x.camera,
                x.fps,
                a.visible,
                100.0 * accuracy::MIN_VISIBLE,
                a.found,
                a.found_pct(),
                100.0 * accuracy::MAX_ERROR_OF_DIAMETER,
                a.right,
                a.right_pct(),
                a.wrong,
                a.wrong_per_message(),
                a.poses,
                a.stray,
                a.confirmed,
                a.wrong_confirmed,
                a.stray_confirmed,
                a.id_kept,
                a.id_switched
            ));
        }
    }
    let mut fps_seen = Vec::new();
    for x in r.rates.iter().filter(|x| x.camera == "cam0") {
        if fps_seen.contains(&x.fps.to_bits()) {
            continue;
        }
        fps_seen.push(x.fps.to_bits());
        let mib = |k: u64| k as f64 / 1024.0;
        let rss = x.daemon_rss_kib.map_or("n/a".into(), |[all, anon, shm]| {
            format!("{:.1} MiB (private {:.1} MiB, shared memory {:.1} MiB)", mib(all), mib(anon), mib(shm))
        });
        s.push_str(&format!("{} fps: daemon RSS at the end {rss}", x.fps));
        if let Some(all) = &x.all {
            s.push_str(&format!(
                "; all-cameras consumer: messages per camera {:?}, of a wrong camera {}, cell messages {} (up to {} cameras each)",
                all.per_camera, all.foreign, all.cell_messages, all.cell_max_cameras
            ));
        }
        s.push('\n');
    }
    if let Some(p) = &r.png {
        s.push_str(&format!("png: {}\n", p.display()));
    }
    if let Some(p) = &r.hlog {
        s.push_str(&format!("hlog: {}\n", p.display()));
    }
    s.push_str(&format!("loadavg after: {}\n", r.load_after));
    s
}
