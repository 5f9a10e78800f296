//! Harness for the multi-process integration tests in `tests/tests/`: an
//! isolated iceoryx2 root path and prefix per test, the `fuseposed` binary
//! (built on demand with cargo, same profile and target directory), and
//! child processes that are killed when a test ends.
//!
//! The test producer and consumer are binaries of this package
//! (`fp-test-producer`, `fp-test-consumer`), so cargo builds them for the tests.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::mpsc::{Receiver, channel};
use std::sync::{Mutex, OnceLock};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};

/// A per-test iceoryx2 namespace and scratch directory.
pub struct TestEnv {
    pub dir: tempfile::TempDir,
    pub iox_root: PathBuf,
    pub prefix: String,
}

impl TestEnv {
    pub fn new(name: &str) -> anyhow::Result<Self> {
        static COUNTER: AtomicUsize = AtomicUsize::new(0);
        let dir = tempfile::Builder::new().prefix(&format!("fusepose-{name}-")).tempdir()?;
        let iox_root = dir.path().join("iox2");
        std::fs::create_dir_all(&iox_root)?;
        let prefix = format!("fpt{}x{}_", std::process::id(), COUNTER.fetch_add(1, Ordering::Relaxed));
        Ok(Self { dir, iox_root, prefix })
    }

    /// Options for in-test-process iceoryx2 use (stats queries).
    pub fn ipc_options(&self) -> fusepose_client::IpcOptions {
        fusepose_client::IpcOptions {
            root_path: Some(self.iox_root.clone()),
            prefix: Some(self.prefix.clone()),
            ..Default::default()
        }
    }

    /// Sets the iceoryx2 namespace for a child process.
    pub fn apply(&self, cmd: &mut Command) {
        cmd.env("FUSEPOSE_IOX2_ROOT", &self.iox_root).env("FUSEPOSE_IOX2_PREFIX", &self.prefix);
    }

    pub fn hlog_path(&self) -> PathBuf {
        self.dir.path().join("fuseposed.hlog")
    }

    /// Writes a daemon config for camera `cam0` in this namespace; `extra` is
    /// appended verbatim inside `[estimator]` (e.g. `kind = "none"`).
    pub fn write_daemon_config(&self, estimator: &str) -> anyhow::Result<PathBuf> {
        self.write_daemon_config_named("fuseposed.toml", &["cam0"], estimator)
    }

    /// As [`TestEnv::write_daemon_config`], for `cameras`, into `file_name` in the scratch directory.
    pub fn write_daemon_config_named(
        &self,
        file_name: &str,
        cameras: &[&str],
        estimator: &str,
    ) -> anyhow::Result<PathBuf> {
        let path = self.dir.path().join(file_name);
        let text = format!(
            "cameras = {cameras:?}\nlog_level = \"info\"\n\n[estimator]\n{estimator}\n\n[stats]\nwindow_s = 1.0\nsummary_interval_s = 1.0\nhlog_path = {:?}\n\n[ipc]\nroot_path = {:?}\nprefix = {:?}\n",
            self.hlog_path(),
            self.iox_root,
            self.prefix
        );
        std::fs::write(&path, text)?;
        Ok(path)
    }
}

impl Drop for TestEnv {
    fn drop(&mut self) {
        // Shared memory of killed processes: remove this test's objects only.
        if let Ok(entries) = std::fs::read_dir("/dev/shm") {
            for entry in entries.flatten() {
                if entry.file_name().to_string_lossy().starts_with(&self.prefix) {
                    let _ = std::fs::remove_file(entry.path());
                }
            }
        }
    }
}

/// The `fuseposed` binary, built once per test process with the cargo that runs the tests.
pub fn daemon_binary() -> anyhow::Result<PathBuf> {
    workspace_binary("fusepose-daemon", "fuseposed")
}

