//! A camera-side producer: how a real RGB-D camera driver feeds `fuseposed`.
//! Each frame is loaned in shared memory, filled in place (no copy through
//! the daemon), stamped with its capture time and intrinsics, and sent.
//!
//! Replace `grab_frame` with your camera SDK's call (RealSense, Azure Kinect,
//! ZED, ...). As written it sends a synthetic flat scene at 30 frames/s so it
//! runs anywhere:
//!
//! ```sh
//! cargo run --release -p fusepose-daemon -- --config config/fuseposed.toml  # terminal 1 (daemon)
//! cargo run --release -p fusepose-client --example camera_producer     # terminal 2 (this)
//! cargo run --release -p fusepose-cli -- watch                          # terminal 3 (poses)
//! ```
//!
//! Without a label plane the daemon segments frames itself with the built-in
//! segmenter embedded in the weight file (`estimator.masks = "auto"`).

use std::time::Duration;

use fusepose_client::{ColorFormat, DepthFormat, DepthMut, FrameLayout, Ipc, IpcOptions, Producer, monotonic_ns};

/// Pinhole intrinsics of the colour camera, pixels (depth registered to colour).
struct Intrinsics {
    fx: f64,
    fy: f64,
    cx: f64,
    cy: f64,
}

/// Stand-in for the camera SDK: fills RGB8 and depth in millimetres for frame `n`
/// and returns its capture time on `CLOCK_MONOTONIC` (ns). Real drivers convert
/// the device timestamp to this clock once (offset measured at start-up).
fn grab_frame(n: u64, rgb: &mut [u8], depth_mm: &mut [u16], width: usize) -> u64 {
    for (i, px) in rgb.chunks_exact_mut(3).enumerate() {
        let (u, v) = (i % width, i / width);
        px.copy_from_slice(&[(u / 3) as u8, (v / 2) as u8, (n % 256) as u8]);
    }
    depth_mm.fill(800); // a wall 0.8 m away
    monotonic_ns()
}

fn main() -> anyhow::Result<()> {
    let layout = FrameLayout {
        width: 640,
        height: 480,
        color_format: ColorFormat::Rgb8,
        depth_format: DepthFormat::U16,
        depth_scale: 0.001, // one depth unit = 1 mm
        labels: None,       // let the daemon segment
    };
    let k = Intrinsics { fx: 615.0, fy: 615.0, cx: 319.5, cy: 239.5 };
    let ipc = Ipc::new(&IpcOptions::from_env().with_node_name("camera_producer"))?;
    let mut producer = Producer::create(&ipc, "cam0", layout)?;
    let period = Duration::from_secs_f64(1.0 / 30.0);
    for n in 0.. {
        let mut frame = producer.loan()?;
        let planes = frame.planes_mut();
        let DepthMut::U16(depth) = planes.depth else { unreachable!("the layout asks for u16 depth") };
        let captured = grab_frame(n, planes.color, depth, layout.width as usize);
        frame.set_capture_time_ns(captured).set_intrinsics(k.fx, k.fy, k.cx, k.cy);
        let sequence = frame.send()?;
        if sequence % 30 == 0 {
            println!("sent frame {sequence}");
        }
        std::thread::sleep(period);
    }
    Ok(())
}
