//! A robot-side consumer: wait for fresh poses of camera `cam0` and pick the
//! most confident object to grasp. Run beside `fuseposed` and a camera:
//!
//! ```sh
//! cargo run -p fusepose-client --example grasp_consumer
//! ```

use std::time::Duration;

use fusepose_client::{Consumer, Ipc, IpcOptions};

fn main() -> anyhow::Result<()> {
    let ipc = Ipc::new(&IpcOptions::from_env().with_node_name("grasp_consumer"))?;
    let mut consumer = Consumer::open(&ipc, "cam0")?;
    loop {
        let Some(msg) = consumer.wait(Duration::from_secs(1))? else {
            eprintln!("no poses for 1 s: is fuseposed running?");
            continue;
        };
        if !msg.is_ok() {
            eprintln!("frame {} unusable (status {:#x})", msg.frame_sequence, msg.status);
            continue;
        }
        let best = msg.objects().iter().max_by(|a, b| a.confidence.total_cmp(&b.confidence));
        if let Some(o) = best {
            let [x, y, z] = o.translation_m;
            println!(
                "frame {}: grasp class {} at ({x:.3}, {y:.3}, {z:.3}) m, q {:?}, conf {:.2}, capture→publish {:.1} ms",
                msg.frame_sequence,
                o.class_id,
                o.quaternion,
                o.confidence,
                msg.latency_ns() as f64 / 1e6
            );
        }
    }
}