/// Binary `bin` of workspace package `package`, built once per test process
/// with the cargo that runs the tests (same profile and target directory).
pub fn workspace_binary(package: &str, bin: &str) -> anyhow::Result<PathBuf> {
    static BUILT: OnceLock<Mutex<Vec<(String, PathBuf)>>> = OnceLock::new();
    let cell = BUILT.get_or_init(|| Mutex::new(Vec::new()));
    let mut built = cell.lock().unwrap_or_else(|e| e.into_inner());
    if let Some((_, path)) = built.iter().find(|(name, _)| name == bin) {
        return Ok(path.clone());
    }
    let profile_dir = profile_dir()?;
    let profile_dir = profile_dir.as_path();
    let target_dir = profile_dir.parent().context("profile directory has no parent")?;
    let profile = profile_dir.file_name().and_then(|s| s.to_str()).unwrap_or("debug");
    let workspace = workspace_root()?;
    let mut cmd = Command::new(env!("CARGO"));
    cmd.current_dir(&workspace).args(["build", "--quiet", "-p", package, "--bin", bin, "--target-dir"]).arg(target_dir);
    if profile == "release" {
        cmd.arg("--release");
    }
    let status = cmd.status().with_context(|| format!("running cargo build for {bin}"))?;
    if !status.success() {
        bail!("cargo build -p {package} --bin {bin} failed: {status}");
    }
    let path = profile_dir.join(bin);
    if !path.exists() {
        bail!("{} missing after cargo build", path.display());
    }
    built.push((bin.to_owned(), path.clone()));
    Ok(path)
}

/// The workspace root (the checkout).
pub fn workspace_root() -> anyhow::Result<PathBuf> {
    Ok(Path::new(env!("CARGO_MANIFEST_DIR")).parent().context("no workspace root")?.to_path_buf())
}

/// A child process killed (SIGKILL) when dropped, with its stdout lines on a channel.
pub struct Proc {
    pub name: &'static str,
    pub child: Child,
    pub lines: Receiver<String>,
}

impl Proc {
    /// Spawns `cmd` with piped stdout (lines collected) and stderr inherited.
    pub fn spawn(name: &'static str, cmd: Command) -> anyhow::Result<Self> {
        Self::spawn_with_stderr(name, cmd, Stdio::inherit())
    }

    /// Spawns `cmd` with piped stdout (lines collected) and the given stderr (e.g. a log file).
    pub fn spawn_with_stderr(name: &'static str, mut cmd: Command, stderr: Stdio) -> anyhow::Result<Self> {
        cmd.stdout(Stdio::piped()).stderr(stderr);
        let mut child = cmd.spawn().with_context(|| format!("spawning {name}"))?;
        let stdout = child.stdout.take().context("no stdout")?;
        let (tx, lines) = channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        Ok(Self { name, child, lines })
    }

    pub fn pid(&self) -> i32 {
        self.child.id() as i32
    }

    /// Sends `signal` (e.g. `libc::SIGTERM`).
    pub fn signal(&self, signal: i32) {
        // SAFETY: kill(2) on our own child's pid.
        unsafe { libc::kill(self.pid(), signal) };
    }

    /// Waits for the exit status up to `timeout`.
    pub fn wait_timeout(&mut self, timeout: Duration) -> anyhow::Result<std::process::ExitStatus> {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(status) = self.child.try_wait()? {
                return Ok(status);
            }
            if Instant::now() > deadline {
                bail!("{} did not exit within {timeout:?}", self.name);
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    /// Collects stdout lines until `done(all lines so far)` or `timeout`.
    pub fn collect_until(&self, out: &mut Vec<String>, timeout: Duration, done: impl Fn(&[String]) -> bool) -> bool {
        let deadline = Instant::now() + timeout;
        loop {
            if done(out) {
                return true;
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return false;
            }
            match self.lines.recv_timeout(left.min(Duration::from_millis(50))) {
                Ok(line) => out.push(line),
                Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {}
                Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => return done(out),
            }
        }
    }

    /// Waits for a stdout line starting with `prefix`.
    pub fn wait_for_line(&self, prefix: &str, timeout: Duration) -> anyhow::Result<String> {
        let deadline = Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.lines.recv_timeout(left) {
                Ok(line) if line.starts_with(prefix) => return Ok(line),
                Ok(_) => {}
                Err(_) => bail!("{}: no line starting with {prefix:?} within {timeout:?}", self.name),
            }
        }
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// `<target>/<profile>/` of the running test binary (`<profile>/deps/<test>`).
fn profile_dir() -> anyhow::Result<PathBuf> {
    let exe = std::env::current_exe()?;
    Ok(exe.parent().and_then(Path::parent).context("test binary has no profile directory")?.to_owned())
}

/// A binary of this package (cargo builds them before running integration tests).
pub fn package_binary(name: &str) -> anyhow::Result<PathBuf> {
    let path = profile_dir()?.join(name);
    anyhow::ensure!(path.exists(), "{} missing: run through `cargo test -p fusepose-tests`", path.display());
    Ok(path)
}

/// The `key=number` fields of a line starting with `prefix` (None when it
/// does not, or a field is not a number).
fn key_values<'a>(line: &'a str, prefix: &str) -> Option<std::collections::HashMap<&'a str, u64>> {
    let rest = line.strip_prefix(prefix)?;
    rest.split_whitespace().map(|kv| kv.split_once('=').and_then(|(k, v)| Some((k, v.parse().ok()?)))).collect()
}

/// One line printed by `fp-test-consumer` per pose message.
#[derive(Clone, Debug, PartialEq)]
pub struct PoseLine {
    pub sequence: u64,
    pub status: u32,
    pub invalid_reason: u32,
    pub objects: u16,
    pub camera_id: u32,
    pub capture_ns: u64,
    pub received_ns: u64,
    pub published_ns: u64,
}

impl PoseLine {
    /// Parses `pose seq=.. status=.. reason=.. objects=.. camera=.. capture=.. received=.. published=..`.
    pub fn parse(line: &str) -> Option<Self> {
        let fields = key_values(line, "pose ")?;
        Some(Self {
            sequence: *fields.get("seq")?,
            status: *fields.get("status")? as u32,
            invalid_reason: *fields.get("reason")? as u32,
            objects: *fields.get("objects")? as u16,
            camera_id: *fields.get("camera")? as u32,
            capture_ns: *fields.get("capture")?,
            received_ns: *fields.get("received")?,
            published_ns: *fields.get("published")?,
        })
    }

