use super::super::planner::PressureAdvance;
use super::super::pressure_advance::deposit_line;
use super::super::synthetic::{pressure_advance_pattern as pattern, pressure_advance_widths as measure};
use super::*;

const ADVANCES: [f64; 11] = [0.0, 0.01, 0.02, 0.03, 0.04, 0.05, 0.06, 0.07, 0.08, 0.09, 0.1];

#[test]
fn recovers_the_lag_and_recommends_it_as_the_advance() {
    let lines = pattern(&ADVANCES, 0.04);
    let tau = 0.045;
    let measured = measure(&lines, tau, 0.01, 7);
    let fit = tune(&lines, &measured, &TuningSettings::default()).unwrap();
    assert_eq!(fit.status, TauStatus::Fitted);
    assert!((fit.tau_s - tau).abs() < 0.05 * tau, "τ {}", fit.tau_s);
    assert!(fit.tau_ci_s.0 < tau && tau < fit.tau_ci_s.1, "{:?}", fit.tau_ci_s);
    // with Klipper's smoothing the flattest advance is close to τ, not equal
    assert!((fit.recommended_pa_s - tau).abs() < 0.1 * tau, "K {}", fit.recommended_pa_s);
    assert!(fit.pa_ci_s.0 < fit.recommended_pa_s && fit.recommended_pa_s < fit.pa_ci_s.1);
    // the held-out lines are predicted to about their noise
    assert!(fit.heldout_rmse_mm < 1.5 * 0.01, "held out {}", fit.heldout_rmse_mm);
    assert!((fit.noise_mm - 0.01).abs() < 0.003, "noise {}", fit.noise_mm);
    // the flattest printed line is the one nearest τ
    assert!((fit.flattest_line_advance_s - 0.05).abs() < 0.011, "{}", fit.flattest_line_advance_s);
    for (i, f) in fit.lines.iter().enumerate() {
        assert!((f.level - (1.25 + 0.02 * (i % 5) as f64)).abs() < 0.01, "line {i} level {}", f.level);
    }
}

#[test]
fn without_smoothing_the_flattest_advance_is_tau() {
    // W = E' + (K − τ)·u' and E' is the commanded width: K = τ makes it exactly flat.
    let lines = pattern(&[0.0, 0.05], 0.0);
    let refs: Vec<&PrintedLine> = lines.iter().collect();
    let settings = TuningSettings { smoothing_mm: 0.0, ..TuningSettings::default() };
    for tau in [0.01, 0.04, 0.2] {
        let k = flattest_advance(&refs, tau, &settings);
        assert!((k - tau).abs() < 1e-9, "{tau}: {k}");
    }
}

#[test]
fn the_parts_give_the_deposit_under_any_advance() {
    let lines = pattern(&[0.03], 0.04);
    let tau = 0.05;
    let settings = DepositSettings { smoothing_mm: 0.0, ..DepositSettings::for_line(&lines[0], tau) };
    let parts = deposit_parts(&lines[0], &settings);
    for k in [0.0, 0.03, 0.1] {
        let pa = PressureAdvance { advance_s: k, ..lines[0].pressure_advance };
        let direct = deposit_line(&lines[0], &DepositSettings { pressure_advance: pa, ..settings });
        for (j, w) in direct.flow_widths_mm.iter().enumerate() {
            assert!((parts.width_mm(j, k, tau) - w).abs() < 1e-9, "K {k} at {j}");
        }
    }
}

#[test]
fn a_lag_beyond_the_range_is_reported_at_its_bound() {
    let lines = pattern(&ADVANCES[..4], 0.04);
    let measured = measure(&lines, 0.08, 0.005, 3);
    let settings = TuningSettings { tau_range_s: (0.002, 0.02), ..TuningSettings::default() };
    let fit = tune(&lines, &measured, &settings).unwrap();
    assert_eq!(fit.status, TauStatus::AtBound);
    assert!((fit.tau_s - 0.02).abs() < 1e-12);
}

#[test]
fn refuses_one_line_and_unknown_lines() {
    let lines = pattern(&ADVANCES[..3], 0.04);
    let mut measured = measure(&lines, 0.04, 0.01, 1);
    measured[1].series = vec![vec![]];
    measured[2].series.clear();
    assert_eq!(tune(&lines, &measured, &TuningSettings::default()), Err(TuningError::TooFewLines(1)));
    let wrong = vec![MeasuredLine { line: 9, series: vec![vec![(1.0, 1.0)]] }];
    assert_eq!(tune(&lines, &wrong, &TuningSettings::default()), Err(TuningError::UnknownLine { line: 9, lines: 3 }));
}

#[test]
fn the_golden_section_finds_a_minimum_on_a_staircase() {
    // a parabola plus steps of 0.01 every 0.025: (x − 0.3)² + 0.01·⌊40x⌋ is least just
    // below the step at 0.125 (0.0306 + 0.04), found to the tolerance
    let f = |x: f64| (x - 0.3).powi(2) + 0.01 * (x * 40.0).floor();
    let x = golden_minimum(f, 0.0, 1.0, 1e-6);
    assert!(x < 0.125 && x > 0.125 - 2e-6, "{x}");
    let smooth = golden_minimum(|x: f64| (x - 0.3).powi(2), 0.0, 1.0, 1e-9);
    assert!((smooth - 0.3).abs() < 1e-8);
}
