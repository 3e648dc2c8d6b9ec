//! Which camera file is which exposure: camera files matched to the controller's record by time.
//!
//! The controller records, for every exposure, the host time of the camera's X-sync edge
//! (`host_time_us`, Unix microseconds through the controller's clock model). Each camera file
//! carries the camera's own clock reading (EXIF `DateTimeOriginal`, with `SubSecTimeOriginal`
//! and `OffsetTimeOriginal` where the body writes them). The two clocks differ by an unknown
//! offset (the camera is set by hand, often to local time without a zone) and drift slightly;
//! this module estimates both and pairs files with exposures, or refuses.
//!
//! # Model
//!
//! For a file taken at host time `h` (seconds), the camera's clock reads
//!
//! ```text
//! c = h + offset + drift * (h - h_ref) + jitter,        |jitter| <= jitter_tolerance_s
//! ```
//!
//! where `offset` also absorbs the camera's shutter lag between X-sync and the EXIF time stamp
//! (tens of milliseconds, constant for a body and mode) and `h_ref` is the middle of the
//! session's fired exposures. The EXIF time is truncated to its resolution `q` (1 s without a
//! sub-second field, [`MatchOptions::subsec_resolution_s`] with one), so the true reading lies
//! in `[t, t + q)` and the module works with the midpoint `c = t + q/2`. A pair (exposure `i`,
//! file `j`) is *consistent* with a clock `(offset, drift)` when
//!
//! ```text
//! |c_j - h_i - offset - drift * (h_i - h_ref)| <= tol_j = q_j / 2 + jitter_tolerance_s (+ slack)
//! ```
//!
//! With `OffsetTimeOriginal` on every file the camera times are converted to UTC first;
//! otherwise the camera's local time is used as is and the time zone is part of `offset`, so
//! any offset works (time zones up to ±14 h, clocks off by hours or days). The drift is fitted
//! (bounded by [`MatchOptions::max_drift_ppm`]) when at least
//! [`MatchOptions::min_pairs_for_drift`] pairs are matched; with fewer, it is fixed at 0 and
//! the tolerance gains the slack `max_drift * span / 2` that an unmodelled drift over the
//! session's span can cause.
//!
//! # Conventions
//!
//! * Only exposures that fired the camera ([`ShotOutcome::Ok`], [`ShotOutcome::MissingFlash`])
//!   take part; the others ([`ShotOutcome::MissingXsync`], [`ShotOutcome::FlashNotReady`],
//!   [`ShotOutcome::Aborted`]) are listed in [`Matching::no_file_expected`]. A file taken at such
//!   an exposure (a hot shoe that failed to report X-sync) is reported as an extra file
//!   ([`ExtraReason::NearUnfiredExposure`]), never matched.
//! * Files from another body (serial differs from the expected one, given or the majority) and
//!   duplicates (the same path twice, the same name at the same time, or the same time and
//!   shutter count) are set aside first and reported by name.
//! * Both sequences are monotone: the `k`-th file in camera-time order can only belong to an
//!   exposure later than the one of any earlier file. A matching is therefore a *chain*: pairs
//!   strictly increasing in exposure time and in camera time, with gaps (missing files, extra
//!   files).
//!
//! # Score
//!
//! A chain scores one per pair, minus the costs below; every cost is in pairs.
//!
//! * **Counters.** Shutter counts (when every file has one and they increase with camera time)
//!   and file numbers (when every file has one; DCF numbers roll over from 9999 to 0001) count
//!   actuations. Between two consecutive pairs `(i, j)` and `(i', j')` of a chain the camera
//!   actuated at least `need = (i' - i) + (j' - j - 1)` times: the fired exposures after `i` up
//!   to `i'` (including those whose file is missing) plus the unmatched files in between. A
//!   shutter-count step below `need` is impossible and forbids the transition; a step above it
//!   (an actuation the chain cannot explain) costs [`MatchOptions::counter_penalty_pairs`]; a
//!   file-number step other than `need` costs the same (numbers can reset, so they never
//!   forbid).
//! * **Coincidences.** An unmatched file that is consistent with an unmatched fired exposure
//!   between the same two neighbours of the chain (or before its first or after its last pair)
//!   costs [`MatchOptions::coincidence_penalty_pairs`] once per gap: such a chain claims that
//!   a test shot was taken at the very time of an exposure whose own file is missing. This
//!   cost is one pair below the counter cost, so "this file is that exposure's, plus an
//!   unexplained actuation" ties with "a test shot coinciding with a deleted file" (a refusal),
//!   and it makes every chain that merely drops a consistent pair of the answer score at least
//!   `1 + coincidence cost` below it.
//!
//! # Algorithm
//!
//! 1. **Candidate offsets.** For every pair `(i, j)` the offset difference `d_ij = c_j - h_i`.
//!    Under the offset-only model with the tolerance widened by the drift slack
//!    `max_drift * span / 2`, the set of pairs consistent with offset `o` changes only at the
//!    ends of the windows `d_ij ± tol_j`, and every such set is contained in the set at some left
//!    end `o = d_ij - tol_j`. Sweeping those `n·m` candidates therefore visits every maximal set
//!    of pairs that a clock within the drift bound can make consistent; identical sets are
//!    visited once. A known offset ([`MatchOptions::known_offset_s`]) removes the pairs outside
//!    its window first.
//! 2. **Monotone assignment.** For each set, a dynamic programme over its pairs (sorted by
//!    exposure, then file) gives the best chain ending at every pair (`F`) and starting at every
//!    pair (`B`), with the score above (coincidences counted by prefix sums over the
//!    exposure x file grid, `O(1)` per transition).
//! 3. **Refit.** The best chain over all candidates is refitted by a Chebyshev (minimax) fit of
//!    `offset` and `drift` (weighted by `tol_j`): the errors are bounded (truncation and bounded
//!    jitter), not Gaussian, so the minimax fit is the natural estimator and its value decides
//!    consistency exactly. The drift is found by a golden-section search on `[-max, max]` (the
//!    minimax error is convex in the drift), the offset in closed form. The pairs consistent
//!    with the refitted clock are re-assigned by the same programme until the chain is stable;
//!    if the refitted chain is not consistent or scores lower, the offset-only fit of the
//!    swept chain (drift fixed at 0 within its slack) is kept.
//! 4. **Ambiguity.** Every chain other than the answer is an *alternative*. Those that contain
//!    a pair the answer does not (a different file for an exposure, a different exposure for a
//!    file, an additional pair) are found by running step 1 again: the best one through pair `p`
//!    scores `F[p] + B[p] - 1`. Those that only drop pairs are consistent with the answer's own
//!    clock: the best one is found under it, one dropped pair at a time. If the best
//!    alternative scores at least `best - ambiguity_margin_pairs`, the match is refused with
//!    [`MatchError::Ambiguous`], naming every file whose exposure differs and what would tell
//!    the two apart. The default margin of one pair means that an explanation needing one more
//!    missing file and one more extra file counts as about as good.
//!
//! # Cost
//!
//! With `n` fired exposures, `m` files and `P` pairs per candidate set (about `n` when the
//! shot interval exceeds the tolerance): sorting the `n·m` differences is
//! `O(n·m·log(n·m))`; each distinct candidate set costs `O(n·m)` for its grid and `O(P²)` for
//! the two programmes, so the sweeps are `O(n·m·(n·m + P²))` in the worst case. In practice
//! most candidates give the same set, and the sets are visited largest first and the sweep
//! stops at the first set smaller than the score still sought (no chain scores more than its
//! set's size). The drop-one check is `O(k·P²)` for an answer of `k` pairs; the minimax fit
//! `O(k)` per drift value. Measured times: `docs/benchmarks-matching.md`.
//!
//! # Guarantees
//!
//! * No file appears in two pairs, no exposure in two pairs, and every pair's residual is within
//!   its tolerance.
//! * If the true assignment satisfies the model (jitter within its tolerance, drift within its
//!   bound), it is a chain of some visited candidate set. The answer is then either the truth,
//!   or refused, or a chain scoring more than the truth by more than the margin. The last
//!   happens when a file taken within one time step of a fired exposure whose own file is
//!   missing is taken for that file while neither shutter counts nor file numbers show the
//!   additional actuation (with either, the two explanations tie and the call refuses).
//! * Candidate windows are widened by the drift slack, never narrowed, so rounding and drift can
//!   only add alternatives (more refusals), not hide them; the coincidence cost of an
//!   alternative is counted among its candidate set's pairs, whose windows are at most the
//!   drift slack (a few milliseconds over a session) wider than its own clock's.
//! * Refusal rates against a simulated studio are in `docs/ingest.md`.