    pub fn format(msg: &fusepose_client::PoseMessage) -> String {
        format!(
            "pose seq={} status={} reason={} objects={} camera={} capture={} received={} published={}",
            msg.frame_sequence,
            msg.status,
            msg.invalid_reason,
            msg.object_count,
            msg.camera_id,
            msg.capture_time_ns,
            msg.received_time_ns,
            msg.published_time_ns
        )
    }
}

/// One line printed by `fp-test-consumer @cell` per cell message.
#[derive(Clone, Debug, PartialEq)]
pub struct CellLine {
    pub sequence: u64,
    pub cameras: u16,
    pub objects: u16,
    pub trigger: u32,
    pub published_ns: u64,
}

impl CellLine {
    /// Parses `cell seq=.. cameras=.. objects=.. trigger=.. published=..`.
    pub fn parse(line: &str) -> Option<Self> {
        let fields = key_values(line, "cell ")?;
        Some(Self {
            sequence: *fields.get("seq")?,
            cameras: *fields.get("cameras")? as u16,
            objects: *fields.get("objects")? as u16,
            trigger: *fields.get("trigger")? as u32,
            published_ns: *fields.get("published")?,
        })
    }

    pub fn format(msg: &fusepose_client::CellPoseMessage) -> String {
        format!(
            "cell seq={} cameras={} objects={} trigger={} published={}",
            msg.sequence, msg.camera_count, msg.object_count, msg.trigger_camera_id, msg.published_time_ns
        )
    }
}

/// Starts `fuseposed --config <config>` in `env`'s namespace and waits until it answers stats.
pub fn start_daemon(env: &TestEnv, config: &Path) -> anyhow::Result<Proc> {
    start_daemon_for(env, config, "cam0")
}

/// As [`start_daemon`], waiting for the stats of `camera` (one it serves).
pub fn start_daemon_for(env: &TestEnv, config: &Path, camera: &str) -> anyhow::Result<Proc> {
    let mut cmd = Command::new(daemon_binary()?);
    cmd.arg("--config").arg(config).current_dir(env.dir.path());
    let daemon = Proc::spawn("fuseposed", cmd)?;
    query_stats_of(env, camera, Duration::from_secs(20)).context("fuseposed never answered a stats request")?;
    Ok(daemon)
}

/// Spawns `fuseposed --config <config>` in `env`'s namespace without waiting
/// for it; its log (stderr) goes to `log` when given.
pub fn spawn_daemon(env: &TestEnv, config: &Path, log: Option<&Path>) -> anyhow::Result<Proc> {
    let mut cmd = Command::new(daemon_binary()?);
    cmd.arg("--config").arg(config).current_dir(env.dir.path());
    let stderr = match log {
        Some(path) => Stdio::from(std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?),
        None => Stdio::inherit(),
    };
    Proc::spawn_with_stderr("fuseposed", cmd, stderr)
}

/// Resident set size of process `pid`, bytes (`VmRSS` of `/proc/<pid>/status`).
pub fn rss_bytes(pid: i32) -> anyhow::Result<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status"))?;
    let line = status.lines().find(|l| l.starts_with("VmRSS:")).context("no VmRSS line")?;
    let kib: u64 = line.split_whitespace().nth(1).context("VmRSS without a value")?.parse()?;
    Ok(kib * 1024)
}

