//! One module per subcommand; each owns its flags and validates them into library configs.

pub mod bench;
pub mod capture;
pub mod compare;
pub mod demo;
pub mod derender;
pub mod fit;
pub mod ingest;
pub mod internal_decode;
pub mod ports;
pub mod poses;
pub mod process;
pub mod render;
pub mod sim;
pub mod survey;
pub mod synth;
pub mod targets;

/// Prints `value` as pretty JSON on stdout (the commands' `--json`), through the checked writer
/// ([`skinbrdf_core::json`]): a NaN or infinity is an error naming its field, never a `null`.
/// How camera raw images load (`--raw-mode`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum RawModeArg {
    /// One pixel per photosite, each its own channel and ray (full resolution).
    #[default]
    Photosite,
    /// 2x2 superpixels (half resolution, faster).
    Superpixel,
}

impl From<RawModeArg> for skinbrdf_session::RawMode {
    fn from(a: RawModeArg) -> Self {
        match a {
            RawModeArg::Photosite => Self::Photosite,
            RawModeArg::Superpixel => Self::Superpixel,
        }
    }
}

/// `--bvh-quality`: the mesh crate's build presets, by their names.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum BvhQuality {
    /// No reinsertion, one triangle per leaf.
    Fastest,
    /// Very fast build.
    #[value(name = "very_fast", alias = "very-fast")]
    VeryFast,
    /// Quick build, slower traversal.
    Fast,
    /// About Embree's build time with faster traversal.
    Medium,
    /// Spatial pre-splits and more reinsertion.
    High,
    /// Full reinsertion.
    #[value(name = "very_high", alias = "very-high")]
    VeryHigh,
}

impl From<BvhQuality> for skinbrdf_mesh::BuildQuality {
    fn from(q: BvhQuality) -> Self {
        match q {
            BvhQuality::Fastest => Self::Fastest,
            BvhQuality::VeryFast => Self::VeryFast,
            BvhQuality::Fast => Self::Fast,
            BvhQuality::Medium => Self::Medium,
            BvhQuality::High => Self::High,
            BvhQuality::VeryHigh => Self::VeryHigh,
        }
    }
}

pub(crate) fn print_json<T: serde::Serialize + ?Sized>(value: &T) -> anyhow::Result<()> {
    let text = skinbrdf_core::json::to_string_pretty(std::path::Path::new("stdout"), value)?;
    println!("{text}");
    Ok(())
}

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

/// One spinner per running stage on stderr (drawn only on a terminal), with its elapsed time;
/// lines printed through [`StageProgress::println`] appear above it.
#[derive(Debug, Default)]
pub(crate) struct StageProgress {
    bar: Option<indicatif::ProgressBar>,
}

impl StageProgress {
    /// Starts a spinner for `what` (ending the previous one).
    pub(crate) fn start(&mut self, what: &str) {
        self.finish();
        let bar = indicatif::ProgressBar::new_spinner();
        bar.set_style(
            indicatif::ProgressStyle::with_template("{spinner} {msg} [{elapsed_precise}]")
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_spinner()),
        );
        bar.set_message(what.to_string());
        bar.enable_steady_tick(std::time::Duration::from_millis(120));
        self.bar = Some(bar);
    }

    /// Ends the current spinner.
    pub(crate) fn finish(&mut self) {
        if let Some(bar) = self.bar.take() {
            bar.finish_and_clear();
        }
    }

    /// Prints a line to stderr above the spinner.
    pub(crate) fn println(&self, line: &str) {
        match &self.bar {
            Some(bar) => bar.suspend(|| eprintln!("{line}")),
            None => eprintln!("{line}"),
        }
    }
}