use std::collections::{BTreeMap, HashMap, HashSet};
use std::fmt;

use serde::{Deserialize, Serialize};
use skinbrdf_session::capture::{Exposure, ImageRole, ShotOutcome};

/// DCF file numbers run 0001..=9999 and then start again at 0001.
const FILE_NUMBER_MODULUS: i64 = 9999;
/// Scores are sums of small integers and fixed weights: anything closer than this is equal.
const SCORE_EPS: f64 = 1e-9;
/// A chain is consistent when its minimax error is at most its tolerance; this allows the
/// rounding of the fit's arithmetic (about 1e-7 s relative to tolerances of milliseconds).
const CONSISTENCY_EPS: f64 = 1e-6;
/// A candidate offset sits exactly on the edge of its own pair's window; this keeps the pair
/// inside despite rounding (it only widens the relaxed windows, which is the safe side).
const WINDOW_EPS_S: f64 = 1e-9;
/// Golden-section iterations of the drift search: the bracket shrinks by 0.618 each time, so
/// 100 iterations take a ±1e-3 bracket below 1e-23, far below any measurable drift.
const DRIFT_SEARCH_ITERATIONS: usize = 100;
/// Upper bound on assign-refit rounds; the chain normally settles in two.
const MAX_REFINE_ROUNDS: usize = 8;
/// For an exposure without X-sync the host time is the shutter command, which precedes the
/// camera's time stamp by the shutter lag (well under half a second on any body); a leftover
/// file this close to such an exposure is labelled as taken by it.
const UNFIRED_LAG_WINDOW_S: f64 = 0.5;

/// The camera's time stamp of one file, as read from its EXIF.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CameraTime {
    /// `DateTimeOriginal` read as if it were UTC: seconds since 1970-01-01 of the camera's
    /// local date and time.
    pub naive_local_s: i64,
    /// `SubSecTimeOriginal` as a fraction of a second in `[0, 1)`, when present.
    pub subsec_s: Option<f64>,
    /// `OffsetTimeOriginal` in seconds east of UTC, when present.
    pub utc_offset_s: Option<i32>,
}

/// One camera file: its name and what its metadata says about when and by whom it was taken.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CameraShot {
    /// The file, as it will be named in reports (a path relative to the card, say).
    pub file: String,
    /// The camera's time stamp.
    pub time: CameraTime,
    /// The body's shutter actuation count, where the format carries it.
    pub shutter_count: Option<u32>,
    /// The number in the file name (`SKB_0412.DNG` is 412; see [`file_number_from_name`]).
    pub file_number: Option<u32>,
    /// The body serial number.
    pub body_serial: Option<String>,
}

/// The part of an [`Exposure`] the matching needs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ExposureInput {
    /// Index of the exposure in the capture record.
    pub index: u32,
    /// What the image is for.
    pub role: ImageRole,
    /// How the shot ended.
    pub outcome: ShotOutcome,
    /// X-sync (or shutter command) time, Unix microseconds.
    pub host_time_us: f64,
}

impl From<&Exposure> for ExposureInput {
    fn from(exposure: &Exposure) -> Self {
        Self {
            index: exposure.index,
            role: exposure.role,
            outcome: exposure.outcome,
            host_time_us: exposure.host_time_us,
        }
    }
}

impl ExposureInput {
    /// The slim inputs of a capture record's exposures, in record order.
    pub fn from_exposures(exposures: &[Exposure]) -> Vec<Self> {
        exposures.iter().map(Self::from).collect()
    }

    /// True when the camera fired (X-sync seen): the exposure should have a file.
    pub fn camera_fired(&self) -> bool {
        matches!(self.outcome, ShotOutcome::Ok | ShotOutcome::MissingFlash)
    }
}

/// Tolerances and bounds of the matching.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MatchOptions {
    /// The body whose files belong to the session; `None`: the serial most files carry.
    pub expected_body_serial: Option<String>,
    /// Largest variation of the camera's latency between X-sync and its time stamp that a pair
    /// may show: shutter-lag jitter is 1-5 ms, doubled for margin.
    pub jitter_tolerance_s: f64,
    /// Resolution of `SubSecTimeOriginal` (two digits on most bodies).
    pub subsec_resolution_s: f64,
    /// Largest camera clock drift relative to the host: quartz clocks are specified to
    /// ±20-50 ppm, this allows twice the worst seen.
    pub max_drift_ppm: f64,
    /// The drift is fitted with at least this many matched pairs, else fixed at 0.
    pub min_pairs_for_drift: usize,
    /// A different chain scoring within this many pairs of the best makes the match ambiguous:
    /// one more missing file plus one more extra file is a plausible explanation.
    pub ambiguity_margin_pairs: f64,
    /// The best chain must match at least this fraction of `min(fired exposures, files)`.
    pub min_matched_fraction: f64,
    /// Cost, in pairs, of a counter step a chain cannot explain (see the module docs).
    pub counter_penalty_pairs: f64,
    /// Cost, in pairs, of leaving an unmatched file that fits an unmatched fired exposure
    /// between two pairs of a chain (a test shot at the very time of a deleted file). One pair
    /// less than the counter penalty, so that "this file is that exposure's, plus an
    /// unexplained actuation" ties with "a test shot coinciding with a deleted file".
    pub coincidence_penalty_pairs: f64,
    /// The camera clock's offset (camera minus host, seconds, as [`CameraClockFit::offset_s`])
    /// and how far it may be off, when known in advance (say from a photograph of the host's
    /// clock); `None`: any offset.
    pub known_offset_s: Option<(f64, f64)>,
}

impl Default for MatchOptions {
    fn default() -> Self {
        Self {
            expected_body_serial: None,
            jitter_tolerance_s: 0.010,
            subsec_resolution_s: 0.01,
            max_drift_ppm: 200.0,
            min_pairs_for_drift: 10,
            ambiguity_margin_pairs: 1.0,
            min_matched_fraction: 0.5,
            counter_penalty_pairs: 3.0,
            coincidence_penalty_pairs: 2.0,
            known_offset_s: None,
        }
    }
}

/// One file matched to one exposure.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MatchedPair {
    /// The exposure's index in the capture record.
    pub exposure_index: u32,
    /// The exposure's role.
    pub role: ImageRole,
    /// The file.
    pub file: String,
    /// Camera time (mid-resolution) minus the fitted clock's prediction, seconds.
    pub residual_s: f64,
}

