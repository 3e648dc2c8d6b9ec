//! `skinbrdf fit`.

/// Flags of `skinbrdf fit`.
#[derive(Debug, clap::Args)]
pub struct Args {}

pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`skinbrdf fit` is not built yet")
}
