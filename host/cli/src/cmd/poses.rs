//! `skinbrdf poses`.

/// Flags of `skinbrdf poses`.
#[derive(Debug, clap::Args)]
pub struct Args {}

pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`skinbrdf poses` is not built yet")
}
