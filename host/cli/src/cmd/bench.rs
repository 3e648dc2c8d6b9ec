//! `skinbrdf bench`.

/// Flags of `skinbrdf bench`.
#[derive(Debug, clap::Args)]
pub struct Args {}

pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`skinbrdf bench` is not built yet")
}
