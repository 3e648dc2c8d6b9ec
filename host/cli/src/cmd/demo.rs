//! `skinbrdf demo`.

/// Flags of `skinbrdf demo`.
#[derive(Debug, clap::Args)]
pub struct Args {}

pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`skinbrdf demo` is not built yet")
}
