//! What moved in the latest night, against the nights before it.
//!
//! The rules (the defaults of [`Rules`]):
//! - **A number's tolerance band** is the median `m` of its values over the last
//!   `window_nights` nights before the latest, ± `max(k · 1.4826 · MAD, r · |m|, ε)`:
//!   three robust standard deviations where the number varies from night to night
//!   (a seed that moves, a timing), and at least 1 % of its size where it does not (our
//!   runs are deterministic, so most numbers have MAD 0 and any change of a percent is
//!   a change someone made). A number outside its band is a *regression*, unless the
//!   paper gives a value and the number moved towards it (then it is an *improvement*,
//!   listed but not failing the night). Medians and MADs are robust to the one odd
//!   night a mean would follow.
//! - **A verdict** (the discrepancy engine's named cause) that differs from its most
//!   frequent verdict over the window is a regression: the cause a model names is the
//!   result, not a number near it.
//! - **A number that disappears** (present the night before, absent now, its run
//!   complete) or stops being finite is a regression; a **run that fails** is one.
//! - **A stage is slower** when its wall time exceeds its window median by more than
//!   25 %, by more than half a second, and by more than three robust standard
//!   deviations of its own times over the window: below half a second, scheduler
//!   noise on a stage of a few milliseconds would cry wolf every night, and on a
//!   shared machine (a cloud VM) the same binary's stage of a few seconds varies by a
//!   quarter from night to night, which the stage's own spread measures once the
//!   window holds a few nights. With one earlier night that spread is not known yet
//!   and the 25 % alone applies.
//!
//! With no earlier night there is nothing to compare, so nothing is flagged.

use std::collections::BTreeMap;

use crate::history::History;
use crate::{Night, SeriesKey};

/// The tolerances.
#[derive(Debug, Clone, PartialEq)]
pub struct Rules {
    /// Earlier nights a band is drawn from.
    pub window_nights: usize,
    /// Half-width in robust standard deviations (1.4826 · MAD).
    pub mad_k: f64,
    /// Smallest half-width, relative to the median's size.
    pub relative_floor: f64,
    /// Smallest half-width, absolute (for numbers whose median is 0).
    pub absolute_floor: f64,
    /// A stage is slower when its time exceeds this multiple of its median …
    pub slower_ratio: f64,
    /// … and its median by this many seconds.
    pub slower_min_s: f64,
}

impl Default for Rules {
    fn default() -> Self {
        Self {
            window_nights: 7,
            mad_k: 3.0,
            relative_floor: 0.01,
            absolute_floor: 1e-9,
            slower_ratio: 1.25,
            slower_min_s: 0.5,
        }
    }
}

/// A number's band over the window.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Band {
    /// Median of the window.
    pub median: f64,
    /// Half-width.
    pub half_width: f64,
}

impl Band {
    /// Whether `value` lies in the band.
    pub fn contains(&self, value: f64) -> bool {
        (value - self.median).abs() <= self.half_width
    }
}

/// What a finding is about.
#[derive(Debug, Clone, PartialEq)]
pub enum Change {
    /// A number left its band.
    LeftBand {
        /// Tonight's value.
        value: f64,
        /// The band.
        band: Band,
        /// The paper's value, if any.
        paper: Option<f64>,
    },
    /// A verdict changed.
    VerdictChanged {
        /// Tonight's.
        now: String,
        /// The window's most frequent.
        was: String,
    },
    /// A number present the night before is absent or not finite.
    Missing,
    /// A run failed.
    RunFailed {
        /// Its error.
        error: String,
    },
    /// A stage took longer.
    Slower {
        /// Tonight's wall time, s.
        wall_time_s: f64,
        /// The window's median, s.
        median_s: f64,
    },
}

/// One thing that moved.
#[derive(Debug, Clone, PartialEq)]
pub struct Finding {
    /// `run`, `run / stage` or `run / stage / table / metric`.
    pub subject: String,
    /// What moved.
    pub change: Change,
    /// Whether it is a regression (fails `--fail-on-regression`) or an improvement.
    pub regression: bool,
}

/// Everything that moved in the latest night of `history`.
pub fn findings(history: &History, rules: &Rules) -> Vec<Finding> {
    let Some((latest, earlier)) = history.nights.split_last() else {
        return Vec::new();
    };
    let window = &earlier[earlier.len().saturating_sub(rules.window_nights)..];
    let mut found = run_failures(latest);
    if window.is_empty() {
        return found;
    }
    found.extend(number_changes(latest, window, rules));
    found.extend(slower_stages(latest, window, rules));
    found
}

fn run_failures(latest: &Night) -> Vec<Finding> {
    latest
        .runs
        .iter()
        .filter(|r| !r.ok)
        .map(|r| Finding {
            subject: r.run.clone(),
            change: Change::RunFailed { error: r.error.clone() },
            regression: true,
        })
        .collect()
}

