//! `fusepose stats`: ask fuseposed for one camera's counters and latency
//! percentiles and print them as a table.
//!
//! The iceoryx2 namespace comes from `FUSEPOSE_IOX2_ROOT` / `FUSEPOSE_IOX2_PREFIX`.

use std::time::Duration;

use fusepose_client::{InvalidReason, Ipc, IpcOptions, LatencySummary, Stage, StatsClient, StatsSnapshot};

#[derive(clap::Args)]
pub struct Args {
    /// Camera name.
    #[arg(long, default_value = "cam0")]
    pub name: String,
    /// How long to wait for the daemon's answer, milliseconds.
    #[arg(long, default_value_t = 2000)]
    pub timeout_ms: u64,
}

fn row(name: &str, s: &LatencySummary) -> String {
    let ms = |ns: u64| ns as f64 / 1e6;
    format!(
        "  {:<13} {:>8} {:>9.3} {:>9.3} {:>9.3} {:>9.3} {:>9.3}",
        name,
        s.count,
        ms(s.p50_ns),
        ms(s.p90_ns),
        ms(s.p99_ns),
        ms(s.p999_ns),
        ms(s.max_ns)
    )
}

/// The table `fusepose stats` prints.
pub fn render(camera: &str, s: &StatsSnapshot) -> String {
    let mut out = format!(
        "camera {camera} (id {:#010x}), up {:.1} s, deadline {:.2} ms\n\
         frames: received {}  processed {}  skipped stale {}  missed (sequence gaps) {}  invalid {}  deadline misses {}  estimator failures {}\n",
        s.camera_id,
        s.uptime_ns as f64 / 1e9,
        s.deadline_ns as f64 / 1e6,
        s.frames_received,
        s.frames_processed,
        s.frames_skipped_stale,
        s.frames_missed_sequence,
        s.frames_invalid,
        s.deadline_misses,
        s.estimator_failures,
    );
    let invalid: Vec<String> = InvalidReason::ALL
        .iter()
        .filter(|r| s.invalid_by_reason[**r as usize] > 0)
        .map(|r| format!("{} {}", r.name(), s.invalid_by_reason[*r as usize]))
        .collect();
    if !invalid.is_empty() {
        out.push_str(&format!("invalid by reason: {}\n", invalid.join(", ")));
    }
    out.push_str(&format!(
        "degraded frames {}  objects shed for time {}  poses failing the depth check {}  non-finite poses {}  producer restarts {}\n",
        s.frames_degraded, s.objects_shed, s.poses_failed_verification, s.poses_non_finite, s.producer_restarts
    ));
    let names = Stage::timeline_names();
    for (title, table) in [
        ("since start".to_owned(), &s.since_start),
        (format!("last window ({:.1} s)", s.window_ns as f64 / 1e9), &s.last_window),
    ] {
        out.push_str(&format!(
            "{title} [ms]\n  {:<13} {:>8} {:>9} {:>9} {:>9} {:>9} {:>9}\n",
            "stage", "n", "p50", "p90", "p99", "p99.9", "max"
        ));
        for (i, summary) in table.iter().enumerate() {
            if summary.count > 0 {
                out.push_str(&row(names[i], summary));
                out.push('\n');
            }
        }
    }
    out
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let ipc = Ipc::new(&IpcOptions::from_env().with_node_name("fusepose-stats"))?;
    let client = StatsClient::open(&ipc, &args.name)?;
    let snapshot = client.query(Duration::from_millis(args.timeout_ms))?;
    print!("{}", render(&args.name, &snapshot));
    Ok(())
}
