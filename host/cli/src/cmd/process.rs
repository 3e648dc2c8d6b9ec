//! `skinbrdf process`.

/// Flags of `skinbrdf process`.
#[derive(Debug, clap::Args)]
pub struct Args {}

pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`skinbrdf process` is not built yet")
}
