//! `fusepose-bench`: benchmark subcommands (estimator; transport and e2e
//! are added by their owners as further [`Command`] variants).

use clap::{Parser, Subcommand};
use fusepose_bench::alloc_count::CountingAlloc;
use fusepose_bench::estimator::{self, EstimatorArgs};

#[global_allocator]
static ALLOC: CountingAlloc = CountingAlloc;

#[derive(Parser)]
#[command(name = "fusepose-bench", about = "fusepose benchmarks: measured numbers, no pass/fail")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Per-stage estimator latency (sampling, network, refiner, ICP) vs objects per frame.
    Estimator(EstimatorArgs),
}

fn main() -> anyhow::Result<()> {
    match Cli::parse().command {
        Command::Estimator(args) => {
            let report = estimator::run(&args)?;
            let text = estimator::table::render(&report);
            print!("{text}");
            std::fs::write(args.out.join("estimator.txt"), &text)?;
        }
    }
    Ok(())
}
