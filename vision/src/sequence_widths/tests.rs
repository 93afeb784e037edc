//! The width reading on synthetic frames of a straight Gaussian bead, whose width at
//! any threshold is known in closed form.

use super::*;
use crate::synth::HotPolyline;

const BACKGROUND_C: f64 = 60.0;
const BEAD_C: f64 = 200.0;
const SIGMA_MM: f64 = 0.3;
/// 0.1 mm per pixel, the plane origin at pixel (40, 40).
const PLANE_TO_PX: Homography = Homography { m: [[10.0, 0.0, 40.0], [0.0, 10.0, 40.0], [0.0, 0.0, 1.0]] };

/// An 81 × 81 px frame of a bead along y = 0 whose centre is `bead_c` hot.
fn bead_frame(bead_c: f64) -> ThermalFrame {
    let bead = HotPolyline {
        vertices_mm: vec![[-4.0, 0.0], [4.0, 0.0]],
        background_c: BACKGROUND_C,
        bead_c,
        bead_sigma_mm: SIGMA_MM,
        corner_excess_c: 0.0,
        corner_sigma_mm: 1.0,
    };
    let mut frame = ThermalFrame::filled(81, 81, 0.0);
    for v in 0..81 {
        for u in 0..81 {
            let p = [(u as f64 - 40.0) / 10.0, (v as f64 - 40.0) / 10.0];
            frame.temp_c[v * 81 + u] = bead.temp_c(p) as f32;
        }
    }
    frame
}

/// The full width of the Gaussian bead at `threshold_c`: 2σ·√(2 ln(ΔT_bead/ΔT_t)).
fn closed_form_width_mm(threshold_c: f64) -> f64 {
    2.0 * SIGMA_MM * (2.0 * ((BEAD_C - BACKGROUND_C) / (threshold_c - BACKGROUND_C)).ln()).sqrt()
}

/// Samples along the bead at x = −1..1 mm, left direction +y, at t = 0, 0.01, … s.
fn queries() -> (Vec<f64>, Vec<WidthQuery>) {
    let xs: Vec<f64> = (0..21).map(|k| -1.0 + 0.1 * k as f64).collect();
    let t_s = (0..xs.len()).map(|k| 0.01 * k as f64).collect();
    (t_s, xs.iter().map(|&x| WidthQuery { p_mm: [x, 0.0], n_left: [0.0, 1.0] }).collect())
}

fn reading(threshold: Threshold) -> Reading {
    Reading { measure_age_s: 0.1, frame_period_s: 0.125, widths: WidthParams::with_threshold(0.0), threshold }
}

#[test]
fn a_sample_is_read_in_the_frame_of_its_layer_nearest_the_measuring_age() {
    let (t_s, queries) = queries();
    let straight = vec![true; t_s.len()];
    let widths =
        SequenceWidths { t_s: &t_s, queries: &queries, straight: &straight, reading: reading(Threshold::Fixed(100.0)) };
    let view = |layer, t: Option<f64>| FrameView { layer, placed: t.map(|t| (t, &PLANE_TO_PX)), image: None };
    // Frames of layer 0 at 0.1 s and 0.2 s, an unplaced one, and one of layer 1 at 0.15 s.
    let frames = [view(0, Some(0.1)), view(0, None), view(0, Some(0.2)), view(1, Some(0.15))];
    let owner = widths.frame_of_samples(&frames, 0);
    // Sample k (t = 0.01 k) is 0.1 s old at 0.1 + 0.01 k: frame 0 up to k = 5 (a tie at
    // k = 5 goes to the earlier frame), frame 2 from k = 6 to k = 16, none after (more
    // than half a period, 0.0625 s, from 0.2 s).
    for (k, o) in owner.iter().enumerate() {
        let expected = match k {
            0..=5 => Some(0),
            6..=16 => Some(2),
            _ => None,
        };
        assert_eq!(*o, expected, "sample {k}");
    }
    assert!(widths.frame_of_samples(&frames, 1)[..11].iter().all(|o| *o == Some(3)));
}

