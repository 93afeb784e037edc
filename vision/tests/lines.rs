//! Accuracy of `vision::lines` on photos from the virtual camera (`tests/support`), with
//! the true width w_l + w_r known at every position, and its behaviour on hostile input.
//!
//! The lines follow paper 000's single-line photos (Sec. III): 120 mm, 0.8 mm mean width
//! with a 1.3 mm start blob, a 0.05 mm / 10 mm ripple and a slow trend, rough edges,
//! rotated by −3°, 0° or +2.5°, metadata 6 px and 0.5° off, uneven lighting, vignetting,
//! bed texture, 1.5 % noise, bright and dark lines, 8- and 16-bit PNGs.

mod support;

use rayon::prelude::*;
use support::Scene;
use vision::lines::{segment_edge_fit, segment_threshold_columns, GrayImage, LineError, Segmentation, DEFAULT_STEP_MM};

/// RMSE and bias (mm) of a segmentation against the scene's true widths.
#[derive(Debug, Clone, Copy)]
struct Accuracy {
    rmse_mm: f64,
    bias_mm: f64,
    measured: usize,
    skipped: usize,
}

fn accuracy(scene: &Scene, seg: &Segmentation) -> Accuracy {
    let errors: Vec<f64> =
        seg.positions_mm.iter().zip(&seg.widths_mm).map(|(&s, &w)| w - scene.profile.width_mm(s)).collect();
    let n = errors.len() as f64;
    let bias_mm = errors.iter().sum::<f64>() / n;
    let rmse_mm = (errors.iter().map(|e| e * e).sum::<f64>() / n).sqrt();
    Accuracy { rmse_mm, bias_mm, measured: errors.len(), skipped: seg.skipped.len() }
}

/// The twelve test lines at one scale: 3 angles × bright/dark × 8/16 bit.
fn scenes(px_per_mm: f64) -> Vec<Scene> {
    let mut out = Vec::new();
    for (a, angle_deg) in [-3.0, 0.0, 2.5].into_iter().enumerate() {
        for (p, dark) in [false, true].into_iter().enumerate() {
            for (b, bits) in [8u8, 16].into_iter().enumerate() {
                let seed = 100 * px_per_mm as u64 + (a * 4 + p * 2 + b) as u64;
                out.push(Scene::paper000(px_per_mm, angle_deg, dark, bits, seed));
            }
        }
    }
    out
}

/// Both methods on every line at one scale; prints a table and returns (fit, baseline).
fn evaluate(px_per_mm: f64) -> Vec<(String, Accuracy, Accuracy)> {
    let rows: Vec<_> = scenes(px_per_mm)
        .par_iter()
        .map(|scene| {
            let img = scene.render();
            let geom = scene.nominal_geometry();
            let fit = segment_edge_fit(&img, &geom, DEFAULT_STEP_MM).expect("edge fit");
            let baseline = segment_threshold_columns(&img, &geom, DEFAULT_STEP_MM).expect("baseline");
            assert_eq!(fit.axis, baseline.axis, "both methods share the axis");
            let name = format!(
                "{:>4.1}° {} {:>2}-bit σ={}",
                scene.angle_rad.to_degrees(),
                if scene.contrast < 0.0 { "dark  " } else { "bright" },
                scene.bits,
                scene.sigma_psf_px
            );
            (name, accuracy(scene, &fit), accuracy(scene, &baseline))
        })
        .collect();
    for (name, fit, base) in &rows {
        eprintln!(
            "{px_per_mm:>4} px/mm {name}: edge fit RMSE {:.4} bias {:+.4} ({} measured, {} skipped) | \
             Otsu RMSE {:.4} bias {:+.4}",
            fit.rmse_mm, fit.bias_mm, fit.measured, fit.skipped, base.rmse_mm, base.bias_mm
        );
    }
    let worst = |f: fn(&(String, Accuracy, Accuracy)) -> f64| rows.iter().map(f).fold(0.0, f64::max);
    eprintln!(
        "{px_per_mm:>4} px/mm worst: edge fit RMSE {:.4} |bias| {:.4}; Otsu RMSE {:.4} |bias| {:.4}",
        worst(|r| r.1.rmse_mm),
        worst(|r| r.1.bias_mm.abs()),
        worst(|r| r.2.rmse_mm),
        worst(|r| r.2.bias_mm.abs())
    );
    rows
}

/// Asserts the bounds on every line, and that the baseline is worse than the edge fit.
fn assert_bounds(px_per_mm: f64, rmse_max_mm: f64, bias_max_mm: f64) {
    let positions = (120.0 / DEFAULT_STEP_MM) as usize + 1;
    for (name, fit, base) in evaluate(px_per_mm) {
        assert!(fit.rmse_mm <= rmse_max_mm, "{name}: RMSE {} > {rmse_max_mm}", fit.rmse_mm);
        assert!(fit.bias_mm.abs() <= bias_max_mm, "{name}: bias {} beyond ±{bias_max_mm}", fit.bias_mm);
        // Only the end blur may be skipped: a handful of positions at each end.
        assert!(fit.measured + 20 >= positions, "{name}: only {} of {positions} measured", fit.measured);
        assert!(base.rmse_mm > fit.rmse_mm, "{name}: Otsu RMSE {} not worse than {}", base.rmse_mm, fit.rmse_mm);
    }
}

/// The brief's target; measured worst RMSE 0.0065 mm, |bias| 0.0003 mm.
#[test]
fn edge_fit_is_within_0_01_mm_rmse_and_0_005_mm_bias_at_40_px_per_mm() {
    assert_bounds(40.0, 0.01, 0.005);
}

