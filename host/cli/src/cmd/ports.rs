//! `skinbrdf ports`.

/// Flags of `skinbrdf ports`.
#[derive(Debug, clap::Args)]
pub struct Args {}

pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`skinbrdf ports` is not built yet")
}
