//! `skinbrdf capture`.

/// Flags of `skinbrdf capture`.
#[derive(Debug, clap::Args)]
pub struct Args {}

pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`skinbrdf capture` is not built yet")
}