/// The band of `values` (finite ones only); `None` when there are none.
pub fn band(values: &[f64], rules: &Rules) -> Option<Band> {
    let finite: Vec<f64> = values.iter().copied().filter(|v| v.is_finite()).collect();
    let centre = median(&finite)?;
    let deviations: Vec<f64> = finite.iter().map(|v| (v - centre).abs()).collect();
    let mad = median(&deviations).unwrap_or(0.0);
    let half_width = (rules.mad_k * 1.4826 * mad).max(rules.relative_floor * centre.abs()).max(rules.absolute_floor);
    Some(Band { median: centre, half_width })
}

/// The median of the finite values ([`models::stats::finite_median`]); `None` when there are none.
fn median(values: &[f64]) -> Option<f64> {
    let median = models::stats::finite_median(values.iter().copied());
    median.is_finite().then_some(median)
}

/// The window's values of every series: numbers and verdicts.
#[derive(Default)]
struct Past {
    values: Vec<f64>,
    verdicts: Vec<String>,
}

fn number_changes(latest: &Night, window: &[Night], rules: &Rules) -> Vec<Finding> {
    let mut past: BTreeMap<SeriesKey, Past> = BTreeMap::new();
    for night in window {
        for n in &night.numbers {
            let slot = past.entry(n.series()).or_default();
            slot.values.extend(n.value);
            slot.verdicts.extend(n.text.clone());
        }
    }
    let tonight: BTreeMap<SeriesKey, &crate::NumberRow> = latest.numbers.iter().map(|n| (n.series(), n)).collect();
    let mut found = Vec::new();
    let previous = window.last().expect("a window has nights");
    let completed = |run: &str| latest.runs.iter().any(|r| r.run == run && r.ok);
    for n in previous.numbers.iter().filter(|n| completed(&n.run)) {
        let key = n.series();
        let absent = match tonight.get(&key) {
            None => true,
            Some(now) => n.value.is_some() && now.value.is_none() || n.text.is_some() && now.text.is_none(),
        };
        if absent {
            found.push(Finding { subject: subject(&key), change: Change::Missing, regression: true });
        }
    }
    for (key, now) in &tonight {
        let Some(was) = past.get(key) else { continue };
        if let (Some(value), Some(band)) = (now.value, band(&was.values, rules)) {
            if !band.contains(value) {
                let towards_paper = now.paper_value.is_some_and(|p| (value - p).abs() < (band.median - p).abs());
                let change = Change::LeftBand { value, band, paper: now.paper_value };
                found.push(Finding { subject: subject(key), change, regression: !towards_paper });
            }
        }
        if let (Some(text), Some(usual)) = (&now.text, most_frequent(&was.verdicts)) {
            if *text != usual {
                let change = Change::VerdictChanged { now: text.clone(), was: usual };
                found.push(Finding { subject: subject(key), change, regression: true });
            }
        }
    }
    found
}

fn most_frequent(texts: &[String]) -> Option<String> {
    let mut counts: BTreeMap<&String, usize> = BTreeMap::new();
    for t in texts {
        *counts.entry(t).or_default() += 1;
    }
    let best = counts.values().copied().max()?;
    // The latest of the most frequent, so a tie follows the recent nights.
    texts.iter().rev().find(|t| counts[t] == best).cloned()
}

fn slower_stages(latest: &Night, window: &[Night], rules: &Rules) -> Vec<Finding> {
    let mut past: BTreeMap<(&str, &str), Vec<f64>> = BTreeMap::new();
    for stage in window.iter().flat_map(|n| &n.stages) {
        past.entry((&stage.run, &stage.stage)).or_default().push(stage.wall_time_s);
    }
    latest
        .stages
        .iter()
        .filter_map(|s| {
            let times = past.get(&(s.run.as_str(), s.stage.as_str()))?;
            let median_s = median(times)?;
            let deviations: Vec<f64> = times.iter().map(|t| (t - median_s).abs()).collect();
            let noise_s = rules.mad_k * 1.4826 * median(&deviations).unwrap_or(0.0);
            let margin_s = ((rules.slower_ratio - 1.0) * median_s).max(rules.slower_min_s).max(noise_s);
            (s.wall_time_s - median_s > margin_s).then(|| Finding {
                subject: format!("{} / {}", s.run, s.stage),
                change: Change::Slower { wall_time_s: s.wall_time_s, median_s },
                regression: true,
            })
        })
        .collect()
}