/// The fitted camera clock: `camera = host + offset_s + drift_ppm·1e-6·(host - host_ref)`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CameraClockFit {
    /// The host time the offset refers to (the middle of the fired exposures), Unix µs.
    pub host_ref_us: f64,
    /// Camera clock minus host clock at `host_ref_us`, seconds (includes the time zone when
    /// the files carry no UTC offset, and the camera's shutter lag).
    pub offset_s: f64,
    /// Camera clock rate error relative to the host, parts per million.
    pub drift_ppm: f64,
    /// False when too few pairs were matched and the drift was fixed at 0.
    pub drift_fitted: bool,
    /// RMS of the pairs' residuals, seconds.
    pub residual_rms_s: f64,
    /// Largest absolute residual, seconds.
    pub residual_max_s: f64,
    /// Coarsest time-stamp resolution among the matched files, seconds.
    pub time_resolution_s: f64,
    /// Largest tolerance a residual was held to, seconds.
    pub tolerance_s: f64,
    /// Number of pairs in the fit.
    pub pairs_used: usize,
}

/// Why a file was left out of the matching.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", tag = "reason")]
pub enum ExtraReason {
    /// Taken before the session's first fired exposure (a test shot).
    BeforeSession,
    /// Taken after the session's last fired exposure.
    AfterSession,
    /// Taken during the session at a time with no exposure.
    BetweenShots,
    /// Taken at an exposure the controller saw no X-sync for (treated as not fired).
    NearUnfiredExposure {
        /// The exposure's index.
        exposure_index: u32,
    },
    /// Taken by another body.
    AnotherBody {
        /// This file's body serial.
        serial: String,
        /// The session's body serial.
        expected: String,
    },
    /// A copy of another file.
    Duplicate {
        /// The file kept.
        of: String,
    },
}

impl fmt::Display for ExtraReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::BeforeSession => write!(f, "taken before the session"),
            Self::AfterSession => write!(f, "taken after the session"),
            Self::BetweenShots => write!(f, "taken between exposures"),
            Self::NearUnfiredExposure { exposure_index } => write!(
                f,
                "taken at exposure {exposure_index}, which the controller recorded as not fired"
            ),
            Self::AnotherBody { serial, expected } => {
                write!(f, "from body {serial}, not the session's body {expected}")
            }
            Self::Duplicate { of } => write!(f, "a duplicate of {of}"),
        }
    }
}

/// Whether camera times were converted to UTC.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum TimeBasis {
    /// Every file had `OffsetTimeOriginal`: times are UTC.
    Utc,
    /// Some file had none: the camera's local time, the zone part of the offset.
    CameraLocal,
}

/// The result of [`match_shots`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Matching {
    /// Matched pairs, in exposure order.
    pub pairs: Vec<MatchedPair>,
    /// The camera clock.
    pub clock: CameraClockFit,
    /// Files not matched, with the reason, in camera-time order (set-aside files last).
    pub extra_files: Vec<(String, ExtraReason)>,
    /// Exposures that fired the camera but have no file.
    pub missing: Vec<u32>,
    /// Exposures that did not fire the camera.
    pub no_file_expected: Vec<u32>,
    /// How camera times were read.
    pub time_basis: TimeBasis,
    /// Shutter counts took part (every file had one, increasing with time).
    pub shutter_counts_used: bool,
    /// File numbers took part (every file had one).
    pub file_numbers_used: bool,
}

/// A file assigned differently by the answer and by an equally good alternative.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Conflict {
    /// The file.
    pub file: String,
    /// Its exposure in the best chain (`None`: extra).
    pub exposure_best: Option<u32>,
    /// Its exposure in the alternative (`None`: extra).
    pub exposure_alternative: Option<u32>,
}

impl fmt::Display for Conflict {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let show = |e: Option<u32>| match e {
            Some(i) => format!("exposure {i}"),
            None => "no exposure".to_owned(),
        };
        write!(
            f,
            "{}: {} or {}",
            self.file,
            show(self.exposure_best),
            show(self.exposure_alternative)
        )
    }
}

/// What would tell two explanations apart.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Remedy {
    /// Sub-second time stamps (`SubSecTimeOriginal`): some files have 1 s resolution.
    SubSecondTimes,
    /// Shutter counts on every file.
    ShutterCounts,
    /// Fewer missing files: the explanations differ in which exposures lack a file.
    FewerMissingFiles,
    /// Test shots and other files that are not the session's moved off the card.
    RemoveExtraFiles,
    /// The camera clock's offset known in advance ([`MatchOptions::known_offset_s`]).
    KnownClockOffset,
}

impl fmt::Display for Remedy {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::SubSecondTimes => "sub-second time stamps (SubSecTimeOriginal)",
            Self::ShutterCounts => "shutter counts in every file",
            Self::FewerMissingFiles => "the missing files",
            Self::RemoveExtraFiles => "moving test shots and foreign files off the card",
            Self::KnownClockOffset => {
                "the camera clock's offset known in advance (a photograph of the host's clock)"
            }
        })
    }
}

/// Why the files could not be matched.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MatchError {
    /// No camera files were given.
    #[error("no camera files to match")]
    NoShots,
    /// The capture record has no exposures.
    #[error("the capture record has no exposures")]
    NoExposures,
    /// No exposure fired the camera.
    #[error("none of the capture record's {exposures} exposures fired the camera (no X-sync)")]
    NoFiredExposures {
        /// Number of exposures.
        exposures: usize,
    },
    /// An option is out of its range.
    #[error("matching option `{option}` = {value} is out of range ({expected})")]
    InvalidOption {
        /// The option's name.
        option: &'static str,
        /// Its value.
        value: f64,
        /// What it must be.
        expected: &'static str,
    },
    /// A file's sub-second field is not a fraction.
    #[error("{file}: SubSecTimeOriginal {subsec_s} is not a fraction of a second in [0, 1)")]
    InvalidSubsec {
        /// The file.
        file: String,
        /// The value.
        subsec_s: f64,
    },
    /// An exposure's host time is not a number.
    #[error("capture record: exposure {exposure_index} has host time {host_time_us} µs, not a finite number")]
    InvalidHostTime {
        /// The exposure.
        exposure_index: u32,
        /// Its host time.
        host_time_us: f64,
    },
    /// Two exposures share an index.
    #[error("capture record: exposure index {exposure_index} appears more than once")]
    DuplicateExposureIndex {
        /// The index.
        exposure_index: u32,
    },
    /// Files from several bodies, none in the majority.
    #[error("the files come from {} bodies equally often ({}); name the session's body serial", .serials.len(), .serials.join(", "))]
    AmbiguousBody {
        /// The serials tied for most files.
        serials: Vec<String>,
    },
    /// No file is from the expected body.
    #[error("no file was taken by body {expected}; the files' bodies are {}", .found.join(", "))]
    NoShotsFromBody {
        /// The expected serial.
        expected: String,
        /// The serials found.
        found: Vec<String>,
    },
    /// No clock explains enough of the files.
    #[error("no camera clock offset explains the files: the best alignment pairs {best_pairs} of {fired_exposures} fired exposures with {files} files; at least {needed_pairs} pairs are needed (are these files from this session?)")]
    NoConsistentOffset {
        /// Fired exposures.
        fired_exposures: usize,
        /// Files taking part.
        files: usize,
        /// Pairs in the best chain.
        best_pairs: usize,
        /// Pairs required.
        needed_pairs: usize,
    },
    /// Two explanations fit about equally well.
    #[error("ambiguous match, refused: {best_pairs} pairs at camera offset {best_offset_s:.3} s fit about as well as {alternative_pairs} pairs at offset {alternative_offset_s:.3} s; in question: {}; would disambiguate: {}", join_display(.conflicts), join_display(.remedies))]
    Ambiguous {
        /// Pairs of the best chain.
        best_pairs: usize,
        /// Pairs of the alternative.
        alternative_pairs: usize,
        /// The best chain's clock offset, seconds.
        best_offset_s: f64,
        /// The alternative's clock offset, seconds.
        alternative_offset_s: f64,
        /// Every file assigned differently.
        conflicts: Vec<Conflict>,
        /// What would tell them apart.
        remedies: Vec<Remedy>,
    },
}