#[test]
fn the_widths_at_a_fixed_threshold_are_the_contour_s() {
    let (t_s, queries) = queries();
    let straight = vec![true; t_s.len()];
    let widths =
        SequenceWidths { t_s: &t_s, queries: &queries, straight: &straight, reading: reading(Threshold::Fixed(120.0)) };
    let image = bead_frame(BEAD_C);
    let frames = [FrameView { layer: 0, placed: Some((0.15, &PLANE_TO_PX)), image: Some(&image) }];
    let layers = widths.layers(&frames);
    assert_eq!(layers.len(), 1);
    let expected = closed_form_width_mm(120.0);
    // The frame at 0.15 s holds samples up to 0.0625 s from 0.1 s old: k = 0..=11.
    assert_eq!(layers[0].owner.iter().filter(|o| o.is_some()).count(), 12);
    for m in layers[0].measured.iter().take(12) {
        assert!((m.left_mm + m.right_mm - expected).abs() < 0.01, "{m:?} against {expected}");
        assert!((m.left_mm - m.right_mm).abs() < 1e-6, "a symmetric bead: {m:?}");
        assert!((m.temp_c - BEAD_C).abs() < 0.5, "{m:?}");
    }
}

#[test]
fn the_calibrated_threshold_gives_the_nominal_width_on_the_straight_samples() {
    let (t_s, queries) = queries();
    // Samples 0-6 are read in the frame at 0.1 s (6 is a tie, which goes to the earlier
    // frame), 0-5 of them straight; samples 7-18 are read in a hotter frame (its bead
    // wider at any threshold) and must not move the calibration.
    let straight: Vec<bool> = (0..t_s.len()).map(|k| k <= 5).collect();
    let nominal_width_mm = 0.45;
    let threshold = Threshold::Calibrated { low_c: BACKGROUND_C + 1.0, high_c: 230.0, nominal_width_mm };
    let widths = SequenceWidths { t_s: &t_s, queries: &queries, straight: &straight, reading: reading(threshold) };
    let (cool, hot) = (bead_frame(BEAD_C), bead_frame(BEAD_C + 60.0));
    let frames = [
        FrameView { layer: 0, placed: Some((0.1, &PLANE_TO_PX)), image: Some(&cool) },
        FrameView { layer: 0, placed: Some((0.22, &PLANE_TO_PX)), image: Some(&hot) },
    ];
    let layer = &widths.layers(&frames)[0];
    // Closed form: T_t = T_bg + ΔT_bead · exp(−(w/2)² / 2σ²).
    let expected_c =
        BACKGROUND_C + (BEAD_C - BACKGROUND_C) * (-(nominal_width_mm / 2.0).powi(2) / (2.0 * SIGMA_MM.powi(2))).exp();
    assert!((layer.threshold_c - expected_c).abs() < 1.0, "{} against {expected_c}", layer.threshold_c);
    let straight_widths = layer.measured[..=5].iter().map(|m| m.left_mm + m.right_mm);
    assert!((finite_median(straight_widths) - nominal_width_mm).abs() < 0.005);
    assert!(layer.measured[7..=18].iter().all(|m| m.left_mm + m.right_mm > nominal_width_mm + 0.05), "hot frame wider");
}

#[test]
fn nothing_placed_reads_nothing_and_an_unreadable_threshold_counts_as_too_high() {
    let (t_s, queries) = queries();
    let straight = vec![true; t_s.len()];
    let threshold = Threshold::Calibrated { low_c: 61.0, high_c: 230.0, nominal_width_mm: 0.45 };
    let widths = SequenceWidths { t_s: &t_s, queries: &queries, straight: &straight, reading: reading(threshold) };
    let frames = [FrameView { layer: 1, placed: None, image: None }];
    let layers = widths.layers(&frames);
    assert_eq!(layers.len(), 2, "layers 0 to the largest");
    for layer in &layers {
        assert!(layer.owner.iter().all(Option::is_none));
        assert!(layer.measured.iter().all(|m| m.left_mm.is_nan() && m.temp_c.is_nan()));
        // No width at any threshold: every bisection step goes down.
        assert!((layer.threshold_c - 61.0).abs() < 1e-6, "{}", layer.threshold_c);
    }
}
