//! `skinbrdf sim`.

/// Flags of `skinbrdf sim`.
#[derive(Debug, clap::Args)]
pub struct Args {}

pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`skinbrdf sim` is not built yet")
}