fn join_display<T: fmt::Display>(items: &[T]) -> String {
    items
        .iter()
        .map(ToString::to_string)
        .collect::<Vec<_>>()
        .join("; ")
}

/// The DCF file number in a file name: `SKB_0412.DNG` -> 412, `DSC05123.ARW` -> 5123,
/// `P1000412.RW2` -> 412 (the 4 digits after the 4-character prefix), else the last run of
/// digits in the name's stem (`shot12.dng` -> 12). Directories are ignored.
pub fn file_number_from_name(name: &str) -> Option<u32> {
    let base = name.rsplit(['/', '\\']).next().unwrap_or(name);
    let stem = match base.rfind('.') {
        Some(dot) if dot > 0 => &base[..dot],
        _ => base,
    };
    let bytes = stem.as_bytes();
    if bytes.len() >= 8 && bytes[4..8].iter().all(u8::is_ascii_digit) {
        return stem.get(4..8).and_then(|s| s.parse().ok());
    }
    let end = bytes.iter().rposition(u8::is_ascii_digit)? + 1;
    let start = bytes[..end]
        .iter()
        .rposition(|b| !b.is_ascii_digit())
        .map_or(0, |p| p + 1);
    let digits = stem.get(start.max(end.saturating_sub(9))..end)?;
    digits.parse().ok()
}

/// A file taking part in the matching, in camera-time order.
#[derive(Debug, Clone)]
struct Shot {
    input: usize,
    /// Camera time (mid-resolution), seconds from the earliest file's whole second.
    c_s: f64,
    resolution_s: f64,
    shutter: Option<u32>,
    file_number: Option<u32>,
}

/// A fired exposure, in host-time order.
#[derive(Debug, Clone)]
struct Fired {
    input: usize,
    /// Host time, seconds from the first fired exposure.
    h_s: f64,
    /// Host time from the middle of the fired exposures, seconds.
    x_s: f64,
}

/// A camera clock: predicted `c = h + offset_s + drift * x`, tolerances widened by `slack_s`.
#[derive(Debug, Clone, Copy)]
struct Clock {
    offset_s: f64,
    drift: f64,
    slack_s: f64,
}

type Pair = (usize, usize);

struct Problem {
    shots: Vec<Shot>,
    fired: Vec<Fired>,
    use_shutter: bool,
    use_file_numbers: bool,
    jitter_s: f64,
    penalty: f64,
    coincidence_penalty: f64,
    max_drift: f64,
    drift_slack_s: f64,
    /// Camera-minus-host offsets allowed by [`MatchOptions::known_offset_s`], in the problem's
    /// relative times.
    known_offset_window_s: Option<(f64, f64)>,
}

/// Best chains ending at and starting at every pair of a candidate set.
struct Chains {
    pairs: Vec<Pair>,
    fwd: Vec<f64>,
    pred: Vec<Option<usize>>,
    bwd: Vec<f64>,
    succ: Vec<Option<usize>>,
    /// Cost of ending a chain at each pair.
    end: Vec<f64>,
}

/// Prefix counts of a set of pairs over the exposure x file grid (compressed to the rows and
/// columns the set uses), for rectangle queries.
struct Grid {
    rows: Vec<usize>,
    cols: Vec<usize>,
    prefix: Vec<u32>,
}

impl Grid {
    fn new(pairs: &[Pair]) -> Self {
        let mut rows: Vec<usize> = pairs.iter().map(|p| p.0).collect();
        let mut cols: Vec<usize> = pairs.iter().map(|p| p.1).collect();
        rows.sort_unstable();
        rows.dedup();
        cols.sort_unstable();
        cols.dedup();
        let stride = cols.len() + 1;
        let mut prefix = vec![0u32; (rows.len() + 1) * stride];
        for &(i, j) in pairs {
            let r = rows.partition_point(|&x| x < i);
            let c = cols.partition_point(|&x| x < j);
            prefix[(r + 1) * stride + c + 1] += 1;
        }
        for r in 1..=rows.len() {
            for c in 1..=cols.len() {
                prefix[r * stride + c] += prefix[(r - 1) * stride + c] + prefix[r * stride + c - 1]
                    - prefix[(r - 1) * stride + c - 1];
            }
        }
        Self { rows, cols, prefix }
    }

    /// True when some pair has exposure in `i0..i1` and file in `j0..j1`.
    fn any(&self, i0: usize, i1: usize, j0: usize, j1: usize) -> bool {
        if i0 >= i1 || j0 >= j1 {
            return false;
        }
        let (r0, r1) = (
            self.rows.partition_point(|&x| x < i0),
            self.rows.partition_point(|&x| x < i1),
        );
        let (c0, c1) = (
            self.cols.partition_point(|&x| x < j0),
            self.cols.partition_point(|&x| x < j1),
        );
        let s = self.cols.len() + 1;
        let at = |r: usize, c: usize| i64::from(self.prefix[r * s + c]);
        at(r1, c1) - at(r0, c1) - at(r1, c0) + at(r0, c0) > 0
    }
}

impl Chains {
    fn total(&self, k: usize) -> f64 {
        self.fwd[k] - self.end[k]
    }

    fn best(&self) -> Option<usize> {
        let mut best: Option<usize> = None;
        for k in 0..self.pairs.len() {
            if best.is_none_or(|b| self.total(k) > self.total(b) + SCORE_EPS) {
                best = Some(k);
            }
        }
        best
    }

    fn forced_score(&self, k: usize) -> f64 {
        self.fwd[k] + self.bwd[k] - 1.0
    }

    fn chain_through(&self, k: usize) -> Vec<Pair> {
        let mut head = vec![self.pairs[k]];
        let mut at = self.pred[k];
        while let Some(p) = at {
            head.push(self.pairs[p]);
            at = self.pred[p];
        }
        head.reverse();
        let mut at = self.succ[k];
        while let Some(s) = at {
            head.push(self.pairs[s]);
            at = self.succ[s];
        }
        head
    }

    fn chain_ending(&self, k: usize) -> Vec<Pair> {
        let mut chain = vec![self.pairs[k]];
        let mut at = self.pred[k];
        while let Some(p) = at {
            chain.push(self.pairs[p]);
            at = self.pred[p];
        }
        chain.reverse();
        chain
    }
}

impl Problem {
    fn tolerance_s(&self, j: usize, slack_s: f64) -> f64 {
        self.shots[j].resolution_s / 2.0 + self.jitter_s + slack_s
    }

    fn residual_s(&self, clock: &Clock, (i, j): Pair) -> f64 {
        let f = &self.fired[i];
        self.shots[j].c_s - (f.h_s + clock.offset_s + clock.drift * f.x_s)
    }

    /// Cost of `q` directly following `p` in a chain; `None` when the shutter counts forbid it.
    fn transition_cost(&self, p: Pair, q: Pair) -> Option<f64> {
        let need = (q.0 - p.0) as i64 + (q.1 - p.1) as i64 - 1;
        let mut cost = 0.0;
        if self.use_shutter {
            if let (Some(a), Some(b)) = (self.shots[p.1].shutter, self.shots[q.1].shutter) {
                let step = i64::from(b) - i64::from(a);
                if step < need {
                    return None;
                }
                if step > need {
                    cost += self.penalty;
                }
            }
        }
        if self.use_file_numbers {
            if let (Some(a), Some(b)) = (self.shots[p.1].file_number, self.shots[q.1].file_number) {
                let step = (i64::from(b) - i64::from(a)).rem_euclid(FILE_NUMBER_MODULUS);
                if step != need.rem_euclid(FILE_NUMBER_MODULUS) {
                    cost += self.penalty;
                }
            }
        }
        Some(cost)
    }

