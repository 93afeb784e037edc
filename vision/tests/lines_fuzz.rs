//! Bounded, reproducible fuzzing of `vision::lines` on stable Rust: random bytes and valid
//! gray PNGs with 1-4 byte splices (headers claiming other or huge sizes, bit depths,
//! colour types; truncated and corrupt data) must decode to an image or a `LineError`,
//! never panic or allocate from a lying header; whatever decodes is then segmented with
//! both methods, which must also return a result or an error. Random geometries on a real
//! line photo must do the same.

mod mutate;

use proptest::prelude::*;
use vision::lines::{segment_edge_fit, segment_threshold_columns, GrayImage, LineGeometry};

/// Cases per test: well under a second each in release.
const CASES: u32 = 2000;
/// Pixel limit of the decoder in these tests.
const MAX_PIXELS: usize = 1 << 16;

/// A 64 × 24 8-bit photo of a bright bar and a 16-bit 5 × 4 one, as PNG bytes.
fn seeds() -> Vec<Vec<u8>> {
    let size = kornia_image::ImageSize { width: 64, height: 24 };
    let bar: Vec<u8> = (0..64 * 24).map(|k| if (9..15).contains(&(k / 64)) { 200 } else { 40 }).collect();
    let mut png8 = Vec::new();
    kornia_io::png::encode_image_png_gray8(&kornia_image::Image::new(size, bar).unwrap(), &mut png8, None).unwrap();
    let mut png16 = Vec::new();
    let size = kornia_image::ImageSize { width: 5, height: 4 };
    kornia_io::png::encode_image_png_gray16_slice(&[9000; 20], size, &mut png16, None).unwrap();
    vec![png8, png16]
}

/// The bar of `seeds()[0]` read at 4 px/mm: 14 mm of a 1.5 mm (6 px) wide line along row 12.
fn bar_geometry() -> LineGeometry {
    LineGeometry { start_px: [4.0, 12.0], direction_rad: 0.0, length_mm: 14.0, px_per_mm: 4.0, nominal_width_mm: 1.5 }
}

#[test]
fn decoding_and_segmenting_never_panic_on_mutated_or_random_bytes() {
    let png = prop_oneof![4 => mutate::spliced(seeds()), 1 => prop::collection::vec(any::<u8>(), 0..300)];
    mutate::runner(CASES)
        .run(&png, |bytes| {
            if let Ok(img) = GrayImage::from_png_bytes(&bytes, MAX_PIXELS) {
                prop_assert_eq!(img.pixels.len(), img.width * img.height);
                prop_assert!(img.width * img.height <= MAX_PIXELS);
                let _ = segment_edge_fit(&img, &bar_geometry(), 0.25);
                let _ = segment_threshold_columns(&img, &bar_geometry(), 0.25);
            }
            Ok(())
        })
        .unwrap();
}

#[test]
fn random_geometries_never_panic() {
    let img = GrayImage::from_png_bytes(&seeds()[0], MAX_PIXELS).unwrap();
    let number = prop_oneof![4 => -100.0f64..100.0, 1 => any::<f64>()];
    let strategy = (prop::collection::vec(number, 6), prop_oneof![3 => 0.01f64..2.0, 1 => any::<f64>()]);
    mutate::runner(CASES)
        .run(&strategy, |(g, step_mm)| {
            let geom = LineGeometry {
                start_px: [g[0], g[1]],
                direction_rad: g[2],
                length_mm: g[3].abs(),
                px_per_mm: g[4].abs(),
                nominal_width_mm: g[5].abs() * 0.05,
            };
            if let Ok(seg) = segment_edge_fit(&img, &geom, step_mm) {
                prop_assert_eq!(seg.positions_mm.len(), seg.widths_mm.len());
                prop_assert!(seg.widths_mm.iter().all(|w| w.is_finite() && *w > 0.0));
            }
            let _ = segment_threshold_columns(&img, &geom, step_mm);
            Ok(())
        })
        .unwrap();
}
