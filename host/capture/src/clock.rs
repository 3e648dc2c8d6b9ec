//! Device-to-host clock model: offset and drift from round-trip clock reads.
//!
//! The host reads the device clock several times. Each read is a round trip: the host notes its
//! Unix time `t_send` before the request and `t_recv` after the response, and the device reports
//! its microsecond clock `d` somewhere in between. Assuming symmetric link latency, the device
//! read happened at the host midpoint `m = (t_send + t_recv) / 2`, with an error of at most half
//! the round trip.
//!
//! The model is affine, `host = host_ref + (d - device_ref) * (1 + drift)`, fitted by ordinary
//! least squares of `m` on `d`. Both clocks are large integers (device time since boot may pass
//! 2^32 us after 71 minutes; host Unix time is ~1.8e15 us), so before any floating point the
//! fit subtracts a reference from each: device times relative to the first read (as exact `i64`
//! differences), host times relative to the first midpoint. The sums are then small and centered,
//! which keeps the normal equations well conditioned. `device_ref_us` is the (integer) mean device
//! time, where the fitted intercept has the least variance.
//!
//! With a single read, or reads too close in device time to see drift
//! ([`MIN_DRIFT_SPAN_US`]), drift is reported as zero and only the offset is fitted.
//! The residual RMS (microseconds) is reported with the model: it bounds how well an exposure's
//! device time can be placed on the host clock.
//!
//! **Clock rate.** [`device_rate`] is the coarse counterpart of the drift: device microseconds
//! per host microsecond, fitted over a host-time span of at least [`MIN_RATE_SPAN_US`]. A real
//! board's rate is 1 within its crystal's tolerance; a simulator run with `--time-scale 20`
//! spends device time twenty times faster (rate 20). The capture session converts host
//! durations it sets on the device (the host watchdog) through this rate, so the same settings
//! hold on a board, a time-scaled simulator and an emulator.

use skinbrdf_session::capture::ClockModel;

/// One round-trip read of the device clock.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ClockRead {
    /// Host Unix time just before the request was written, microseconds.
    pub host_send_us: u64,
    /// Device clock in the response, microseconds since device boot.
    pub device_us: u64,
    /// Host Unix time just after the response was decoded, microseconds.
    pub host_recv_us: u64,
}

impl ClockRead {
    /// Round-trip time in microseconds (zero if the host clock stepped backwards).
    pub fn round_trip_us(&self) -> u64 {
        self.host_recv_us.saturating_sub(self.host_send_us)
    }
}

/// Shortest device-time span over which drift is estimated: 100 ms. Over shorter spans a 1 us
/// midpoint error is already 10 ppm of drift, more than a crystal's real drift, so the offset-only
/// model is the better estimate.
pub const MIN_DRIFT_SPAN_US: u64 = 100_000;

/// Why no clock model could be fitted.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ClockError {
    /// No reads were taken.
    #[error("no clock reads to fit a clock model")]
    NoReads,
}

/// Fits offset and drift by least squares over the midpoints of `reads`.
pub fn fit_clock(reads: &[ClockRead]) -> Result<ClockModel, ClockError> {
    let first = reads.first().ok_or(ClockError::NoReads)?;
    let d0 = first.device_us;
    let h0 = first.host_send_us;
    let (xs, ys) = relative_times(reads);
    let n = reads.len() as f64;
    let Moments {
        x_mean,
        y_mean,
        sxx,
        sxy,
    } = moments(&xs, &ys);
    let (min_d, max_d) = reads.iter().fold((u64::MAX, 0u64), |(lo, hi), r| {
        (lo.min(r.device_us), hi.max(r.device_us))
    });
    let span = max_d - min_d;
    let slope = if span >= MIN_DRIFT_SPAN_US && sxx > 0.0 {
        sxy / sxx
    } else {
        1.0
    };
    // Reference at the (integer) mean device time.
    let x_ref = x_mean.round();
    let device_ref_us = (d0 as i128 + x_ref as i128).clamp(0, u64::MAX as i128) as u64;
    let y_ref = y_mean + slope * (x_ref - x_mean);
    let host_ref_us = h0 as f64 + y_ref;
    let sum_sq: f64 = xs
        .iter()
        .zip(&ys)
        .map(|(x, y)| {
            let r = y - (y_ref + slope * (x - x_ref));
            r * r
        })
        .sum();
    Ok(ClockModel {
        device_ref_us,
        host_ref_us,
        drift_ppm: (slope - 1.0) * 1e6,
        residual_rms_us: (sum_sq / n).sqrt(),
        samples: u32::try_from(reads.len()).unwrap_or(u32::MAX),
    })
}

