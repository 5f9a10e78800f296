//! Test consumer: prints one `pose …` line per pose message (see
//! `fusepose_tests::PoseLine`) until it has run for DURATION_MS.
//!
//! Usage: fp-test-consumer CAMERA DURATION_MS. CAMERA `@cell` consumes the
//! cell poses instead (one `cell …` line per message, `fusepose_tests::CellLine`).

use std::io::Write;
use std::time::{Duration, Instant};

use fusepose_client::{Consumer, Ipc, IpcOptions};
use fusepose_tests::PoseLine;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    anyhow::ensure!(args.len() == 2, "usage: fp-test-consumer CAMERA DURATION_MS");
    let duration = Duration::from_millis(args[1].parse()?);
    let ipc = Ipc::new(&IpcOptions::from_env().with_node_name("fp-test-consumer"))?;
    let end = Instant::now() + duration;
    let mut stdout = std::io::stdout();
    if args[0] == "@cell" {
        let mut cell = fusepose_client::CellConsumer::open(&ipc)?;
        println!("ready");
        let mut batch = Vec::new();
        while Instant::now() < end {
            std::thread::sleep(Duration::from_millis(20));
            batch.clear();
            cell.drain(&mut batch)?;
            for msg in &batch {
                writeln!(stdout, "{}", fusepose_tests::CellLine::format(msg))?;
            }
            stdout.flush()?;
        }
        println!("done");
        return Ok(());
    }
    let mut consumer = Consumer::open(&ipc, &args[0])?;
    println!("ready");
    let mut batch = Vec::new();
    while Instant::now() < end {
        // Every message (not only the newest), so the test sees each published pose.
        if !consumer.wait_ready(Duration::from_millis(50))? {
            continue;
        }
        batch.clear();
        consumer.drain(&mut batch)?;
        for msg in &batch {
            writeln!(stdout, "{}", PoseLine::format(msg))?;
        }
        stdout.flush()?;
    }
    println!("done");
    Ok(())
}