    /// Cost of leaving a pair of `grid` unmatched inside the open rectangle of exposures
    /// `i0..i1` and files `j0..j1` between two chain neighbours: an unmatched file that fits an
    /// unmatched fired exposure is a coincidence a chain must pay for.
    fn skip_cost(&self, grid: &Grid, i0: usize, i1: usize, j0: usize, j1: usize) -> f64 {
        if grid.any(i0, i1, j0, j1) {
            self.coincidence_penalty
        } else {
            0.0
        }
    }

    fn start_cost(&self, grid: &Grid, q: Pair) -> f64 {
        self.skip_cost(grid, 0, q.0, 0, q.1)
    }

    fn end_cost(&self, grid: &Grid, p: Pair) -> f64 {
        self.skip_cost(grid, p.0 + 1, self.fired.len(), p.1 + 1, self.shots.len())
    }

    fn step_cost(&self, grid: &Grid, p: Pair, q: Pair) -> Option<f64> {
        Some(self.transition_cost(p, q)? + self.skip_cost(grid, p.0 + 1, q.0, p.1 + 1, q.1))
    }

    /// Score of a chain among the consistent pairs `set`; `None` if forbidden.
    fn chain_score(&self, chain: &[Pair], set: &[Pair]) -> Option<f64> {
        let (Some(&first), Some(&last)) = (chain.first(), chain.last()) else {
            return Some(0.0);
        };
        let grid = Grid::new(set);
        let mut score =
            chain.len() as f64 - self.start_cost(&grid, first) - self.end_cost(&grid, last);
        for w in chain.windows(2) {
            score -= self.step_cost(&grid, w[0], w[1])?;
        }
        Some(score)
    }

    /// Both dynamic programmes over `pairs` (any order; sorted here by exposure, then file).
    fn chains(&self, pairs: Vec<Pair>) -> Chains {
        let grid = Grid::new(&pairs);
        self.chains_in(pairs, &grid)
    }

    /// [`Self::chains`] over `pairs` with coincidences counted among the pairs of `grid`.
    fn chains_in(&self, mut pairs: Vec<Pair>, grid: &Grid) -> Chains {
        pairs.sort_unstable();
        let n = pairs.len();
        let end: Vec<f64> = pairs.iter().map(|&p| self.end_cost(grid, p)).collect();
        let mut fwd: Vec<f64> = pairs
            .iter()
            .map(|&q| 1.0 - self.start_cost(grid, q))
            .collect();
        let mut pred = vec![None; n];
        for q in 0..n {
            for p in 0..q {
                if pairs[p].0 < pairs[q].0 && pairs[p].1 < pairs[q].1 {
                    if let Some(cost) = self.step_cost(grid, pairs[p], pairs[q]) {
                        let score = fwd[p] + 1.0 - cost;
                        if score > fwd[q] + SCORE_EPS {
                            fwd[q] = score;
                            pred[q] = Some(p);
                        }
                    }
                }
            }
        }
        let mut bwd: Vec<f64> = end.iter().map(|e| 1.0 - e).collect();
        let mut succ = vec![None; n];
        for p in (0..n).rev() {
            for q in p + 1..n {
                if pairs[p].0 < pairs[q].0 && pairs[p].1 < pairs[q].1 {
                    if let Some(cost) = self.step_cost(grid, pairs[p], pairs[q]) {
                        let score = bwd[q] + 1.0 - cost;
                        if score > bwd[p] + SCORE_EPS {
                            bwd[p] = score;
                            succ[p] = Some(q);
                        }
                    }
                }
            }
        }
        Chains {
            pairs,
            fwd,
            pred,
            bwd,
            succ,
            end,
        }
    }

    /// False when a known offset rules the pair out (its offset difference is farther from the
    /// known window than the pair's relaxed tolerance).
    fn within_known_offset(&self, (i, j): Pair) -> bool {
        let Some((lo, hi)) = self.known_offset_window_s else {
            return true;
        };
        let d = self.shots[j].c_s - self.fired[i].h_s;
        let tol = self.tolerance_s(j, self.drift_slack_s);
        d >= lo - tol && d <= hi + tol
    }

    /// Every pair consistent with `clock`.
    fn consistent_pairs(&self, clock: &Clock) -> Vec<Pair> {
        let mut pairs = Vec::new();
        for i in 0..self.fired.len() {
            for j in 0..self.shots.len() {
                if self.residual_s(clock, (i, j)).abs() <= self.tolerance_s(j, clock.slack_s)
                    && self.within_known_offset((i, j))
                {
                    pairs.push((i, j));
                }
            }
        }
        pairs
    }

    /// Step 1 of the algorithm: every maximal candidate set of the relaxed offset-only model,
    /// each visited once, largest first, until the sets are smaller than the score `visit`
    /// returns it still needs.
    fn sweep(&self, mut visit: impl FnMut(&Chains) -> f64) {
        let slack = self.drift_slack_s;
        let mut diffs: Vec<(f64, Pair)> = Vec::with_capacity(self.fired.len() * self.shots.len());
        for (i, f) in self.fired.iter().enumerate() {
            for (j, s) in self.shots.iter().enumerate() {
                if self.within_known_offset((i, j)) {
                    diffs.push((s.c_s - f.h_s, (i, j)));
                }
            }
        }
        diffs.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let tol_max = (0..self.shots.len())
            .map(|j| self.tolerance_s(j, slack))
            .fold(0.0, f64::max);
        let mut seen: HashSet<Vec<Pair>> = HashSet::new();
        let mut sets: Vec<Vec<Pair>> = Vec::new();
        for &(d, (_, j)) in &diffs {
            let offset = d - self.tolerance_s(j, slack);
            let lo = diffs.partition_point(|e| e.0 < offset - tol_max - WINDOW_EPS_S);
            let hi = diffs.partition_point(|e| e.0 <= offset + tol_max + WINDOW_EPS_S);
            let mut set: Vec<Pair> = diffs[lo..hi]
                .iter()
                .filter(|e| (e.0 - offset).abs() <= self.tolerance_s(e.1 .1, slack) + WINDOW_EPS_S)
                .map(|e| e.1)
                .collect();
            set.sort_unstable();
            if seen.insert(set.clone()) {
                sets.push(set);
            }
        }
        // Largest sets first: no chain scores more than its set's size, so once the sets are
        // smaller than what `visit` still looks for, the rest cannot matter.
        sets.sort_by_key(|set| std::cmp::Reverse(set.len()));
        let mut wanted = f64::NEG_INFINITY;
        for set in sets {
            if (set.len() as f64) < wanted {
                break;
            }
            wanted = visit(&self.chains(set));
        }
    }

