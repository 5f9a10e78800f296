//! `fusepose demo`: the whole system on one machine, as separate processes
//! talking over iceoryx2 shared memory:
//!
//! - the daemon (`fusepose demo-daemon`, the `fuseposed` loop) with the
//!   built-in pose network embedded in this binary,
//! - a synthetic camera (`fusepose camera --synthetic`) rendering tabletop
//!   scenes of the built-in objects at 24 frames/s,
//! - a consumer (`fusepose demo-consumer`) that scores every pose against the
//!   camera's ground truth, prints a line per second and, at the end, a
//!   summary table, `summary.json` and overlay PNGs.
//!
//! All three are this same executable in hidden modes, so one
//! `cargo run --release -p fusepose-cli -- demo` builds and runs everything.
//! Each run gets a private iceoryx2 root directory and resource prefix, so it
//! never meets a daemon the user already runs. Ctrl-C stops the run early:
//! the consumer still prints its summary, every child is stopped and the
//! private shared memory is removed.

mod consumer;
mod daemon;
mod truth;

use std::fs::File;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};

pub use consumer::Args as ConsumerArgs;
pub use daemon::{Args as DaemonArgs, DemoEstimator};

/// The environment variables `IpcOptions::from_env` reads in every child.
const ROOT_ENV: &str = "FUSEPOSE_IOX2_ROOT";
const PREFIX_ENV: &str = "FUSEPOSE_IOX2_PREFIX";

/// Camera name used inside the private namespace.
const CAMERA: &str = "demo";

#[derive(clap::Args)]
pub struct Args {
    /// How long to measure, in seconds, counted from the first pose message.
    #[arg(long, default_value_t = 20.0, value_name = "SECONDS")]
    pub seconds: f64,
    /// Frame rate of the synthetic camera, frames per second.
    #[arg(long, default_value_t = 24.0)]
    pub fps: f64,
    /// Output directory for overlay PNGs, summary.json and the logs of the
    /// daemon and camera (created if missing).
    #[arg(long, default_value = "demo-out", value_name = "DIR")]
    pub out: PathBuf,
    /// Number of overlay PNGs to write, taken evenly over the run.
    #[arg(long, default_value_t = 4)]
    pub overlays: usize,
    /// Estimator the daemon runs.
    #[arg(long, value_enum, default_value = "net")]
    pub estimator: DemoEstimator,
    #[arg(long, value_name = "FILE", help = crate::weights::WEIGHTS_HELP)]
    pub weights: Option<PathBuf>,
    /// First scene seed of the synthetic camera; each scene is shown from
    /// --views-per-scene viewpoints, then the next seed follows. The default
    /// lies far from the seeds `fusepose train` renders and validates on.
    #[arg(long, default_value_t = 500_000_000)]
    pub seed: u64,
    /// Camera viewpoints per rendered scene.
    #[arg(long, default_value_t = 8)]
    pub views_per_scene: usize,
    /// Frames the camera renders before the run and then replays in a loop,
    /// so the frame rate holds on a slow machine (rendering costs ~35 ms of
    /// one core per frame); 0 renders every frame live.
    #[arg(long, default_value_t = 48, value_name = "FRAMES")]
    pub preload: usize,
}

/// A child process of the demo with its role for messages.
struct Role {
    name: &'static str,
    child: Child,
    log: Option<PathBuf>,
}

impl Role {
    fn signal(&self, signal: i32) {
        // SAFETY: kill(2) on our own child's pid; harmless if it already exited.
        unsafe { libc::kill(self.child.id() as libc::pid_t, signal) };
    }

    /// SIGTERM, then SIGKILL if it has not exited within `grace`.
    fn stop(&mut self, grace: Duration) -> Option<ExitStatus> {
        if let Ok(Some(status)) = self.child.try_wait() {
            return Some(status);
        }
        self.signal(libc::SIGTERM);
        let until = Instant::now() + grace;
        while Instant::now() < until {
            if let Ok(Some(status)) = self.child.try_wait() {
                return Some(status);
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        eprintln!("demo: {} did not stop within {grace:?}; killing it", self.name);
        let _ = self.child.kill();
        self.child.wait().ok()
    }

    /// The last lines of its log, for error messages.
    fn log_tail(&self) -> String {
        let Some(path) = &self.log else {
            return String::new();
        };
        let text = std::fs::read_to_string(path).unwrap_or_default();
        let lines: Vec<&str> = text.lines().collect();
        let tail = lines[lines.len().saturating_sub(15)..].join("\n");
        format!("\n--- last lines of {} ---\n{tail}", path.display())
    }
}

fn args_of(values: &[&dyn std::fmt::Display]) -> Vec<String> {
    values.iter().map(|v| v.to_string()).collect()
}

fn spawn(
    name: &'static str,
    exe: &Path,
    args: &[String],
    env: &[(&str, &str)],
    log: Option<PathBuf>,
) -> anyhow::Result<Role> {
    let mut cmd = Command::new(exe);
    cmd.args(args).stdin(Stdio::null());
    for (k, v) in env {
        cmd.env(k, v);
    }
    if let Some(path) = &log {
        let file = File::create(path).with_context(|| format!("creating {}", path.display()))?;
        cmd.stdout(file.try_clone()?).stderr(file);
    }
    #[cfg(target_os = "linux")]
    {
        use std::os::unix::process::CommandExt;
        // SAFETY: prctl is async-signal-safe; it only asks the kernel to send
        // SIGTERM to the child when the demo dies, so no child outlives it.
        unsafe {
            cmd.pre_exec(|| {
                libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM);
                Ok(())
            });
        }
    }
    let child = cmd.spawn().with_context(|| format!("starting the {name} ({})", exe.display()))?;
    Ok(Role { name, child, log })
}

pub fn run(args: Args) -> anyhow::Result<()> {
    if !(args.seconds.is_finite() && args.seconds > 0.0) {
        bail!("--seconds must be a positive number of seconds, got {}", args.seconds);
    }
    if !(args.fps.is_finite() && args.fps > 0.0) {
        bail!("--fps must be positive, got {}", args.fps);
    }
    let interrupted = Arc::new(AtomicBool::new(false));
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(signal, interrupted.clone()).context("installing the signal handler")?;
    }
    let exe = std::env::current_exe().context("locating the fusepose executable")?;
    let logs = args.out.join("logs");
    std::fs::create_dir_all(&logs).with_context(|| format!("creating {}", logs.display()))?;