/// One reading of a process's memory, KiB (`/proc/<pid>/status`), `t_s` seconds into a run.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MemorySample {
    pub t_s: f64,
    /// `VmRSS`: everything resident.
    pub rss_kib: u64,
    /// `RssAnon`: private memory (heap, stacks): where a leak shows.
    pub anon_kib: u64,
    /// `RssShmem`: shared-memory pages mapped and touched (iceoryx2 segments).
    pub shmem_kib: u64,
    /// `RssFile`: mapped files (the executable, libraries).
    pub file_kib: u64,
}

/// Reads `pid`'s memory now.
pub fn memory_sample(pid: i32, t_s: f64) -> anyhow::Result<MemorySample> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status"))?;
    let field = |name: &str| -> anyhow::Result<u64> {
        let line = status.lines().find(|l| l.starts_with(name)).with_context(|| format!("no {name} line"))?;
        Ok(line.split_whitespace().nth(1).with_context(|| format!("{name} without a value"))?.parse()?)
    };
    Ok(MemorySample {
        t_s,
        rss_kib: field("VmRSS:")?,
        anon_kib: field("RssAnon:")?,
        shmem_kib: field("RssShmem:")?,
        file_kib: field("RssFile:")?,
    })
}

/// Asks the daemon for camera `cam0`'s stats, retrying until `timeout`.
pub fn query_stats(env: &TestEnv, timeout: Duration) -> anyhow::Result<fusepose_client::StatsSnapshot> {
    query_stats_of(env, "cam0", timeout)
}

/// Asks the daemon for `camera`'s stats, retrying until `timeout`.
pub fn query_stats_of(
    env: &TestEnv,
    camera: &str,
    timeout: Duration,
) -> anyhow::Result<fusepose_client::StatsSnapshot> {
    let ipc = fusepose_client::Ipc::new(&env.ipc_options())?;
    let client = fusepose_client::StatsClient::open(&ipc, camera)?;
    let deadline = Instant::now() + timeout;
    loop {
        match client.query(Duration::from_millis(500)) {
            Ok(s) => return Ok(s),
            Err(e) if Instant::now() > deadline => return Err(e.into()),
            Err(_) => {}
        }
    }
}

/// Starts the test producer: `frames` frames (0 = forever) at `fps` from sequence `start`,
/// breaking the frames whose sequence is in `malformed`.
pub fn start_producer(env: &TestEnv, frames: u64, fps: f64, start: u64, malformed: &[u64]) -> anyhow::Result<Proc> {
    start_producer_of(env, "cam0", frames, fps, start, malformed)
}

/// As [`start_producer`], for `camera`.
pub fn start_producer_of(
    env: &TestEnv,
    camera: &str,
    frames: u64,
    fps: f64,
    start: u64,
    malformed: &[u64],
) -> anyhow::Result<Proc> {
    let mut cmd = Command::new(package_binary("fp-test-producer")?);
    env.apply(&mut cmd);
    cmd.args([camera, &frames.to_string(), &fps.to_string(), &start.to_string()]);
    cmd.args(malformed.iter().map(u64::to_string));
    let p = Proc::spawn("fp-test-producer", cmd)?;
    p.wait_for_line("ready", Duration::from_secs(10))?;
    Ok(p)
}

/// Starts a test consumer that prints pose lines for up to `duration`.
pub fn start_consumer(env: &TestEnv, duration: Duration) -> anyhow::Result<Proc> {
    start_consumer_of(env, "cam0", duration)
}

/// As [`start_consumer`], for `camera`; `@cell` consumes the cell poses
/// (one `cell …` line per message, see [`CellLine`]).
pub fn start_consumer_of(env: &TestEnv, camera: &str, duration: Duration) -> anyhow::Result<Proc> {
    let mut cmd = Command::new(package_binary("fp-test-consumer")?);
    env.apply(&mut cmd);
    cmd.args([camera, &duration.as_millis().to_string()]);
    let p = Proc::spawn("fp-test-consumer", cmd)?;
    p.wait_for_line("ready", Duration::from_secs(10))?;
    Ok(p)
}

