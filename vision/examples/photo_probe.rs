//! Calibrates and measures every photo of an `fdm-photos` dataset and prints a summary per
//! photo and line, writing an overlay of the measured edges next to each photo in
//! `OUT_DIR` (default /tmp): a developer's probe of `vision::photo`, outside the pipeline.
//!
//! `cargo run --release -p vision --example photo_probe -- DATASET_DIR [OUT_DIR]`

use std::time::Instant;

use vision::photo::{calibrate, measure::measure_paths, ColourImage, PrintedPath};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let dir = std::path::Path::new(args.get(1).ok_or("usage: photo_probe DATASET_DIR [OUT_DIR]")?);
    let out = std::path::PathBuf::from(args.get(2).map_or("/tmp", |s| s.as_str()));
    let data = datasets::fdm_photos::FdmPhotos::read(dir)?;
    let paths: Vec<PrintedPath> = data.lines.iter().map(PrintedPath::from_line).collect();
    for photo in &data.photos {
        let t0 = Instant::now();
        let img = ColourImage::decode(&std::fs::read(&photo.image)?, 64 << 20)?;
        let t_decode = t0.elapsed();
        let cal = calibrate(&img, &paths, false)?;
        let t_cal = t0.elapsed();
        let contrast = cal.contrast_axis.apply(&img);
        let measured = measure_paths(&contrast, &paths, &cal.camera, 0.05);
        // the photographer's mask, if given as MASK_DIR/<photo file stem>_mask.png
        if let Ok(mask_dir) = std::env::var("MASK_DIR") {
            let stem = photo.image.file_stem().and_then(|s| s.to_str()).unwrap_or("");
            let mask = ColourImage::decode(&std::fs::read(format!("{mask_dir}/{stem}_mask.png"))?, 64 << 20)?;
            let mask = vision::lines::GrayImage {
                width: mask.width,
                height: mask.height,
                pixels: mask.pixels.iter().map(|p| p[0]).collect(),
            };
            let reference = measure_paths(&mask, &paths, &cal.camera, 0.05);
            let fast = |m: &vision::photo::measure::PathMeasurement, p: &PrintedPath, threshold: bool| -> f64 {
                let (a, b) = (
                    p.speed_changes_mm.first().copied().unwrap_or(0.0) + 1.0,
                    p.speed_changes_mm.get(1).copied().unwrap_or(0.0) - 1.0,
                );
                let mut w: Vec<f64> = m
                    .samples
                    .iter()
                    .filter(|s| s.position_mm >= a && s.position_mm <= b && s.width_mm > 0.0)
                    .map(|s| if threshold { s.threshold_width_mm } else { s.width_mm })
                    .collect();
                w.sort_by(f64::total_cmp);
                w.get(w.len() / 2).copied().unwrap_or(f64::NAN)
            };
            for (i, p) in paths.iter().enumerate().filter(|(_, p)| p.speed_changes_mm.len() >= 2) {
                let (ours, base, refw) =
                    (fast(&measured[i], p, false), fast(&measured[i], p, true), fast(&reference[i], p, true));
                println!(
                    "FAST {} line {i}: edge-fit {ours:.3} threshold {base:.3} mask {refw:.3} diff {:+.3}",
                    photo.photo_id,
                    ours - refw
                );
            }
        }
        println!(
            "{}: decode {:?} calibrate {:?} measure {:?}; coarse {:.3}; k1 {:.4} k2 {:.4}; orientation {:?}; separation {:.1}",
            photo.photo_id, t_decode, t_cal - t_decode, t0.elapsed() - t_cal, cal.coarse_score, cal.camera.k1, cal.camera.k2, cal.orientation, cal.contrast_axis.separation
        );
        for l in &cal.levels {
            println!(
                "  level sigma {:.2} correlation {:.4} points {} it {}",
                l.sigma_mm, l.correlation, l.points, l.iterations
            );
        }
        let mut overlay = image::RgbImage::from_fn(img.width as u32, img.height as u32, |i, j| {
            image::Rgb(img.at(i as usize, j as usize).map(|v| (v * 255.0) as u8))
        });
        for (i, (m, p)) in measured.iter().zip(&paths).enumerate() {
            let beads: Vec<f64> = m.samples.iter().filter(|s| s.width_mm > 0.0).map(|s| s.width_mm).collect();
            let gaps = m.samples.len() - beads.len();
            let mut sorted = beads.clone();
            sorted.sort_by(f64::total_cmp);
            let median = sorted.get(sorted.len() / 2).copied().unwrap_or(f64::NAN);
            let mut reasons: Vec<String> = m.skipped.iter().map(|(_, s)| s.reason()).collect();
            reasons.sort();
            reasons.dedup();
            println!(
                "  line {i:2}: beads {:4} gaps {:3} skipped {:4} median {:.3} {:?}",
                beads.len(),
                gaps,
                m.skipped.len(),
                median,
                reasons
            );
            for s in &m.samples {
                for (t, colour) in [(s.left_mm, [255, 0, 0]), (-s.right_mm, [0, 255, 0])] {
                    if t.is_finite() {
                        if let Some(q) = cal.camera.project(p.point(s.position_mm, t)) {
                            if q[0] >= 0.0
                                && q[1] >= 0.0
                                && (q[0] as u32) < overlay.width()
                                && (q[1] as u32) < overlay.height()
                            {
                                overlay.put_pixel(q[0] as u32, q[1] as u32, image::Rgb(colour));
                            }
                        }
                    }
                }
                if s.width_mm == 0.0 {
                    if let Some(q) = cal.camera.project(p.point(s.position_mm, 0.0)) {
                        if q[0] >= 0.0
                            && q[1] >= 0.0
                            && (q[0] as u32) < overlay.width()
                            && (q[1] as u32) < overlay.height()
                        {
                            overlay.put_pixel(q[0] as u32, q[1] as u32, image::Rgb([0, 128, 255]));
                        }
                    }
                }
            }
        }
        overlay.save(out.join(format!("overlay_{}.png", photo.photo_id)))?;
    }
    Ok(())
}