    // Private iceoryx2 namespace: its own root directory and resource prefix.
    let run_dir = tempfile::Builder::new().prefix("fusepose-demo-").tempdir().context("creating the run directory")?;
    let root = run_dir.path().join("iox2");
    std::fs::create_dir_all(&root)?;
    let root = root.to_string_lossy().into_owned();
    let prefix = format!("fpdemo{}_", std::process::id());
    let env = [(ROOT_ENV, root.as_str()), (PREFIX_ENV, prefix.as_str())];

    let weights = crate::weights::resolve_weights(args.weights.as_deref())?;
    // The children run in this directory too, but take an absolute path anyway.
    let weights = std::fs::canonicalize(&weights).unwrap_or(weights);
    let estimator = match args.estimator {
        DemoEstimator::Net => "net",
        DemoEstimator::Icp => "icp",
    };
    println!(
        "fusepose demo: daemon ({estimator}), synthetic camera at {} frames/s, consumer; {} s; output in {}",
        args.fps,
        args.seconds,
        args.out.display()
    );
    let mut daemon = spawn(
        "daemon",
        &exe,
        &args_of(&[&"demo-daemon", &"--camera", &CAMERA, &"--estimator", &estimator, &"--weights", &weights.display()]),
        &env,
        Some(logs.join("daemon.log")),
    )?;
    let mut camera = spawn(
        "camera",
        &exe,
        &args_of(&[
            &"camera",
            &"--synthetic",
            &"--name",
            &CAMERA,
            &"--fps",
            &args.fps,
            &"--seed",
            &args.seed,
            &"--views-per-scene",
            &args.views_per_scene,
            &"--preload",
            &args.preload,
        ]),
        &env,
        Some(logs.join("camera.log")),
    )?;
    let mut consumer = spawn(
        "consumer",
        &exe,
        &args_of(&[
            &"demo-consumer",
            &"--camera",
            &CAMERA,
            &"--seconds",
            &args.seconds,
            &"--seed",
            &args.seed,
            &"--views-per-scene",
            &args.views_per_scene,
            &"--preload",
            &args.preload,
            &"--out",
            &args.out.display(),
            &"--overlays",
            &args.overlays,
        ]),
        &env,
        None,
    )?;

    // Wait for the consumer; a daemon or camera that dies first ends the run.
    let mut forwarded = false;
    let outcome: anyhow::Result<ExitStatus> = loop {
        if interrupted.load(Ordering::Relaxed) && !forwarded {
            // A terminal's Ctrl-C reaches every child already; a SIGTERM sent
            // to the demo alone does not, so pass the request on.
            consumer.signal(libc::SIGINT);
            forwarded = true;
        }
        match consumer.child.try_wait() {
            Ok(Some(status)) => break Ok(status),
            Ok(None) => {}
            Err(e) => break Err(e.into()),
        }
        if !interrupted.load(Ordering::Relaxed) {
            let mut died = None;
            for role in [&mut daemon, &mut camera] {
                if let Ok(Some(status)) = role.child.try_wait() {
                    died = Some(anyhow::anyhow!("the {} exited early ({status}){}", role.name, role.log_tail()));
                    break;
                }
            }
            if let Some(e) = died {
                consumer.stop(Duration::from_secs(5));
                break Err(e);
            }
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    camera.stop(Duration::from_secs(3));
    let daemon_status = daemon.stop(Duration::from_secs(10));
    drop(run_dir); // removes the private iceoryx2 root
    remove_shared_memory(&prefix);
    println!("logs: {}", logs.display());
    let status = outcome?;
    if interrupted.load(Ordering::Relaxed) {
        eprintln!("demo: interrupted; all processes stopped");
        std::process::exit(130);
    }
    if !status.success() {
        bail!("the consumer failed ({status}){}{}", daemon.log_tail(), camera.log_tail());
    }
    if daemon_status.is_some_and(|s| !s.success() && s.code().is_some()) {
        eprintln!("demo: the daemon exited with an error on shutdown{}", daemon.log_tail());
    }
    Ok(())
}

/// Removes what iceoryx2 leaves in `/dev/shm` under this run's prefix once
/// every process has exited (its per-prefix global management segment
/// outlives the nodes). The prefix holds this process's id, so nothing
/// else can match it.
fn remove_shared_memory(prefix: &str) {
    let Ok(entries) = std::fs::read_dir("/dev/shm") else {
        return;
    };
    for entry in entries.flatten() {
        if entry.file_name().to_string_lossy().starts_with(prefix) {
            let _ = std::fs::remove_file(entry.path());
        }
    }
}

/// Hidden mode: the demo's daemon.
pub fn run_daemon(args: DaemonArgs) -> anyhow::Result<()> {
    daemon::run(args)
}

/// Hidden mode: the demo's consumer.
pub fn run_consumer(args: ConsumerArgs) -> anyhow::Result<()> {
    consumer::run(args)
}