/// Pose lines among a consumer's output.
pub fn pose_lines(lines: &[String]) -> Vec<PoseLine> {
    lines.iter().filter_map(|l| PoseLine::parse(l)).collect()
}

/// Every interval histogram of an `.hlog` file, with its tag, decoded by hdrhistogram's own parser.
pub fn read_hlog(path: &Path) -> anyhow::Result<Vec<(String, hdrhistogram::Histogram<u64>)>> {
    use hdrhistogram::serialization::Deserializer;
    use hdrhistogram::serialization::interval_log::{IntervalLogIterator, LogEntry};
    let text = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    let mut out = Vec::new();
    for entry in IntervalLogIterator::new(&text) {
        let entry = entry.map_err(|e| anyhow::anyhow!("{}: unreadable entry: {e:?}", path.display()))?;
        if let LogEntry::Interval(interval) = entry {
            let tag = interval.tag().map(|t| t.as_str().to_owned()).unwrap_or_default();
            let bytes = base64_decode(interval.encoded_histogram())?;
            let h: hdrhistogram::Histogram<u64> = Deserializer::new()
                .deserialize(&mut &bytes[..])
                .map_err(|e| anyhow::anyhow!("{}: bad histogram for {tag}: {e:?}", path.display()))?;
            out.push((tag, h));
        }
    }
    Ok(out)
}

/// One interval of an `.hlog` file: its tag, start (seconds after the log's base time) and histogram.
pub struct HlogInterval {
    pub tag: String,
    pub start_s: f64,
    pub histogram: hdrhistogram::Histogram<u64>,
}

/// Every interval of an `.hlog` file with its start time, in file order.
pub fn read_hlog_intervals(path: &Path) -> anyhow::Result<Vec<HlogInterval>> {
    use hdrhistogram::serialization::Deserializer;
    use hdrhistogram::serialization::interval_log::{IntervalLogIterator, LogEntry};
    let text = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    let mut out = Vec::new();
    for entry in IntervalLogIterator::new(&text) {
        let entry = entry.map_err(|e| anyhow::anyhow!("{}: unreadable entry: {e:?}", path.display()))?;
        if let LogEntry::Interval(interval) = entry {
            let tag = interval.tag().map(|t| t.as_str().to_owned()).unwrap_or_default();
            let bytes = base64_decode(interval.encoded_histogram())?;
            let histogram: hdrhistogram::Histogram<u64> = Deserializer::new()
                .deserialize(&mut &bytes[..])
                .map_err(|e| anyhow::anyhow!("{}: bad histogram for {tag}: {e:?}", path.display()))?;
            out.push(HlogInterval { tag, start_s: interval.start_timestamp().as_secs_f64(), histogram });
        }
    }
    Ok(out)
}

/// Standard base64 (with padding) → bytes.
fn base64_decode(s: &str) -> anyhow::Result<Vec<u8>> {
    let val = |c: u8| -> anyhow::Result<u32> {
        Ok(match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' => 62,
            b'/' => 63,
            _ => bail!("invalid base64 character {c:#x}"),
        } as u32)
    };
    let bytes: Vec<u8> = s.bytes().filter(|&c| c != b'=').collect();
    let mut out = Vec::with_capacity(bytes.len() * 3 / 4);
    for chunk in bytes.chunks(4) {
        let mut acc = 0u32;
        for (i, &c) in chunk.iter().enumerate() {
            acc |= val(c)? << (18 - 6 * i);
        }
        out.extend_from_slice(&acc.to_be_bytes()[1..chunk.len()]);
    }
    Ok(out)
}

/// A wire pose (quaternion `[x, y, z, w]`, translation in metres) as an
/// object → camera isometry.
pub fn wire_pose(q: [f64; 4], t: [f64; 3]) -> nalgebra::Isometry3<f64> {
    let rotation = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[3], q[0], q[1], q[2]));
    nalgebra::Isometry3::from_parts(nalgebra::Translation3::new(t[0], t[1], t[2]), rotation)
}

