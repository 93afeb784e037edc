//! Telling apart poses that the pattern's geometry leaves equally good. A frame with
//! evenly spaced lines looks the same turned by 180°, yet the print is not symmetric: the
//! bead's width changes where the G-code changes speed (the melt's lag, paper 000), and
//! those places are not symmetric along a line. Under each pose every line's width proxy
//! (the material across a window, integrated) is read along the line, and its change over
//! 1 mm at the G-code's speed changes is compared with its change elsewhere; the pose under
//! which more lines show their changes where the G-code puts them wins, by a two-sided sign
//! test over the lines at level [`SIGN_TEST_ALPHA`]; if it is not significant the choice is
//! reported as ambiguous.

use rayon::prelude::*;

use super::contrast::ColourAxis;
use super::{Calibration, ColourImage, PrintedPath};

/// Level of the sign test over lines.
pub const SIGN_TEST_ALPHA: f64 = 0.01;
/// Spacing of the width proxy along a line (mm).
const STEP_MM: f64 = 0.1;
/// Distance over which a change is measured (mm).
const CHANGE_SPAN_MM: f64 = 0.5;
/// How far from a commanded speed change its signature is looked for (mm).
const SEARCH_MM: f64 = 1.0;

/// How the orientation was chosen.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Choice {
    /// One pose fitted clearly best; nothing to choose.
    Only,
    /// Chosen by the print: `lines_for` lines favoured it, `lines_against` the runner-up.
    ByPrint {
        /// Lines favouring the chosen pose.
        lines_for: usize,
        /// Lines favouring the runner-up.
        lines_against: usize,
        /// Two-sided sign-test p-value.
        p_value: f64,
    },
    /// The print does not tell the poses apart at the test's level: the chosen pose is
    /// the one more lines favour, which may be wrong.
    Ambiguous {
        /// Lines favouring the chosen pose.
        lines_for: usize,
        /// Lines favouring the runner-up.
        lines_against: usize,
        /// Two-sided sign-test p-value.
        p_value: f64,
    },
}

/// The pose among `tied` that the print favours; `None` if `tied` is empty.
pub fn choose(img: &ColourImage, paths: &[PrintedPath], mut tied: Vec<Calibration>) -> Option<Calibration> {
    if tied.len() <= 1 {
        return tied.pop();
    }
    let signatures: Vec<Vec<Option<f64>>> = tied.iter().map(|c| signatures(img, paths, c)).collect();
    // the pose with the most line-by-line wins over all others, then the sign test
    // against its strongest rival
    let wins = |a: usize, b: usize| {
        signatures[a].iter().zip(&signatures[b]).filter(|(x, y)| matches!((x, y), (Some(x), Some(y)) if x > y)).count()
    };
    let best =
        (0..tied.len()).max_by_key(|&a| (0..tied.len()).filter(|&b| b != a).map(|b| wins(a, b)).sum::<usize>())?;
    let rival = (0..tied.len()).filter(|&b| b != best).max_by_key(|&b| wins(b, best))?;
    let (lines_for, lines_against) = (wins(best, rival), wins(rival, best));
    let p_value = sign_test(lines_for, lines_against);
    let choice = if p_value < SIGN_TEST_ALPHA {
        Choice::ByPrint { lines_for, lines_against, p_value }
    } else {
        Choice::Ambiguous { lines_for, lines_against, p_value }
    };
    let mut chosen = tied.swap_remove(best);
    chosen.orientation = choice;
    Some(chosen)
}

/// Per path: how much more the width proxy changes at the commanded speed changes than
/// elsewhere; `None` for a path without speed changes or outside the photo.
fn signatures(img: &ColourImage, paths: &[PrintedPath], cal: &Calibration) -> Vec<Option<f64>> {
    paths.par_iter().map(|p| signature(img, p, cal)).collect()
}

fn signature(img: &ColourImage, path: &PrintedPath, cal: &Calibration) -> Option<f64> {
    let length = path.length_mm();
    let changes: Vec<f64> = path
        .speed_changes_mm
        .iter()
        .copied()
        .filter(|&c| c > SEARCH_MM + CHANGE_SPAN_MM && c < length - SEARCH_MM - CHANGE_SPAN_MM)
        .collect();
    if changes.is_empty() {
        return None;
    }
    let n = (length / STEP_MM).floor() as usize;
    let proxy: Vec<Option<f64>> =
        (0..=n).map(|k| width_proxy(img, &cal.contrast_axis, cal, path, k as f64 * STEP_MM)).collect();
    let span = (CHANGE_SPAN_MM / STEP_MM).round() as usize;
    let change: Vec<Option<f64>> = (0..=n)
        .map(|k| match (k.checked_sub(span).and_then(|a| proxy[a]), proxy.get(k + span).copied().flatten()) {
            (Some(a), Some(b)) => Some((b - a).abs()),
            _ => None,
        })
        .collect();
    let mut all: Vec<f64> = change.iter().flatten().copied().collect();
    if all.len() < 10 {
        return None;
    }
    all.sort_by(f64::total_cmp);
    let typical = all[all.len() / 2];
    let at_changes: f64 = changes
        .iter()
        .map(|&c| {
            let (a, b) = (((c - SEARCH_MM) / STEP_MM).floor() as usize, ((c + SEARCH_MM) / STEP_MM).ceil() as usize);
            change[a..=b.min(n)].iter().flatten().copied().fold(0.0, f64::max)
        })
        .sum::<f64>()
        / changes.len() as f64;
    Some(at_changes - typical)
}

/// Material across the path at `s_mm` (mm of contrast-weighted width) within its commanded
/// width on each side.
fn width_proxy(img: &ColourImage, axis: &ColourAxis, cal: &Calibration, path: &PrintedPath, s_mm: f64) -> Option<f64> {
    let half = path.width_mm.max(0.3);
    let dt = 0.05;
    let mut sum = 0.0;
    let mut t = -half;
    let path_axis = path.axis();
    while t <= half {
        let p = cal.camera.project(path_axis.point(s_mm, t))?;
        let (i, j) = (p[0].floor(), p[1].floor());
        if i < 0.0 || j < 0.0 || i as usize >= img.width || j as usize >= img.height {
            return None;
        }
        sum += axis.value(img.at(i as usize, j as usize)).clamp(0.0, 1.2) * dt;
        t += dt;
    }
    Some(sum)
}

/// Two-sided exact sign test of `a` successes against `b` (ties left out).
pub fn sign_test(a: usize, b: usize) -> f64 {
    let n = a + b;
    if n == 0 {
        return 1.0;
    }
    let k = a.max(b);
    // P(X ≥ k) for X ~ Bin(n, ½), in log space
    let ln_half_n = n as f64 * 0.5f64.ln();
    let mut ln_choose = 0.0;
    let mut tail = 0.0;
    for i in 0..=n {
        if i > 0 {
            ln_choose += ((n - i + 1) as f64).ln() - (i as f64).ln();
        }
        if i >= k {
            tail += (ln_choose + ln_half_n).exp();
        }
    }
    (2.0 * tail).min(1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sign_test_matches_the_binomial() {
        // 10 of 10: 2 · 2⁻¹⁰
        assert!((sign_test(10, 0) - 2.0 / 1024.0).abs() < 1e-12);
        // 5 of 10: the whole distribution
        assert_eq!(sign_test(5, 5), 1.0);
        // 8 of 10: 2 · (45 + 10 + 1) / 1024
        assert!((sign_test(2, 8) - 112.0 / 1024.0).abs() < 1e-12);
        assert_eq!(sign_test(0, 0), 1.0);
    }
}