fn subject(key: &SeriesKey) -> String {
    format!("{} / {} / {} / {}", key.run, key.stage, key.table, key.metric)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::history::tests::night;

    fn history(nights: Vec<Night>) -> History {
        History { nights }
    }

    #[test]
    fn the_band_is_robust_and_never_zero() {
        let rules = Rules::default();
        let b = band(&[1.0, 1.0, 1.0, 1.0, 50.0], &rules).unwrap();
        assert_eq!(b.median, 1.0);
        assert!((b.half_width - 0.01).abs() < 1e-12, "MAD 0 gives the 1 % floor: {b:?}");
        let spread = band(&[1.0, 2.0, 3.0, 4.0, 5.0], &rules).unwrap();
        assert!((spread.half_width - 3.0 * 1.4826 * 1.0).abs() < 1e-12, "{spread:?}");
        assert!(band(&[0.0, 0.0], &rules).unwrap().half_width > 0.0);
        assert_eq!(band(&[f64::NAN], &rules), None);
    }

    #[test]
    fn a_clean_history_has_no_findings() {
        let nights: Vec<Night> = (0..8).map(|d| night(d, 0.12 + 1e-5 * d as f64, 3.0 + 0.1 * (d % 2) as f64)).collect();
        assert_eq!(findings(&history(nights), &Rules::default()), vec![]);
        assert_eq!(
            findings(&history(vec![night(0, 0.12, 3.0)]), &Rules::default()),
            vec![],
            "one night: nothing to compare"
        );
    }

    #[test]
    fn an_injected_regression_is_flagged_and_nothing_else() {
        let mut nights: Vec<Night> = (0..6).map(|d| night(d, 0.12, 3.0)).collect();
        let mut bad = night(6, 0.15, 3.0);
        bad.stages[0].wall_time_s = 4.0;
        bad.numbers[1].text = Some("none".into());
        nights.push(bad);
        let found = findings(&history(nights), &Rules::default());
        let kinds: Vec<&str> = found
            .iter()
            .map(|f| match f.change {
                Change::LeftBand { .. } => "band",
                Change::VerdictChanged { .. } => "verdict",
                Change::Slower { .. } => "slower",
                Change::Missing => "missing",
                Change::RunFailed { .. } => "failed",
            })
            .collect();
        assert_eq!(kinds, ["band", "verdict", "slower"], "{found:#?}");
        assert!(found.iter().all(|f| f.regression));
        assert!(found[0].subject.ends_with("table_ii/rmse"));
    }

    #[test]
    fn a_move_towards_the_paper_is_an_improvement() {
        let mut nights: Vec<Night> = (0..3).map(|d| night(d, 0.12, 3.0)).collect();
        nights.push(night(3, 0.105, 3.0));
        let found = findings(&history(nights), &Rules::default());
        assert_eq!(found.len(), 1, "{found:#?}");
        assert!(!found[0].regression, "0.12 → 0.105 with the paper at 0.1");
    }

    #[test]
    fn a_lost_number_and_a_failed_run_are_regressions() {
        let mut lost = night(1, 0.12, 3.0);
        lost.numbers.remove(0);
        let found = findings(&history(vec![night(0, 0.12, 3.0), lost]), &Rules::default());
        assert!(matches!(found[..], [Finding { change: Change::Missing, regression: true, .. }]), "{found:#?}");
        let mut failed = night(1, 0.12, 3.0);
        failed.runs[0].ok = false;
        failed.runs[0].error = "stage `loo` failed".into();
        failed.numbers.clear();
        failed.stages.clear();
        let found = findings(&history(vec![night(0, 0.12, 3.0), failed]), &Rules::default());
        assert!(
            matches!(found[..], [Finding { change: Change::RunFailed { .. }, .. }]),
            "one finding, not every number: {found:#?}"
        );
    }

    #[test]
    fn a_stage_is_slower_only_beyond_its_own_spread() {
        let at = |times: &[f64], tonight: f64| {
            let mut nights: Vec<Night> = times.iter().enumerate().map(|(d, &t)| night(d as i64, 0.12, t)).collect();
            nights.push(night(times.len() as i64, 0.12, tonight));
            findings(&history(nights), &Rules::default())
        };
        // A steady 5 s stage: 30 % slower is a regression.
        assert!(matches!(at(&[5.0, 5.0, 5.0], 6.5)[..], [Finding { change: Change::Slower { .. }, .. }]));
        // The same 30 % on a stage that varies by a second (robust SD 1.48 s) is noise;
        // twice its median is not.
        assert_eq!(at(&[4.0, 5.0, 6.0, 4.0, 5.0, 6.0, 5.0], 6.5), vec![]);
        assert!(matches!(at(&[4.0, 5.0, 6.0, 4.0, 5.0, 6.0, 5.0], 10.0)[..], [Finding { .. }]));
    }

    #[test]
    fn a_tiny_stage_is_not_slower_by_noise() {
        let mut nights: Vec<Night> = (0..4).map(|d| night(d, 0.12, 0.01)).collect();
        nights.push(night(4, 0.12, 0.05));
        assert_eq!(findings(&history(nights), &Rules::default()), vec![], "5× slower but 40 ms");
    }
}
