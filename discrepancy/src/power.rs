//! Scoring a power study (DESIGN §7), the same for every domain: a draw hides one
//! effect (or none) in data whose truth the study knows, the engine names what it
//! finds, and the draw is *correct* when it names the injected mechanism and nothing
//! else, *wrong* when it names anything else, *none* when it names nothing. Per
//! (effect, strength) cell the rates carry Clopper–Pearson intervals, and the correct
//! draws' strength intervals are checked against the injected strength.

use crate::engine::Discovery;
use crate::stats::clopper_pearson;

/// What a power study keeps of one draw's discovery against its `target` (the injected
/// mechanism, `None` for a null draw or an effect no candidate describes).
#[derive(Debug, Clone, PartialEq)]
pub struct DrawVerdict {
    /// The verdict.
    pub outcome: Outcome,
    /// When correct: the target's first fitted parameter with its interval.
    pub fitted: Option<(f64, f64, f64)>,
    /// Each of the `candidates` candidates' raw first-round p-value (NaN: not scored).
    pub first_round_p: Vec<f64>,
}

impl DrawVerdict {
    /// Scores `found` against `target`.
    pub fn of<F>(found: &Discovery<F>, target: Option<usize>, candidates: usize) -> Self {
        let outcome = Outcome::of(&found.named, target);
        let fitted = (outcome == Outcome::Correct)
            .then(|| found.extension.iter().find(|e| e.mechanism == target).map(|e| (e.estimate, e.ci_lo, e.ci_hi)))
            .flatten();
        let mut first_round_p = vec![f64::NAN; candidates];
        if let Some(round) = found.rounds.first() {
            for c in &round.candidates {
                first_round_p[c.mechanism] = c.p_value;
            }
        }
        Self { outcome, fitted, first_round_p }
    }
}

/// How one draw came out.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    /// The injected mechanism and nothing else was named.
    Correct,
    /// Something other than the injected mechanism was named.
    Wrong,
    /// Nothing was named.
    None,
}

impl Outcome {
    /// The outcome of a draw that named `named` when `target` was injected (`None`:
    /// nothing injected, or an effect no candidate describes).
    pub fn of(named: &[usize], target: Option<usize>) -> Self {
        match (named.is_empty(), target) {
            (true, _) => Self::None,
            (false, Some(t)) if named.iter().all(|&n| n == t) => Self::Correct,
            _ => Self::Wrong,
        }
    }

    /// The outcome labelled `label` ([`Outcome::label`]).
    pub fn parse(label: &str) -> Option<Self> {
        [Self::Correct, Self::Wrong, Self::None].into_iter().find(|o| o.label() == label)
    }

    /// `correct`, `wrong` or `none`.
    pub fn label(self) -> &'static str {
        match self {
            Self::Correct => "correct",
            Self::Wrong => "wrong",
            Self::None => "none",
        }
    }
}

/// What the summary needs of one draw.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DrawScore {
    /// The effect's name (`none` for a null draw).
    pub effect: &'static str,
    /// The cell's strength.
    pub strength: f64,
    /// The verdict against the truth.
    pub outcome: Outcome,
    /// For a correct draw with a strength interval: whether it covers the truth.
    pub covered: Option<bool>,
}

/// One row of a power table.
#[derive(Debug, Clone, PartialEq)]
pub struct PowerRow {
    /// The effect (`none` for the null).
    pub effect: &'static str,
    /// Its strength.
    pub strength: f64,
    /// Draws.
    pub draws: usize,
    /// Draws that named the injected mechanism only.
    pub correct: usize,
    /// Draws that named something else.
    pub wrong: usize,
    /// Draws that named nothing.
    pub none: usize,
    /// `correct / draws` with its Clopper–Pearson 95 % interval.
    pub correct_rate: (f64, f64, f64),
    /// `wrong / draws` with its Clopper–Pearson 95 % interval (for the null: any cause).
    pub false_alarm_rate: (f64, f64, f64),
    /// Correct draws whose strength interval covers the truth, of those with one.
    pub covered: (usize, usize),
}

impl PowerRow {
    /// The coverage rate with its Clopper–Pearson 95 % interval (NaN without intervals).
    pub fn coverage_rate(&self) -> (f64, f64, f64) {
        let (covered, with) = self.covered;
        let (lo, hi) = clopper_pearson(covered, with, 0.95);
        (if with > 0 { covered as f64 / with as f64 } else { f64::NAN }, lo, hi)
    }
}

/// The draws summarised per (effect, strength), in the order first seen.
pub fn summarize(draws: &[DrawScore]) -> Vec<PowerRow> {
    let mut cells: Vec<(&'static str, f64)> = Vec::new();
    for d in draws {
        if !cells.iter().any(|c| c.0 == d.effect && c.1 == d.strength) {
            cells.push((d.effect, d.strength));
        }
    }
    cells
        .into_iter()
        .map(|(effect, strength)| {
            let cell: Vec<&DrawScore> = draws.iter().filter(|d| d.effect == effect && d.strength == strength).collect();
            let count = |o: Outcome| cell.iter().filter(|d| d.outcome == o).count();
            let n = cell.len();
            let rate = |k: usize| {
                let (lo, hi) = clopper_pearson(k, n, 0.95);
                (k as f64 / n.max(1) as f64, lo, hi)
            };
            let intervals: Vec<bool> = cell.iter().filter_map(|d| d.covered).collect();
            let (correct, wrong, none) = (count(Outcome::Correct), count(Outcome::Wrong), count(Outcome::None));
            PowerRow {
                effect,
                strength,
                draws: n,
                correct,
                wrong,
                none,
                correct_rate: rate(correct),
                false_alarm_rate: rate(wrong),
                covered: (intervals.iter().filter(|&&c| c).count(), intervals.len()),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outcomes_and_counts() {
        assert_eq!(Outcome::of(&[], Some(1)), Outcome::None);
        assert_eq!(Outcome::of(&[1], Some(1)), Outcome::Correct);
        assert_eq!(Outcome::of(&[1, 2], Some(1)), Outcome::Wrong);
        assert_eq!(Outcome::of(&[0], None), Outcome::Wrong);
        let d = |effect, outcome, covered| DrawScore { effect, strength: 0.1, outcome, covered };
        let rows = summarize(&[
            d("a", Outcome::Correct, Some(true)),
            d("a", Outcome::Correct, Some(false)),
            d("a", Outcome::None, None),
            d("b", Outcome::Wrong, None),
        ]);
        assert_eq!(rows.len(), 2);
        assert_eq!((rows[0].draws, rows[0].correct, rows[0].none, rows[0].covered), (3, 2, 1, (1, 2)));
        assert_eq!(rows[1].false_alarm_rate.0, 1.0);
        assert_eq!(rows[0].coverage_rate().0, 0.5);
    }
}
