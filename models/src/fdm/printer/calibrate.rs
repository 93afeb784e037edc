//! Fitting a virtual printer's profile to measured lines ([`calibrate`]), and how well
//! a profile calibrated without a line reproduces it ([`held_out_agreement`]).

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::{print_line, truth_grid_weights, Effects, PrintedLine, PrinterProfile, Wander, SMOOTHING_MM};
use crate::fdm::discrepancy::fit::{fit, predict};
use crate::fdm::discrepancy::mechanisms::WIDTH_CAP;
use crate::fdm::discrepancy::{FdmLine, FdmModel};
use crate::fdm::line::MeasuredLine;

/// Window over which the wander is separated from the edge roughness (mm).
const WANDER_WINDOW_MM: f64 = 5.0;

/// A profile fitted to measured lines: the lag model (with a start blob if
/// `has_start_blob`, with the width cap if `width_cap`) by the discrepancy engine's
/// least squares on all lines; the line-to-line height, the wander and the edge
/// roughness from the fit's relative residuals.
///
/// - Each line's mean relative residual is its own height's; their root mean square
///   is the height's deviation.
/// - The rest is split by a [`WANDER_WINDOW_MM`] moving average. Its slow part gives
///   the wander's deviation, and the lag at which its autocorrelation falls below 1/e
///   its length.
/// - The fast part (in mm) gives the roughness: its variance split evenly between two
///   independent edges, its lag-one autocorrelation the length. The measured widths
///   carry the camera's quantisation and noise too, which the roughness absorbs.
pub fn calibrate(lines: &[MeasuredLine], has_start_blob: bool, width_cap: bool) -> Result<PrinterProfile, String> {
    let groups: Vec<FdmLine> = lines.iter().enumerate().map(|(i, l)| FdmLine::new(i.to_string(), l.clone())).collect();
    let model = FdmModel::new(&groups, has_start_blob, SMOOTHING_MM);
    let active: &[usize] = if width_cap { &[WIDTH_CAP] } else { &[] };
    let train: Vec<&FdmLine> = groups.iter().collect();
    let fitted = fit(&model, active, &train, None).map_err(|e| e.to_string())?;
    let (mut offsets, mut slow, mut fast) = (Vec::new(), Vec::new(), Vec::new());
    for group in &groups {
        let predicted = predict(&model, &fitted, group, None).map_err(|e| e.to_string())?;
        let line = &group.line;
        let mut relative: Vec<f64> = line.widths_mm.iter().zip(&predicted).map(|(m, p)| m / p - 1.0).collect();
        let offset = relative.iter().sum::<f64>() / relative.len() as f64;
        relative.iter_mut().for_each(|r| *r -= offset);
        offsets.push(offset);
        let step = mean_step(&line.positions_mm);
        let smooth = moving_average(&relative, (WANDER_WINDOW_MM / step).round().max(1.0) as usize);
        let rough_mm: Vec<f64> = relative.iter().zip(&smooth).zip(&predicted).map(|((r, s), p)| (r - s) * p).collect();
        slow.push(Series { values: smooth, step_mm: step });
        fast.push(Series { values: rough_mm, step_mm: step });
    }
    let (wander_sd, rough_sd) = (Series::rms(&slow), Series::rms(&fast));
    Ok(PrinterProfile {
        theta: fitted.theta,
        has_start_blob,
        line_height_sd: rms(&offsets),
        wander: Wander { sd: wander_sd, length_mm: correlation_length(&slow, wander_sd * wander_sd, 1.0) },
        edge: Wander { sd: rough_sd / 2f64.sqrt(), length_mm: correlation_length(&fast, rough_sd * rough_sd, 0.0) },
    })
}

/// One line's residual series, evenly spaced along the path.
struct Series {
    values: Vec<f64>,
    step_mm: f64,
}

impl Series {
    /// The root mean square over every value of every series.
    fn rms(series: &[Series]) -> f64 {
        let (sum, count) = series
            .iter()
            .fold((0.0, 0usize), |(s, n), x| (s + x.values.iter().map(|v| v * v).sum::<f64>(), n + x.values.len()));
        (sum / count.max(1) as f64).sqrt()
    }
}

/// How well a virtual printer calibrated without one line reproduces it.
#[derive(Debug, Clone, PartialEq)]
pub struct HeldOutAgreement {
    /// The held-out line's index.
    pub line: usize,
    /// RMSE of the measured widths against the virtual printer's mean profile (mm).
    pub rmse_mm: f64,
    /// RMS of the virtual printer's own lines around that mean profile (mm): what the
    /// RMSE would be if the real line were one more virtual line.
    pub virtual_scatter_mm: f64,
    /// The virtual mean profile at the measured positions (mm).
    pub mean_mm: Vec<f64>,
    /// The 2.5 % and 97.5 % quantiles of the virtual lines at the measured positions (mm).
    pub band_mm: (Vec<f64>, Vec<f64>),
}