/// Smallest ADD-S (m) of `msg`'s poses of class `class_id` against `truth`
/// (infinite when the message has none of that class).
pub fn best_add_s(
    msg: &fusepose_client::PoseMessage,
    class_id: u16,
    truth: &nalgebra::Isometry3<f64>,
    metric: &fusepose_scene::metrics::ObjectMetric,
) -> f64 {
    msg.objects()
        .iter()
        .filter(|o| o.class_id == class_id)
        .map(|o| metric.add_s(&wire_pose(o.quaternion, o.translation_m), truth))
        .fold(f64::INFINITY, f64::min)
}

/// Waits for the pose message answering frame `sequence`, skipping others.
pub fn wait_for_sequence(
    consumer: &mut fusepose_client::Consumer,
    sequence: u64,
    timeout: Duration,
) -> anyhow::Result<fusepose_client::PoseMessage> {
    let deadline = Instant::now() + timeout;
    while Instant::now() < deadline {
        if let Some(msg) = consumer.wait(Duration::from_millis(200))?
            && msg.frame_sequence == sequence
        {
            return Ok(msg);
        }
    }
    bail!("no pose message for frame {sequence} within {timeout:?}")
}

/// Largest growth of the daemon's private memory a soak accepts: the highest
/// `RssAnon` of the second half of the settled run over that of the first
/// half (`fp-soak`'s `anon_growth_pct`). Measured 0.00 % (ICP, 300 s) and
/// 0.01 % (network + segmenter, 300 s); allocator steps after settling were
/// at most 32 KiB (0.2 % of the ICP daemon's 14.8 MB). docs/RELIABILITY.md,
/// "Memory in soaks".
pub const MAX_SETTLED_GROWTH_PCT: f64 = 1.0;

/// Runs `fp-soak run <args>` with this build's `fuseposed` and returns its `soak` line as key → value.
pub fn run_fp_soak(args: &[&str]) -> anyhow::Result<std::collections::HashMap<String, String>> {
    let out = Command::new(package_binary("fp-soak")?)
        .arg("run")
        .args(args)
        .arg("--daemon")
        .arg(daemon_binary()?)
        .output()?;
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    anyhow::ensure!(out.status.success(), "fp-soak failed ({}):\n{stdout}\n{stderr}", out.status);
    for line in stdout.lines().filter(|l| l.starts_with("window ")) {
        println!("RESULT {line}");
    }
    let line = stdout.lines().find(|l| l.starts_with("soak ")).with_context(|| format!("no soak line:\n{stdout}"))?;
    println!("RESULT {line}");
    Ok(line
        .split_whitespace()
        .skip(1)
        .filter_map(|kv| kv.split_once('='))
        .map(|(k, v)| (k.to_owned(), v.to_owned()))
        .collect())
}

/// The number `key` of a soak result (panics with the whole result when missing).
pub fn soak_number(r: &std::collections::HashMap<String, String>, key: &str) -> f64 {
    r.get(key).and_then(|v| v.parse().ok()).unwrap_or_else(|| panic!("no numeric {key} in {r:?}"))
}

/// The layout of an unlabelled 640x480 frame as the renderer writes it
/// (rgb8, u16 depth in 0.1 mm): the daemon must segment it itself.
pub fn rendered_layout(k: &fusepose_scene::Intrinsics) -> fusepose_client::FrameLayout {
    fusepose_client::FrameLayout {
        width: k.width,
        height: k.height,
        color_format: fusepose_client::ColorFormat::Rgb8,
        depth_format: fusepose_client::DepthFormat::U16,
        depth_scale: 1e-4,
        labels: None,
    }
}

/// Sends what `target` holds (colour and depth, no labels) as one frame; returns its sequence.
pub fn send_rendered(
    producer: &mut fusepose_client::Producer,
    k: &fusepose_scene::Intrinsics,
    target: &fusepose_scene::render::RenderTarget,
) -> anyhow::Result<u64> {
    let mut frame = producer.loan()?;
    frame.set_intrinsics(k.fx, k.fy, k.cx, k.cy);
    let planes = frame.planes_mut();
    anyhow::ensure!(planes.labels.is_none(), "the layout must carry no labels");
    planes.color.copy_from_slice(target.rgb());
    match planes.depth {
        fusepose_client::DepthMut::U16(d) => d.copy_from_slice(target.depth_u16()),
        _ => anyhow::bail!("the layout must carry u16 depth"),
    }
    Ok(frame.send()?)
}
