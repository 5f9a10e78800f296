//! The receiver processes of `fusepose-bench transport` (hidden subcommand
//! `transport-receiver`): stamp each frame when it is readable, write the
//! latencies (ns, one per line) to a file, print `result <CPU % of a core>`.

use std::io::{Read, Write};
use std::os::unix::net::UnixStream;
use std::time::{Duration, Instant};

use fusepose_client::{
    ArrivalPredictor, CameraServices, Ipc, IpcOptions, WaitStrategy, decode_frame, monotonic_ns, wait_for_samples,
};

/// Process CPU time (user + system), ms.
fn process_cpu_ms() -> f64 {
    // SAFETY: getrusage fills the zeroed struct we pass.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: valid pointer to a rusage struct.
    unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut usage) };
    let ms = |t: libc::timeval| t.tv_sec as f64 * 1e3 + t.tv_usec as f64 / 1e3;
    ms(usage.ru_utime) + ms(usage.ru_stime)
}

fn strategy(tag: &str) -> anyhow::Result<WaitStrategy> {
    super::IOX_MODES
        .iter()
        .find(|(t, _, _)| *t == tag)
        .map(|m| m.2)
        .ok_or_else(|| anyhow::anyhow!("unknown receive strategy {tag:?}"))
}

/// Entry point of the hidden subcommand; `args` follow `transport-receiver`.
pub fn main(args: &[String]) -> anyhow::Result<()> {
    anyhow::ensure!(args.len() == 5, "usage: transport-receiver iox|uds STRATEGY|SOCKET FRAMES WARMUP FILE");
    if let Ok(cpu) = std::env::var(super::PIN_ENV) {
        let cpu: usize = cpu.parse()?;
        fusepose_estimator::cpu_pin::pin_current_thread(cpu)
            .map_err(|e| anyhow::anyhow!("pinning the receiver to CPU {cpu}: {e}"))?;
    }
    let frames: u64 = args[2].parse()?;
    let warmup: u64 = args[3].parse()?;
    let mut latencies = Vec::with_capacity(frames as usize);
    let (cpu0, wall0) = (process_cpu_ms(), Instant::now());
    let mut checksum = 0u64;
    let mut polling = String::new();
    match args[0].as_str() {
        "iox" => {
            let strategy = strategy(&args[1])?;
            let ipc = Ipc::new(&IpcOptions::from_env())?;
            let services = CameraServices::open(&ipc, "bench")?;
            let subscriber = services.frame_subscriber()?;
            let listener = services.frame_listener()?;
            println!("ready");
            std::io::stdout().flush()?;
            let mut predictor = ArrivalPredictor::default();
            let mut last_sequence = 0;
            // Frames overwritten while this process was descheduled never arrive:
            // stop at the last sequence or after 2 s without frames.
            while last_sequence + 1 < frames {
                let ready = wait_for_samples(
                    &listener,
                    || subscriber.has_samples(),
                    &mut predictor,
                    strategy,
                    Duration::from_secs(2),
                )
                .map_err(|(op, e)| anyhow::anyhow!("{op}: {e}"))?;
                if !ready {
                    break;
                }
                while let Some(sample) = subscriber.receive().map_err(|e| anyhow::anyhow!("{e:?}"))? {
                    let planes = decode_frame(sample.user_header(), sample.payload(), None)?;
                    // Touch the frame so it is really readable here.
                    checksum = checksum.wrapping_add(planes.color[planes.color.len() / 2] as u64);
                    let now = monotonic_ns();
                    if planes.header.sequence >= warmup {
                        latencies.push(now.saturating_sub(planes.header.capture_time_ns));
                    }
                    last_sequence = planes.header.sequence;
                }
            }
            let (arrivals, polled) = predictor.hits();
            polling = format!(
                " polled_percent {:.2} jitter_us {:.1} wake_delay_us {:.1}",
                100.0 * polled as f64 / arrivals.max(1) as f64,
                predictor.jitter_ns() as f64 / 1e3,
                predictor.wake_delay_ns() as f64 / 1e3
            );
        }
        "uds" => {
            let mut stream = UnixStream::connect(&args[1])?;
            println!("ready");
            std::io::stdout().flush()?;
            let frame_len = fusepose_client::FrameLayout::vga_rgbd().payload_len();
            let mut buf = vec![0u8; 8 + frame_len];
            for i in 0..frames {
                stream.read_exact(&mut buf)?;
                let now = monotonic_ns();
                let sent = u64::from_le_bytes(buf[..8].try_into().expect("8 bytes"));
                checksum = checksum.wrapping_add(buf[8 + frame_len / 2] as u64);
                if i >= warmup {
                    latencies.push(now.saturating_sub(sent));
                }
            }
        }
        other => anyhow::bail!("unknown transport {other:?}"),
    }
    let cpu_percent = (process_cpu_ms() - cpu0) / (wall0.elapsed().as_secs_f64() * 1e3) * 100.0;
    let text: String = latencies.iter().map(|v| format!("{v}\n")).collect();
    std::fs::write(&args[4], text)?;
    println!("result {cpu_percent:.2} checksum {checksum}{polling}");
    Ok(())
}