    /// Chebyshev fit of a chain: the clock minimising the largest tolerance-weighted residual,
    /// and that largest weighted residual (at most 1 means consistent).
    fn fit(&self, chain: &[Pair], fit_drift: bool) -> (Clock, f64) {
        let slack_s = if fit_drift { 0.0 } else { self.drift_slack_s };
        let level = |drift: f64| -> (f64, f64) {
            // Group the residuals by tolerance: lambda = max over groups g, h of
            // (max a_g - min a_h) / (t_g + t_h), and the offset is the middle of the feasible
            // interval at that level.
            let mut groups: BTreeMap<u64, (f64, f64, f64)> = BTreeMap::new();
            for &(i, j) in chain {
                let f = &self.fired[i];
                let a = self.shots[j].c_s - f.h_s - drift * f.x_s;
                let t = self.tolerance_s(j, slack_s);
                let g = groups.entry(t.to_bits()).or_insert((t, a, a));
                g.1 = g.1.max(a);
                g.2 = g.2.min(a);
            }
            let mut lambda: f64 = 0.0;
            for g in groups.values() {
                for h in groups.values() {
                    lambda = lambda.max((g.1 - h.2) / (g.0 + h.0));
                }
            }
            let lower = groups
                .values()
                .map(|g| g.1 - lambda * g.0)
                .fold(f64::NEG_INFINITY, f64::max);
            let upper = groups
                .values()
                .map(|g| g.2 + lambda * g.0)
                .fold(f64::INFINITY, f64::min);
            (lambda, 0.5 * (lower + upper))
        };
        let drift = if fit_drift && chain.len() >= 2 {
            let golden = 0.5 * (5f64.sqrt() - 1.0);
            let (mut a, mut b) = (-self.max_drift, self.max_drift);
            let mut x1 = b - golden * (b - a);
            let mut x2 = a + golden * (b - a);
            let (mut f1, mut f2) = (level(x1).0, level(x2).0);
            for _ in 0..DRIFT_SEARCH_ITERATIONS {
                if f1 <= f2 {
                    b = x2;
                    x2 = x1;
                    f2 = f1;
                    x1 = b - golden * (b - a);
                    f1 = level(x1).0;
                } else {
                    a = x1;
                    x1 = x2;
                    f1 = f2;
                    x2 = a + golden * (b - a);
                    f2 = level(x2).0;
                }
            }
            0.5 * (a + b)
        } else {
            0.0
        };
        let (lambda, offset_s) = level(drift);
        (
            Clock {
                offset_s,
                drift,
                slack_s,
            },
            lambda,
        )
    }

    fn fits_drift(&self, chain: &[Pair], min_pairs_for_drift: usize) -> bool {
        chain.len() >= min_pairs_for_drift.max(2)
    }
}

/// Matches camera files to the capture's exposures by time (see the module docs).
///
/// `exposures` are the capture record's exposures (faults included, any order). Files and
/// exposures are named in the result and in every error.
pub fn match_shots(
    shots: &[CameraShot],
    exposures: &[ExposureInput],
    opts: &MatchOptions,
) -> Result<Matching, MatchError> {
    validate_options(opts)?;
    if shots.is_empty() {
        return Err(MatchError::NoShots);
    }
    if exposures.is_empty() {
        return Err(MatchError::NoExposures);
    }
    let mut indices = HashSet::new();
    for e in exposures {
        if !indices.insert(e.index) {
            return Err(MatchError::DuplicateExposureIndex {
                exposure_index: e.index,
            });
        }
        if !e.host_time_us.is_finite() {
            return Err(MatchError::InvalidHostTime {
                exposure_index: e.index,
                host_time_us: e.host_time_us,
            });
        }
    }
    for s in shots {
        if let Some(subsec_s) = s.time.subsec_s {
            if !(0.0..1.0).contains(&subsec_s) {
                return Err(MatchError::InvalidSubsec {
                    file: s.file.clone(),
                    subsec_s,
                });
            }
        }
    }

    let mut set_aside: Vec<(String, ExtraReason)> = Vec::new();
    let body_ok = select_body(shots, opts, &mut set_aside)?;
    let kept = remove_duplicates(shots, &body_ok, &mut set_aside);

    let time_basis = if kept.iter().all(|&k| shots[k].time.utc_offset_s.is_some()) {
        TimeBasis::Utc
    } else {
        TimeBasis::CameraLocal
    };
    let whole_s = |k: usize| -> i64 {
        let t = &shots[k].time;
        match time_basis {
            TimeBasis::Utc => t.naive_local_s - i64::from(t.utc_offset_s.unwrap_or(0)),
            TimeBasis::CameraLocal => t.naive_local_s,
        }
    };
    let base_s = kept.iter().map(|&k| whole_s(k)).min().unwrap_or(0);
    let mut prepared: Vec<Shot> = kept
        .iter()
        .map(|&k| {
            let s = &shots[k];
            let resolution_s = if s.time.subsec_s.is_some() {
                opts.subsec_resolution_s
            } else {
                1.0
            };
            Shot {
                input: k,
                c_s: (whole_s(k) - base_s) as f64
                    + s.time.subsec_s.unwrap_or(0.0)
                    + resolution_s / 2.0,
                resolution_s,
                shutter: s.shutter_count,
                file_number: s.file_number,
            }
        })
        .collect();
    prepared.sort_by(|a, b| {
        a.c_s
            .total_cmp(&b.c_s)
            .then(a.shutter.cmp(&b.shutter))
            .then(a.file_number.cmp(&b.file_number))
            .then(shots[a.input].file.cmp(&shots[b.input].file))
    });
    let use_shutter = prepared.iter().all(|s| s.shutter.is_some())
        && prepared.windows(2).all(|w| w[0].shutter < w[1].shutter);
    let use_file_numbers = prepared.len() >= 2 && prepared.iter().all(|s| s.file_number.is_some());

    let mut fired_inputs: Vec<usize> = (0..exposures.len())
        .filter(|&k| exposures[k].camera_fired())
        .collect();
    if fired_inputs.is_empty() {
        return Err(MatchError::NoFiredExposures {
            exposures: exposures.len(),
        });
    }
    fired_inputs.sort_by(|&a, &b| {
        exposures[a]
            .host_time_us
            .total_cmp(&exposures[b].host_time_us)
            .then(exposures[a].index.cmp(&exposures[b].index))
    });
    let first_us = exposures[fired_inputs[0]].host_time_us;
    let last_us = exposures[fired_inputs[fired_inputs.len() - 1]].host_time_us;
    let mid_s = 0.5 * (last_us - first_us) * 1e-6;
    let fired: Vec<Fired> = fired_inputs
        .iter()
        .map(|&k| {
            let h_s = (exposures[k].host_time_us - first_us) * 1e-6;
            Fired {
                input: k,
                h_s,
                x_s: h_s - mid_s,
            }
        })
        .collect();
    let max_drift = opts.max_drift_ppm * 1e-6;
    let problem = Problem {
        shots: prepared,
        fired,
        use_shutter,
        use_file_numbers,
        jitter_s: opts.jitter_tolerance_s,
        penalty: opts.counter_penalty_pairs,
        coincidence_penalty: opts.coincidence_penalty_pairs,
        max_drift,
        drift_slack_s: max_drift * mid_s,
        known_offset_window_s: opts.known_offset_s.map(|(offset_s, tolerance_s)| {
            let relative_s = offset_s - (base_s as f64 - first_us * 1e-6);
            (relative_s - tolerance_s, relative_s + tolerance_s)
        }),
    };

    // Step 1-2: the best chain over every candidate set.
    let mut best: Option<(f64, Vec<Pair>)> = None;
    problem.sweep(|chains| {
        if let Some(k) = chains.best() {
            let score = chains.total(k);
            if best.as_ref().is_none_or(|b| score > b.0 + SCORE_EPS) {
                best = Some((score, chains.chain_ending(k)));
            }
        }
        // Only a larger score can replace the best.
        best.as_ref()
            .map_or(f64::NEG_INFINITY, |b| b.0 + 2.0 * SCORE_EPS)
    });
    let n_fired = problem.fired.len();
    let n_shots = problem.shots.len();
    let needed = ((opts.min_matched_fraction * n_fired.min(n_shots) as f64).ceil() as usize).max(1);
    let Some((_, relaxed_chain)) = best else {
        // Only a known offset that no pair fits leaves no candidate at all.
        return Err(MatchError::NoConsistentOffset {
            fired_exposures: n_fired,
            files: n_shots,
            best_pairs: 0,
            needed_pairs: needed,
        });
    };

    // Step 3: refit and re-assign until stable.
    let (chain, clock) = refine(&problem, relaxed_chain, opts.min_pairs_for_drift);
    let best_score = problem
        .chain_score(&chain, &problem.consistent_pairs(&clock))
        .unwrap_or(0.0);

    if chain.len() < needed {
        return Err(MatchError::NoConsistentOffset {
            fired_exposures: n_fired,
            files: n_shots,
            best_pairs: chain.len(),
            needed_pairs: needed,
        });
    }

    // Step 4: the best alternative over every candidate set.
    let in_chain: HashSet<Pair> = chain.iter().copied().collect();
    let mut alternative: Option<(f64, Vec<Pair>)> = None;
    let ambiguous_from = best_score - opts.ambiguity_margin_pairs - SCORE_EPS;
    problem.sweep(|chains| {
        for k in 0..chains.pairs.len() {
            if in_chain.contains(&chains.pairs[k]) {
                continue;
            }
            let score = chains.forced_score(k);
            if alternative.as_ref().is_none_or(|a| score > a.0 + SCORE_EPS) {
                alternative = Some((score, chains.chain_through(k)));
            }
        }
        // Sets smaller than an ambiguous score cannot hold an ambiguous alternative.
        ambiguous_from
    });
    // Chains that only drop pairs of the answer are consistent with its own clock: the best
    // of them, one dropped pair at a time, under the answer's consistent pairs.
    let final_set = problem.consistent_pairs(&clock);
    let final_grid = Grid::new(&final_set);
    for &dropped in &chain {
        let set: Vec<Pair> = final_set
            .iter()
            .copied()
            .filter(|&p| p != dropped)
            .collect();
        let chains = problem.chains_in(set, &final_grid);
        if let Some(k) = chains.best() {
            let score = chains.total(k);
            if alternative.as_ref().is_none_or(|a| score > a.0 + SCORE_EPS) {
                alternative = Some((score, chains.chain_ending(k)));
            }
        }
    }
    let offset_base_s = base_s as f64 - first_us * 1e-6;
    if let Some((alt_score, alt_chain)) = alternative {
        if alt_score >= ambiguous_from {
            let (alt_clock, _) = problem.fit(&alt_chain, false);
            return Err(ambiguity(
                &problem,
                shots,
                exposures,
                &chain,
                &alt_chain,
                clock.offset_s + offset_base_s,
                alt_clock.offset_s + offset_base_s,
            ));
        }
    }

    Ok(assemble(
        &problem,
        shots,
        exposures,
        &chain,
        &clock,
        first_us,
        mid_s,
        offset_base_s,
        time_basis,
        set_aside,
        opts,
    ))
}

