//! `fusepose demo` (stub: to be written).

#[derive(clap::Args)]
pub struct Args {}

pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("fusepose demo is not built yet")
}
