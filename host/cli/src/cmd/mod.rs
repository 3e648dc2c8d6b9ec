//! One module per subcommand; each owns its flags and validates them into library configs.

pub mod bench;
pub mod capture;
pub mod compare;
pub mod demo;
pub mod derender;
pub mod fit;
pub mod ports;
pub mod poses;
pub mod process;
pub mod render;
pub mod sim;
pub mod synth;
pub mod targets;

/// Parses an image size `WxH` (e.g. `1524x1012`).
pub(crate) fn parse_size(s: &str) -> anyhow::Result<(u32, u32)> {
    use anyhow::Context;
    let (w, h) = s
        .split_once(['x', 'X'])
        .with_context(|| format!("`{s}`: expected WxH, e.g. 1524x1012"))?;
    let w: u32 = w
        .trim()
        .parse()
        .with_context(|| format!("`{s}`: bad width"))?;
    let h: u32 = h
        .trim()
        .parse()
        .with_context(|| format!("`{s}`: bad height"))?;
    if w == 0 || h == 0 {
        anyhow::bail!("`{s}`: width and height must be positive");
    }
    Ok((w, h))
}
