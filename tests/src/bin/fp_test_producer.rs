//! Test camera: publishes synthetic 640x480 RGB-D frames; prints `sent <seq>`
//! per frame and `malformed <seq>` per deliberately broken frame.
//!
//! Usage: fp-test-producer CAMERA FRAMES(0 = forever) FPS START_SEQ [MALFORMED_SEQ ...]
//! iceoryx2 namespace from FUSEPOSE_IOX2_ROOT / FUSEPOSE_IOX2_PREFIX.

use std::io::Write;
use std::time::{Duration, Instant};

use fusepose_client::{DepthMut, FrameLayout, Ipc, IpcOptions, PlaneRef, Producer};

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    anyhow::ensure!(args.len() >= 4, "usage: fp-test-producer CAMERA FRAMES FPS START_SEQ [MALFORMED_SEQ ...]");
    let camera = &args[0];
    let frames: u64 = args[1].parse()?;
    let fps: f64 = args[2].parse()?;
    let start: u64 = args[3].parse()?;
    let malformed: Vec<u64> = args[4..].iter().map(|s| s.parse()).collect::<Result<_, _>>()?;

    let ipc = Ipc::new(&IpcOptions::from_env().with_node_name("fp-test-producer"))?;
    let mut producer = Producer::create(&ipc, camera, FrameLayout::vga_rgbd())?;
    producer.set_next_sequence(start);
    println!("ready");
    let period = Duration::from_secs_f64(1.0 / fps);
    let t0 = Instant::now();
    let mut stdout = std::io::stdout();
    let mut n = 0u64;
    while frames == 0 || n < frames {
        let sequence = start + n;
        if malformed.contains(&sequence) {
            // A depth plane pointing past the end of the payload.
            let layout = *producer.layout();
            let mut header = layout.header(producer.camera_id());
            header.sequence = sequence;
            header.capture_time_ns = fusepose_client::monotonic_ns();
            (header.fx, header.fy, header.cx, header.cy) = (525.0, 525.0, 319.5, 239.5);
            header.depth = PlaneRef { offset: layout.payload_len() as u32 - 100, len: header.depth.len };
            let payload = vec![0u8; layout.payload_len()];
            producer.send_raw(header, &payload)?;
            producer.set_next_sequence(sequence + 1);
            writeln!(stdout, "malformed {sequence}")?;
            // Give the daemon time to take it before the next frame supersedes it.
            std::thread::sleep(Duration::from_millis(150));
        } else {
            let mut frame = producer.loan()?;
            frame.set_intrinsics(525.0, 525.0, 319.5, 239.5);
            let planes = frame.planes_mut();
            planes.color.fill((sequence % 251) as u8);
            if let DepthMut::U16(depth) = planes.depth {
                depth.fill(800);
            }
            let sent = frame.send()?;
            writeln!(stdout, "sent {sent}")?;
        }
        stdout.flush()?;
        n += 1;
        let next = t0 + period.mul_f64(n as f64);
        if let Some(wait) = next.checked_duration_since(Instant::now()) {
            std::thread::sleep(wait);
        }
    }
    println!("done");
    // Linger so the last frame is not torn down before the daemon took it.
    std::thread::sleep(Duration::from_millis(300));
    Ok(())
}