/// A read whose round trip exceeds this many times the median round trip (plus
/// [`RTT_SLACK_US`]) was delayed on one leg (host descheduled, USB retry); its midpoint is biased,
/// so [`select_reads`] leaves it out of the fit.
pub const RTT_OUTLIER_FACTOR: u64 = 3;

/// Absolute slack added to the outlier threshold, so sub-millisecond jitter on a fast link never
/// discards reads.
pub const RTT_SLACK_US: u64 = 1_000;

/// The reads whose round trip is not an outlier (see [`RTT_OUTLIER_FACTOR`]).
pub fn select_reads(reads: &[ClockRead]) -> Vec<ClockRead> {
    let mut rtts: Vec<u64> = reads.iter().map(ClockRead::round_trip_us).collect();
    rtts.sort_unstable();
    let Some(&median) = rtts.get(rtts.len() / 2) else {
        return Vec::new();
    };
    let limit = median
        .saturating_mul(RTT_OUTLIER_FACTOR)
        .saturating_add(RTT_SLACK_US);
    reads
        .iter()
        .copied()
        .filter(|r| r.round_trip_us() <= limit)
        .collect()
}

/// Shortest host-time span (between the first and last midpoint) over which [`device_rate`]
/// estimates the device clock's rate: 20 ms. A read's midpoint is uncertain by half its round
/// trip (under 1 ms on USB full speed, tens of microseconds on a pseudo-terminal), so over 20 ms
/// the rate is known to a few per cent: ample for converting a watchdog of seconds, while a
/// time-scaled simulator differs from a board by whole factors.
pub const MIN_RATE_SPAN_US: u64 = 20_000;

/// Host-time span covered by the midpoints of `reads`, microseconds (0 for fewer than 2).
pub fn host_span_us(reads: &[ClockRead]) -> u64 {
    let mids = reads
        .iter()
        .map(|r| r.host_send_us / 2 + r.host_recv_us / 2);
    match (mids.clone().min(), mids.max()) {
        (Some(lo), Some(hi)) => hi - lo,
        _ => 0,
    }
}

/// Device microseconds per host microsecond: least squares of device time on host midpoint over
/// the reads whose round trip is not an outlier ([`select_reads`]). `None` when those reads span
/// less than [`MIN_RATE_SPAN_US`] of host time or the fit is not a positive finite rate (a
/// device clock that does not advance).
pub fn device_rate(reads: &[ClockRead]) -> Option<f64> {
    let kept = select_reads(reads);
    if host_span_us(&kept) < MIN_RATE_SPAN_US {
        return None;
    }
    if kept.is_empty() {
        return None;
    }
    // Device time on host midpoint: the roles of `fit_clock`'s axes swapped.
    let (device, host_mid) = relative_times(&kept);
    let Moments { sxx, sxy, .. } = moments(&host_mid, &device);
    let rate = sxy / sxx;
    (rate.is_finite() && rate > 0.0).then_some(rate)
}

