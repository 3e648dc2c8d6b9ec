//! `skinbrdf synth`.

/// Flags of `skinbrdf synth`.
#[derive(Debug, clap::Args)]
pub struct Args {}

pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`skinbrdf synth` is not built yet")
}