fn validate_options(opts: &MatchOptions) -> Result<(), MatchError> {
    if let Some((offset_s, tolerance_s)) = opts.known_offset_s {
        if !offset_s.is_finite() {
            return Err(MatchError::InvalidOption {
                option: "known_offset_s",
                value: offset_s,
                expected: "finite",
            });
        }
        if !(tolerance_s >= 0.0 && tolerance_s.is_finite()) {
            return Err(MatchError::InvalidOption {
                option: "known_offset_s tolerance",
                value: tolerance_s,
                expected: "finite and >= 0",
            });
        }
    }
    let checks: [(&'static str, f64, bool, &'static str); 7] = [
        (
            "coincidence_penalty_pairs",
            opts.coincidence_penalty_pairs,
            opts.coincidence_penalty_pairs > 0.0 && opts.coincidence_penalty_pairs.is_finite(),
            "finite and > 0",
        ),
        (
            "jitter_tolerance_s",
            opts.jitter_tolerance_s,
            opts.jitter_tolerance_s >= 0.0 && opts.jitter_tolerance_s < 0.5,
            "in [0, 0.5) s",
        ),
        (
            "subsec_resolution_s",
            opts.subsec_resolution_s,
            opts.subsec_resolution_s > 0.0 && opts.subsec_resolution_s <= 1.0,
            "in (0, 1] s",
        ),
        (
            "max_drift_ppm",
            opts.max_drift_ppm,
            (0.0..1e4).contains(&opts.max_drift_ppm),
            "in [0, 10000) ppm",
        ),
        (
            "ambiguity_margin_pairs",
            opts.ambiguity_margin_pairs,
            opts.ambiguity_margin_pairs >= 0.0 && opts.ambiguity_margin_pairs.is_finite(),
            "finite and >= 0",
        ),
        (
            "min_matched_fraction",
            opts.min_matched_fraction,
            (0.0..=1.0).contains(&opts.min_matched_fraction),
            "in [0, 1]",
        ),
        (
            "counter_penalty_pairs",
            opts.counter_penalty_pairs,
            opts.counter_penalty_pairs >= 0.0 && opts.counter_penalty_pairs.is_finite(),
            "finite and >= 0",
        ),
    ];
    for (option, value, ok, expected) in checks {
        if !ok {
            return Err(MatchError::InvalidOption {
                option,
                value,
                expected,
            });
        }
    }
    Ok(())
}

/// Indices of the files from the session's body; the others go to `set_aside`.
fn select_body(
    shots: &[CameraShot],
    opts: &MatchOptions,
    set_aside: &mut Vec<(String, ExtraReason)>,
) -> Result<Vec<usize>, MatchError> {
    let mut counts: BTreeMap<&str, usize> = BTreeMap::new();
    for s in shots {
        if let Some(serial) = &s.body_serial {
            *counts.entry(serial.as_str()).or_insert(0) += 1;
        }
    }
    let expected: String = match &opts.expected_body_serial {
        Some(serial) => {
            if !counts.is_empty() && !counts.contains_key(serial.as_str()) {
                return Err(MatchError::NoShotsFromBody {
                    expected: serial.clone(),
                    found: counts.keys().map(|s| (*s).to_owned()).collect(),
                });
            }
            serial.clone()
        }
        None => {
            let Some(&top) = counts.values().max() else {
                return Ok((0..shots.len()).collect());
            };
            let leaders: Vec<String> = counts
                .iter()
                .filter(|(_, &c)| c == top)
                .map(|(s, _)| (*s).to_owned())
                .collect();
            if leaders.len() > 1 {
                return Err(MatchError::AmbiguousBody { serials: leaders });
            }
            leaders.into_iter().next().unwrap_or_default()
        }
    };
    let mut kept = Vec::new();
    for (k, s) in shots.iter().enumerate() {
        match &s.body_serial {
            Some(serial) if *serial != expected => set_aside.push((
                s.file.clone(),
                ExtraReason::AnotherBody {
                    serial: serial.clone(),
                    expected: expected.clone(),
                },
            )),
            _ => kept.push(k),
        }
    }
    Ok(kept)
}

/// `candidates` minus duplicates (reported in `set_aside`), in input order.
fn remove_duplicates(
    shots: &[CameraShot],
    candidates: &[usize],
    set_aside: &mut Vec<(String, ExtraReason)>,
) -> Vec<usize> {
    let base_name = |f: &str| f.rsplit(['/', '\\']).next().unwrap_or(f).to_owned();
    let time_key = |t: &CameraTime| (t.naive_local_s, t.subsec_s.map(f64::to_bits));
    let mut by_path: HashMap<&str, usize> = HashMap::new();
    let mut by_name_time: HashMap<(String, (i64, Option<u64>)), usize> = HashMap::new();
    let mut by_count_time: HashMap<(u32, (i64, Option<u64>)), usize> = HashMap::new();
    let mut kept = Vec::new();
    for &k in candidates {
        let s = &shots[k];
        let t = time_key(&s.time);
        let name_key = (base_name(&s.file), t);
        let original = by_path
            .get(s.file.as_str())
            .or_else(|| by_name_time.get(&name_key))
            .or_else(|| s.shutter_count.and_then(|c| by_count_time.get(&(c, t))))
            .copied();
        if let Some(of) = original {
            set_aside.push((
                s.file.clone(),
                ExtraReason::Duplicate {
                    of: shots[of].file.clone(),
                },
            ));
            continue;
        }
        by_path.insert(s.file.as_str(), k);
        by_name_time.insert(name_key, k);
        if let Some(c) = s.shutter_count {
            by_count_time.insert((c, t), k);
        }
        kept.push(k);
    }
    kept
}

