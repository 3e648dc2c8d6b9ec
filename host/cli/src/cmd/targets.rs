//! `skinbrdf targets`.

/// Flags of `skinbrdf targets`.
#[derive(Debug, clap::Args)]
pub struct Args {}

pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`skinbrdf targets` is not built yet")
}
