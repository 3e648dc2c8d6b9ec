//! `skinbrdf compare`.

/// Flags of `skinbrdf compare`.
#[derive(Debug, clap::Args)]
pub struct Args {}

pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`skinbrdf compare` is not built yet")
}