/// For each line: [`calibrate`] on the other lines, print `draws` virtual lines of its
/// kinematics (and the noise-free mean), and compare them with it. The mean profile is
/// the physics without the line's height, wander and roughness.
pub fn held_out_agreement(
    lines: &[MeasuredLine],
    has_start_blob: bool,
    width_cap: bool,
    draws: usize,
    seed: u64,
) -> Result<Vec<HeldOutAgreement>, String> {
    use rayon::prelude::*;
    let v_ref_mm_s = lines.iter().map(|l| l.nominal.peak_speed_mm_s()).fold(0.0, f64::max);
    (0..lines.len())
        .into_par_iter()
        .map(|k| {
            let train: Vec<MeasuredLine> =
                lines.iter().enumerate().filter(|(i, _)| *i != k).map(|(_, l)| l.clone()).collect();
            let profile = calibrate(&train, has_start_blob, width_cap)?;
            let line = &lines[k];
            let at = |printed: &PrintedLine| interpolate(&printed.widths_mm(), &line.positions_mm);
            let quiet = PrinterProfile {
                line_height_sd: 0.0,
                wander: Wander { sd: 0.0, ..profile.wander },
                edge: Wander { sd: 0.0, ..profile.edge },
                ..profile
            };
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            rng.set_stream(k as u64);
            let print = |p: &PrinterProfile, rng: &mut ChaCha8Rng| {
                print_line(p, &Effects::default(), &line.nominal, v_ref_mm_s, rng).map_err(|e| e.to_string())
            };
            let mean_mm = at(&print(&quiet, &mut rng)?);
            let virtual_lines: Vec<Vec<f64>> =
                (0..draws).map(|_| print(&profile, &mut rng).map(|p| at(&p))).collect::<Result<_, _>>()?;
            let scatter =
                virtual_lines.iter().flat_map(|v| v.iter().zip(&mean_mm).map(|(a, b)| a - b)).collect::<Vec<_>>();
            let rmse: Vec<f64> = line.widths_mm.iter().zip(&mean_mm).map(|(a, b)| a - b).collect();
            Ok(HeldOutAgreement {
                line: k,
                rmse_mm: rms(&rmse),
                virtual_scatter_mm: rms(&scatter),
                band_mm: quantile_band(&virtual_lines, mean_mm.len()),
                mean_mm,
            })
        })
        .collect()
}

/// Linear interpolation of a profile on the truth grid at `positions_mm`.
fn interpolate(widths_mm: &[f64], positions_mm: &[f64]) -> Vec<f64> {
    positions_mm
        .iter()
        .map(|&x| {
            let (i, j, f) = truth_grid_weights(widths_mm.len(), x);
            widths_mm[i] + f * (widths_mm[j] - widths_mm[i])
        })
        .collect()
}

/// The 2.5 % and 97.5 % quantiles across `lines` at each of `n` positions.
fn quantile_band(lines: &[Vec<f64>], n: usize) -> (Vec<f64>, Vec<f64>) {
    let mut column = Vec::with_capacity(lines.len());
    let (mut lo, mut hi) = (Vec::with_capacity(n), Vec::with_capacity(n));
    for i in 0..n {
        column.clear();
        column.extend(lines.iter().map(|l| l[i]));
        column.sort_by(f64::total_cmp);
        let q = |p: f64| column[((column.len() - 1) as f64 * p).round() as usize];
        lo.push(if column.is_empty() { f64::NAN } else { q(0.025) });
        hi.push(if column.is_empty() { f64::NAN } else { q(0.975) });
    }
    (lo, hi)
}

fn mean_step(positions_mm: &[f64]) -> f64 {
    (positions_mm[positions_mm.len() - 1] - positions_mm[0]) / (positions_mm.len() - 1) as f64
}

pub(super) fn rms(values: &[f64]) -> f64 {
    (values.iter().map(|v| v * v).sum::<f64>() / values.len().max(1) as f64).sqrt()
}

/// Centred moving average over `window` samples (shrunk at the ends).
fn moving_average(values: &[f64], window: usize) -> Vec<f64> {
    let half = window / 2;
    let mut cumulative = vec![0.0; values.len() + 1];
    for (i, v) in values.iter().enumerate() {
        cumulative[i + 1] = cumulative[i] + v;
    }
    (0..values.len())
        .map(|i| {
            let (lo, hi) = (i.saturating_sub(half), (i + half + 1).min(values.len()));
            (cumulative[hi] - cumulative[lo]) / (hi - lo) as f64
        })
        .collect()
}

/// The OU correlation length of the series: from the autocorrelation at one sample
/// (`from_mm = 0`), or the first lag at which it falls below 1/e, searched from
/// `from_mm` on (half a line at most).
fn correlation_length(series: &[Series], variance: f64, from_mm: f64) -> f64 {
    if variance == 0.0 || series.is_empty() {
        return 1.0;
    }
    let autocorrelation = |lag: usize| {
        let (mut sum, mut count) = (0.0, 0usize);
        for s in series {
            for w in s.values.windows(lag + 1) {
                sum += w[0] * w[lag];
                count += 1;
            }
        }
        sum / count.max(1) as f64 / variance
    };
    let (step, samples) = (series[0].step_mm, series[0].values.len());
    if from_mm == 0.0 {
        let rho = autocorrelation(1).clamp(1e-3, 0.999);
        return -step / rho.ln();
    }
    let first = (from_mm / step).ceil() as usize;
    (first..samples / 2)
        .find(|&lag| autocorrelation(lag) < (-1f64).exp())
        .map_or(samples as f64 * step / 2.0, |lag| lag as f64 * step)
}