/// Measured worst of the 12 lines: RMSE 0.013 mm, |bias| 0.0011 mm (the bed texture's
/// error in px stays, each px is twice as wide); bounds with about 50 % slack.
#[test]
fn edge_fit_at_20_px_per_mm() {
    assert_bounds(20.0, 0.02, 0.005);
}

/// Measured worst: RMSE 0.023 mm, |bias| 0.004 mm.
#[test]
fn edge_fit_at_10_px_per_mm() {
    assert_bounds(10.0, 0.035, 0.01);
}

fn small_scene() -> Scene {
    Scene::paper000(10.0, 1.0, false, 8, 7)
}

#[test]
fn truncated_png_is_unreadable() {
    let png = small_scene().render_png();
    for cut in [0, 10, 40, png.len() / 3, png.len() - 13] {
        let err = GrayImage::from_png_bytes(&png[..cut], 1 << 24).unwrap_err();
        assert!(matches!(err, LineError::Unreadable(_)), "cut {cut}: {err:?}");
    }
}

#[test]
fn bed_without_a_line_is_no_line() {
    let scene = Scene { with_line: false, ..small_scene() };
    let img = scene.render();
    for result in [
        segment_edge_fit(&img, &scene.nominal_geometry(), 0.05),
        segment_threshold_columns(&img, &scene.nominal_geometry(), 0.05),
    ] {
        let err = result.unwrap_err();
        assert!(matches!(err, LineError::NoLine { .. }), "{err:?}");
        assert!(err.to_string().contains("no line found"), "{err}");
    }
}

#[test]
fn a_line_running_out_of_the_frame_leaves_the_frame() {
    // The frame is cut 15 mm before the line's end.
    let full = small_scene();
    let scene = Scene { width_px: full.width_px - 150, ..full };
    let err = segment_edge_fit(&scene.render(), &scene.nominal_geometry(), 0.05).unwrap_err();
    assert!(matches!(err, LineError::LeavesFrame { .. }), "{err:?}");
    assert!(err.to_string().contains("leaves the frame"), "{err}");
}

#[test]
fn a_scale_twice_wrong_either_way_is_an_error() {
    let scene = Scene::paper000(20.0, 1.0, true, 16, 3);
    let img = scene.render();
    for factor in [0.5, 2.0] {
        let geom = vision::lines::LineGeometry { px_per_mm: 20.0 * factor, ..scene.nominal_geometry() };
        let err = segment_edge_fit(&img, &geom, 0.05).unwrap_err();
        assert!(
            matches!(
                err,
                LineError::LengthMismatch { .. } | LineError::LeavesFrame { .. } | LineError::WidthMismatch { .. }
            ),
            "px/mm × {factor}: {err:?}"
        );
        assert!(err.to_string().contains("px_per_mm"), "the message names the suspect: {err}");
    }
}

#[test]
fn tiny_and_empty_images_are_errors() {
    let geom = small_scene().nominal_geometry();
    for (w, h) in [(0, 0), (1, 1), (3, 2), (7, 100)] {
        let img = GrayImage { width: w, height: h, pixels: vec![0.5; w * h] };
        assert!(matches!(segment_edge_fit(&img, &geom, 0.05), Err(LineError::BadImage { .. })), "{w}×{h}");
        assert!(matches!(segment_threshold_columns(&img, &geom, 0.05), Err(LineError::BadImage { .. })));
    }
    let lying = GrayImage { width: 100, height: 100, pixels: vec![0.5; 10] };
    assert!(matches!(segment_edge_fit(&lying, &geom, 0.05), Err(LineError::BadImage { .. })));
    let one_px = {
        let mut png = Vec::new();
        kornia_io::png::encode_image_png_gray16_slice(
            &[7],
            kornia_image::ImageSize { width: 1, height: 1 },
            &mut png,
            None,
        )
        .unwrap();
        GrayImage::from_png_bytes(&png, 10).unwrap()
    };
    assert!(matches!(segment_edge_fit(&one_px, &geom, 0.05), Err(LineError::BadImage { .. })));
}

#[test]
fn bad_geometry_and_step_are_errors() {
    let scene = small_scene();
    let img = GrayImage { width: 50, height: 50, pixels: vec![0.5; 2500] };
    let geom = scene.nominal_geometry();
    for step in [0.0, -1.0, f64::NAN, 1e-9] {
        assert!(matches!(segment_edge_fit(&img, &geom, step), Err(LineError::BadGeometry(_))), "step {step}");
    }
    for bad in [
        vision::lines::LineGeometry { px_per_mm: 0.0, ..geom },
        vision::lines::LineGeometry { length_mm: f64::INFINITY, ..geom },
        vision::lines::LineGeometry { start_px: [f64::NAN, 0.0], ..geom },
        vision::lines::LineGeometry { nominal_width_mm: 0.01, ..geom },
    ] {
        assert!(matches!(segment_edge_fit(&img, &bad, 0.05), Err(LineError::BadGeometry(_))), "{bad:?}");
    }
}

#[test]
fn widths_do_not_depend_on_the_number_of_threads() {
    // Positions are fitted in fixed chunks, each from its own start: the same numbers on
    // one thread as on several.
    let scene = Scene::paper000(20.0, -3.0, true, 8, 21);
    let (img, geom) = (scene.render(), scene.nominal_geometry());
    let run = |threads| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| segment_edge_fit(&img, &geom, DEFAULT_STEP_MM).unwrap())
    };
    let one = run(1);
    assert_eq!(one, run(3));
    assert!(one.widths_mm.len() > 2300);
}