/// Device times and host midpoints of `reads`, relative to the first read's device time and
/// host send time, microseconds: exact integer differences first, then f64 (differences are far
/// below 2^53).
fn relative_times(reads: &[ClockRead]) -> (Vec<f64>, Vec<f64>) {
    let Some(first) = reads.first() else {
        return (Vec::new(), Vec::new());
    };
    let (d0, h0) = (first.device_us as i128, first.host_send_us as i128);
    reads
        .iter()
        .map(|r| {
            let send = r.host_send_us as i128 - h0;
            let recv = r.host_recv_us as i128 - h0;
            (
                (r.device_us as i128 - d0) as f64,
                (send + recv) as f64 / 2.0,
            )
        })
        .unzip()
}

/// Means and centred second moments of a least-squares line `y` on `x`.
struct Moments {
    x_mean: f64,
    y_mean: f64,
    sxx: f64,
    sxy: f64,
}

fn moments(xs: &[f64], ys: &[f64]) -> Moments {
    let n = xs.len() as f64;
    let x_mean = xs.iter().sum::<f64>() / n;
    let y_mean = ys.iter().sum::<f64>() / n;
    let (mut sxx, mut sxy) = (0.0, 0.0);
    for (x, y) in xs.iter().zip(ys) {
        sxx += (x - x_mean) * (x - x_mean);
        sxy += (x - x_mean) * (y - y_mean);
    }
    Moments {
        x_mean,
        y_mean,
        sxx,
        sxy,
    }
}