/// Step 3: alternate the Chebyshev fit and the assignment under the fitted clock.
fn refine(
    problem: &Problem,
    relaxed_chain: Vec<Pair>,
    min_pairs_for_drift: usize,
) -> (Vec<Pair>, Clock) {
    let fallback = {
        let (clock, _) = problem.fit(&relaxed_chain, false);
        (relaxed_chain.clone(), clock)
    };
    let mut chain = relaxed_chain;
    for _ in 0..MAX_REFINE_ROUNDS {
        let (clock, _) = problem.fit(&chain, problem.fits_drift(&chain, min_pairs_for_drift));
        let chains = problem.chains(problem.consistent_pairs(&clock));
        let Some(k) = chains.best() else {
            break;
        };
        let next = chains.chain_ending(k);
        if next == chain {
            break;
        }
        chain = next;
    }
    let (clock, level) = problem.fit(&chain, problem.fits_drift(&chain, min_pairs_for_drift));
    let score_of = |chain: &[Pair], clock: &Clock| {
        problem
            .chain_score(chain, &problem.consistent_pairs(clock))
            .unwrap_or(f64::NEG_INFINITY)
    };
    if level <= 1.0 + CONSISTENCY_EPS
        && score_of(&chain, &clock) >= score_of(&fallback.0, &fallback.1) - SCORE_EPS
    {
        (chain, clock)
    } else {
        fallback
    }
}

fn ambiguity(
    problem: &Problem,
    shots: &[CameraShot],
    exposures: &[ExposureInput],
    chain: &[Pair],
    alt_chain: &[Pair],
    best_offset_s: f64,
    alternative_offset_s: f64,
) -> MatchError {
    let assign = |c: &[Pair]| -> HashMap<usize, u32> {
        c.iter()
            .map(|&(i, j)| (j, exposures[problem.fired[i].input].index))
            .collect()
    };
    let a = assign(chain);
    let b = assign(alt_chain);
    let mut conflicts = Vec::new();
    for j in 0..problem.shots.len() {
        let (ea, eb) = (a.get(&j).copied(), b.get(&j).copied());
        if ea != eb {
            conflicts.push(Conflict {
                file: shots[problem.shots[j].input].file.clone(),
                exposure_best: ea,
                exposure_alternative: eb,
            });
        }
    }
    let mut remedies = Vec::new();
    if problem.shots.iter().any(|s| s.resolution_s >= 1.0) {
        remedies.push(Remedy::SubSecondTimes);
    }
    // Counters only tell apart explanations on the same clock (which exposure lacks a file);
    // a shift of the whole clock keeps every counter step.
    let same_clock = (best_offset_s - alternative_offset_s).abs()
        <= 2.0 * problem.jitter_s
            + problem
                .shots
                .iter()
                .map(|s| s.resolution_s)
                .fold(0.0, f64::max);
    if !problem.use_shutter && same_clock {
        remedies.push(Remedy::ShutterCounts);
    }
    let fired = problem.fired.len();
    if chain.len() < fired || alt_chain.len() < fired {
        remedies.push(Remedy::FewerMissingFiles);
    }
    if chain.len() < problem.shots.len() || alt_chain.len() < problem.shots.len() {
        remedies.push(Remedy::RemoveExtraFiles);
    }
    if !same_clock {
        remedies.push(Remedy::KnownClockOffset);
    }
    MatchError::Ambiguous {
        best_pairs: chain.len(),
        alternative_pairs: alt_chain.len(),
        best_offset_s,
        alternative_offset_s,
        conflicts,
        remedies,
    }
}

#[allow(clippy::too_many_arguments)]
fn assemble(
    problem: &Problem,
    shots: &[CameraShot],
    exposures: &[ExposureInput],
    chain: &[Pair],
    clock: &Clock,
    first_us: f64,
    mid_s: f64,
    offset_base_s: f64,
    time_basis: TimeBasis,
    set_aside: Vec<(String, ExtraReason)>,
    opts: &MatchOptions,
) -> Matching {
    let mut pairs: Vec<MatchedPair> = chain
        .iter()
        .map(|&(i, j)| {
            let e = &exposures[problem.fired[i].input];
            MatchedPair {
                exposure_index: e.index,
                role: e.role,
                file: shots[problem.shots[j].input].file.clone(),
                residual_s: problem.residual_s(clock, (i, j)),
            }
        })
        .collect();
    pairs.sort_by_key(|p| p.exposure_index);
    let residuals: Vec<f64> = pairs.iter().map(|p| p.residual_s).collect();
    let residual_max_s = residuals.iter().map(|r| r.abs()).fold(0.0, f64::max);
    let residual_rms_s = if residuals.is_empty() {
        0.0
    } else {
        (residuals.iter().map(|r| r * r).sum::<f64>() / residuals.len() as f64).sqrt()
    };
    let time_resolution_s = chain
        .iter()
        .map(|&(_, j)| problem.shots[j].resolution_s)
        .fold(0.0, f64::max);
    let tolerance_s = chain
        .iter()
        .map(|&(_, j)| problem.tolerance_s(j, clock.slack_s))
        .fold(0.0, f64::max);

    let matched_shots: HashSet<usize> = chain.iter().map(|&(_, j)| j).collect();
    let matched_fired: HashSet<usize> = chain.iter().map(|&(i, _)| i).collect();
    let last_h_s = problem.fired.last().map_or(0.0, |f| f.h_s);
    let unfired: Vec<(u32, f64)> = exposures
        .iter()
        .filter(|e| !e.camera_fired())
        .map(|e| (e.index, (e.host_time_us - first_us) * 1e-6))
        .collect();
    let mut extra_files = Vec::new();
    for (j, s) in problem.shots.iter().enumerate() {
        if matched_shots.contains(&j) {
            continue;
        }
        let tol = problem.tolerance_s(j, clock.slack_s);
        // Invert c = h + offset + drift * (h - mid) for the host time the file was taken at.
        let h_s = (s.c_s - clock.offset_s + clock.drift * mid_s) / (1.0 + clock.drift);
        let reason = if let Some(&(exposure_index, _)) = unfired
            .iter()
            .find(|(_, hu)| (h_s - hu).abs() <= tol + UNFIRED_LAG_WINDOW_S)
        {
            ExtraReason::NearUnfiredExposure { exposure_index }
        } else if h_s < -tol {
            ExtraReason::BeforeSession
        } else if h_s > last_h_s + tol {
            ExtraReason::AfterSession
        } else {
            ExtraReason::BetweenShots
        };
        extra_files.push((shots[s.input].file.clone(), reason));
    }
    extra_files.extend(set_aside);

    let mut missing: Vec<u32> = (0..problem.fired.len())
        .filter(|i| !matched_fired.contains(i))
        .map(|i| exposures[problem.fired[i].input].index)
        .collect();
    missing.sort_unstable();
    let mut no_file_expected: Vec<u32> = unfired.iter().map(|&(i, _)| i).collect();
    no_file_expected.sort_unstable();

    Matching {
        pairs,
        clock: CameraClockFit {
            host_ref_us: first_us + mid_s * 1e6,
            offset_s: clock.offset_s + offset_base_s,
            drift_ppm: clock.drift * 1e6,
            drift_fitted: problem.fits_drift(chain, opts.min_pairs_for_drift)
                && clock.slack_s == 0.0,
            residual_rms_s,
            residual_max_s,
            time_resolution_s,
            tolerance_s,
            pairs_used: chain.len(),
        },
        extra_files,
        missing,
        no_file_expected,
        time_basis,
        shutter_counts_used: problem.use_shutter,
        file_numbers_used: problem.use_file_numbers,
    }
}

#[cfg(test)]
mod tests;
