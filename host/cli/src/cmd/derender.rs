//! `skinbrdf derender`.

/// Flags of `skinbrdf derender`.
#[derive(Debug, clap::Args)]
pub struct Args {}

pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`skinbrdf derender` is not built yet")
}