/// Host Unix time now, in microseconds.
pub fn host_now_us() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| u64::try_from(d.as_micros()).unwrap_or(u64::MAX))
        .unwrap_or(0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Builds a read of a device whose clock maps to host time as `host = offset + d*(1+drift)`.
    fn read(
        device_us: u64,
        host_at_0: f64,
        drift_ppm: f64,
        rtt_us: u64,
        skew_us: i64,
    ) -> ClockRead {
        let host_mid = host_at_0 + device_us as f64 * (1.0 + drift_ppm * 1e-6) + skew_us as f64;
        let send = (host_mid - rtt_us as f64 / 2.0).round() as u64;
        ClockRead {
            host_send_us: send,
            device_us,
            host_recv_us: send + rtt_us,
        }
    }

    #[test]
    fn no_reads_is_an_error() {
        assert_eq!(fit_clock(&[]), Err(ClockError::NoReads));
    }

    #[test]
    fn single_read_gives_offset_only() {
        let r = ClockRead {
            host_send_us: 1_700_000_000_000_000,
            device_us: 5_000_000,
            host_recv_us: 1_700_000_000_000_400,
        };
        let m = fit_clock(&[r]).expect("fit");
        assert_eq!(m.drift_ppm, 0.0);
        assert_eq!(m.samples, 1);
        assert!((m.to_host_us(5_000_000) - 1_700_000_000_000_200.0).abs() < 0.5);
    }

    #[test]
    fn midpoint_is_used() {
        // Asymmetric reads around the same line: midpoints lie exactly on it.
        let reads: Vec<_> = (0..10)
            .map(|i| read(1_000_000 * i, 1.7e15, 0.0, 100 + 50 * i, 0))
            .collect();
        let m = fit_clock(&reads).expect("fit");
        assert!(m.residual_rms_us < 1.0, "{m:?}");
        assert!(m.drift_ppm.abs() < 1.0, "{m:?}");
    }

    #[test]
    fn slow_round_trips_are_left_out() {
        let mut reads: Vec<_> = (0..10)
            .map(|i| read(1_000_000 * i, 1.7e15, 0.0, 200, 0))
            .collect();
        reads.push(read(10_500_000, 1.7e15, 0.0, 80_000, 30_000));
        let kept = select_reads(&reads);
        assert_eq!(kept.len(), 10);
        let m = fit_clock(&kept).expect("fit");
        assert!(m.residual_rms_us < 1.0, "{m:?}");
    }

    #[test]
    fn residual_reports_scatter() {
        // Alternating +-10 us scatter around a perfect line gives an RMS of about 10 us.
        let reads: Vec<_> = (0..20)
            .map(|i| {
                read(
                    500_000 * i,
                    1.7e15,
                    20.0,
                    300,
                    if i % 2 == 0 { 10 } else { -10 },
                )
            })
            .collect();
        let m = fit_clock(&reads).expect("fit");
        assert!((m.residual_rms_us - 10.0).abs() < 1.5, "{m:?}");
    }

    #[test]
    fn rate_needs_a_host_span() {
        // Reads 1 ms of host time apart on a device running 20x faster.
        let reads: Vec<_> = (0..30)
            .map(|i| {
                let send = 1_700_000_000_000_000 + 1_000 * i;
                ClockRead {
                    host_send_us: send,
                    device_us: 5_000_000 + 20 * (1_000 * i + 50),
                    host_recv_us: send + 100,
                }
            })
            .collect();
        assert_eq!(device_rate(&reads[..10]), None, "9 ms is too short");
        let rate = device_rate(&reads).expect("29 ms");
        assert!((rate - 20.0).abs() < 1e-6, "{rate}");
        assert_eq!(host_span_us(&reads), 29_000);
        assert_eq!(host_span_us(&reads[..1]), 0);
    }

    #[test]
    fn rate_of_a_real_board_is_one() {
        let reads: Vec<_> = (0..8)
            .map(|i| read(2_000_000 + 10_000 * i, 1.7e15, 30.0, 400, 0))
            .collect();
        let rate = device_rate(&reads).expect("70 ms");
        assert!((rate - 1.0).abs() < 1e-3, "{rate}");
    }

    proptest! {
        #[test]
        fn recovers_offset_and_drift(
            start_us in 0u64..(1u64 << 45),
            host_at_0 in 1.0e15f64..2.0e15,
            drift_ppm in -200.0f64..200.0,
            n in 3usize..40,
            step_us in 200_000u64..5_000_000,
            rtt_us in 50u64..2_000,
            noise in proptest::collection::vec(-3i64..=3, 40),
        ) {
            let reads: Vec<_> = (0..n)
                .map(|i| read(start_us + step_us * i as u64, host_at_0, drift_ppm, rtt_us, noise[i]))
                .collect();
            let m = fit_clock(&reads).expect("fit");
            // Midpoint rounding (0.5 us) plus +-3 us noise over >= 3 reads spaced >= 0.2 s:
            // drift error stays well under 20 ppm and the mapping within ~5 us in the read span.
            prop_assert!((m.drift_ppm - drift_ppm).abs() < 20.0, "drift {} vs {}", m.drift_ppm, drift_ppm);
            let span_end = start_us + step_us * (n as u64 - 1);
            for d in [start_us, (start_us + span_end) / 2, span_end] {
                let truth = host_at_0 + d as f64 * (1.0 + drift_ppm * 1e-6);
                prop_assert!((m.to_host_us(d) - truth).abs() < 5.0,
                    "at {d}: {} vs {truth}", m.to_host_us(d));
            }
            prop_assert!(m.residual_rms_us <= 4.0);
            prop_assert_eq!(m.samples as usize, n);
        }

        #[test]
        fn exact_beyond_u32_range(start_us in (1u64 << 32)..(1u64 << 52), drift_ppm in -50.0f64..50.0) {
            // Noise-free reads at device times far past 2^32 us: the fit is exact to rounding.
            let reads: Vec<_> = (0..8)
                .map(|i| read(start_us + 1_000_000 * i, 1.6e15, drift_ppm, 200, 0))
                .collect();
            let m = fit_clock(&reads).expect("fit");
            prop_assert!(m.residual_rms_us < 1.0, "{:?}", m);
            prop_assert!((m.drift_ppm - drift_ppm).abs() < 1.0, "{:?}", m);
            let truth = 1.6e15 + start_us as f64 * (1.0 + drift_ppm * 1e-6);
            prop_assert!((m.to_host_us(start_us) - truth).abs() < 2.0);
        }
    }
}
