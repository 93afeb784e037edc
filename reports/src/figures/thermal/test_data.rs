//! Synthetic tables in the schemas the paper 003 stages (`thermal.monitor`,
//! `thermal.compensate`, `thermal.reprint`, `thermal.accuracy`) publish, for the figure
//! and section tests. The geometry is the corner test path of `models::thermal::setup`
//! (a 37 mm base, four teeth of apex 120°, 90°, 60°, 45°), rebuilt here because
//! `reports` reads artifacts only; the numbers are shaped like the paper's (corner
//! over-deposition, a hot spot at each corner), not simulated.

use std::path::Path;

use polars::df;
use polars::prelude::DataFrame;

use tables::thermal::{
    accuracy, compensation, contour, contour_points, contour_regions, corners, deposit_regions, detections_example,
    directions, frame_example, frame_example_meta, frames, mosaic, path, spans, widths,
};

use crate::figures::test_util::{declared, noise, write_declared};

/// Nominal half width w0 (mm): half of the 0.45 mm bead.
pub const W0_MM: f64 = 0.225;
/// Programmed feed (mm/s).
const FEED_MM_S: f64 = 20.0;
/// The vertices whose corners are compensated: the four tooth apexes.
pub const APEXES: [usize; 4] = [3, 5, 7, 9];

/// The corner test path: eleven vertices, counter-clockwise, closed.
pub fn corner_path() -> Vec<(f64, f64)> {
    let halves: Vec<f64> = [120.0_f64, 90.0, 60.0, 45.0].iter().map(|d| 5.0 * (d.to_radians() / 2.0).tan()).collect();
    let width: f64 = 2.0 * halves.iter().sum::<f64>();
    let mut v = vec![(0.0, 0.0), (width, 0.0), (width, 8.0)];
    let mut x = width;
    for h in &halves {
        v.push((x - h, 13.0));
        x -= 2.0 * h;
        v.push((x, 8.0));
    }
    v
}

/// Distance from `p` to the closed polygon and the distance to its nearest vertex.
fn distances(poly: &[(f64, f64)], p: (f64, f64)) -> (f64, f64) {
    let n = poly.len();
    let to_edge = (0..n).map(|i| segment_distance(poly[i], poly[(i + 1) % n], p)).fold(f64::INFINITY, f64::min);
    let to_vertex = poly.iter().map(|v| (v.0 - p.0).hypot(v.1 - p.1)).fold(f64::INFINITY, f64::min);
    (to_edge, to_vertex)
}

fn segment_distance(a: (f64, f64), b: (f64, f64), p: (f64, f64)) -> f64 {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let t = (((p.0 - a.0) * dx + (p.1 - a.1) * dy) / (dx * dx + dy * dy)).clamp(0.0, 1.0);
    (a.0 + t * dx - p.0).hypot(a.1 + t * dy - p.1)
}

/// One trajectory sample.
#[derive(Debug, Clone, Copy)]
pub struct Sample {
    /// Time (s).
    pub t_s: f64,
    /// Position (mm).
    pub xy: (f64, f64),
    /// Unit left normal of the path.
    pub normal: (f64, f64),
    /// Distance to the nearest vertex (mm).
    pub to_vertex_mm: f64,
    /// Speed (mm/s): the feed, slowed to a fifth at the vertices.
    pub speed_mm_s: f64,
}

/// Samples every 0.02 mm along the path, slowing near each vertex.
pub fn samples(poly: &[(f64, f64)]) -> Vec<Sample> {
    let step = 0.02;
    let mut out = Vec::new();
    let mut t_s = 0.0;
    for i in 0..poly.len() {
        let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
        let len = (b.0 - a.0).hypot(b.1 - a.1);
        let tangent = ((b.0 - a.0) / len, (b.1 - a.1) / len);
        for k in 0..(len / step) as usize {
            let s = k as f64 * step;
            let to_vertex_mm = s.min(len - s);
            let speed_mm_s = FEED_MM_S * (to_vertex_mm / 1.0).clamp(0.2, 1.0);
            let xy = (a.0 + s * tangent.0, a.1 + s * tangent.1);
            out.push(Sample { t_s, xy, normal: (-tangent.1, tangent.0), to_vertex_mm, speed_mm_s });
            t_s += step / speed_mm_s;
        }
    }
    out
}

/// The model half widths: wider on the left near a vertex.
fn half_widths(s: &Sample) -> (f64, f64) {
    let bulge = (-s.to_vertex_mm / 0.3).exp();
    (W0_MM * (1.0 + 0.8 * bulge), W0_MM * (1.0 + 0.2 * bulge))
}

/// `directions.parquet`: the deposition direction turns towards the corner bisector
/// within 0.3 mm of a vertex (DDA); without DDA the half widths are NaN within 0.15 mm.
pub fn directions(poly: &[(f64, f64)]) -> DataFrame {
    let s = samples(poly);
    let n = s.len();
    let col = |f: &dyn Fn(&Sample) -> f64| -> Vec<f64> { s.iter().map(f).collect() };
    let dep = |x: &Sample| {
        let turn = 0.6 * (-x.to_vertex_mm / 0.3).exp();
        let (c, si) = (turn.cos(), turn.sin());
        (c * x.normal.0 - si * x.normal.1, si * x.normal.0 + c * x.normal.1)
    };
    let no_dda = |x: &Sample, left: bool| {
        let (l, r) = half_widths(x);
        if x.to_vertex_mm < 0.15 {
            f64::NAN
        } else if left {
            l
        } else {
            r
        }
    };
    declared(
        &directions::TABLE,
        df!(
            directions::sample => (0..n as i32).collect::<Vec<i32>>(),
            directions::t_s => col(&|x| x.t_s), directions::x_mm => col(&|x| x.xy.0), directions::y_mm => col(&|x| x.xy.1),
            directions::speed_mm_s => col(&|x| x.speed_mm_s),
            directions::kappa_per_mm => col(&|x| (-x.to_vertex_mm / 0.05).exp() * 20.0),
            directions::kappa_eff_per_mm => col(&|x| (-x.to_vertex_mm / 0.3).exp() * 2.0),
            directions::psi_rad => col(&|x| 0.6 * (-x.to_vertex_mm / 0.3).exp()),
            directions::slender_before => col(&|x| 2.0 * (-x.to_vertex_mm / 0.1).exp()),
            directions::slender_after => col(&|x| 0.9 * (-x.to_vertex_mm / 0.1).exp()),
            directions::normal_x => col(&|x| x.normal.0), directions::normal_y => col(&|x| x.normal.1),
            directions::dep_x => col(&|x| dep(x).0), directions::dep_y => col(&|x| dep(x).1),
            directions::w_left_mm => col(&|x| half_widths(x).0), directions::w_right_mm => col(&|x| half_widths(x).1),
            directions::w_left_no_dda_mm => col(&|x| no_dda(x, true)), directions::w_right_no_dda_mm => col(&|x| no_dda(x, false))
        )
        .expect("frame"),
    )
}

/// `path.parquet`.
pub fn path_table(poly: &[(f64, f64)]) -> DataFrame {
    df!(
        path::vertex => (0..poly.len() as i32).collect::<Vec<i32>>(),
        path::x_mm => poly.iter().map(|p| p.0).collect::<Vec<f64>>(),
        path::y_mm => poly.iter().map(|p| p.1).collect::<Vec<f64>>()
    )
    .expect("frame")
}

/// Interior angle at vertex `k` (degrees).
pub fn angle_deg(poly: &[(f64, f64)], k: usize) -> f64 {
    let n = poly.len();
    let (p, a, q) = (poly[(k + n - 1) % n], poly[k], poly[(k + 1) % n]);
    let (u, v) = ((p.0 - a.0, p.1 - a.1), (q.0 - a.0, q.1 - a.1));
    ((u.0 * v.0 + u.1 * v.1) / (u.0.hypot(u.1) * v.0.hypot(v.1))).acos().to_degrees()
}

/// Writes every `thermal.monitor` table into `dir`.
pub fn write_monitor(dir: &Path) {
    let poly = corner_path();
    let (frame, detections, meta) = frame_example();
    for (table, df) in [
        (&directions::TABLE, directions(&poly)),
        (&frames::TABLE, frames()),
        (&frame_example::TABLE, frame),
        (&detections_example::TABLE, detections),
        (&frame_example_meta::TABLE, meta),
        (&mosaic::TABLE, mosaic(&poly)),
        (&widths::TABLE, widths(&poly)),
    ] {
        write_declared(dir, table, df);
    }
}

/// `frames.parquet`: 40 frames of two layers, every fifth skipped.
pub fn frames() -> DataFrame {
    let n = 40;
    // Frames 0 and 1 show no corner: placed by their recorded time for widths, not used;
    // the last was filmed after the layer's last move: parked.
    let used: Vec<bool> = (0..n).map(|i| i % 5 != 4 && i >= 2).collect();
    let placed_by: Vec<&str> = (0..n)
        .map(|i| match (i < 2, i == n - 1, used[i]) {
            (true, _, _) => "recorded_time",
            (_, true, _) => "parked",
            (false, false, true) => "corners",
            (false, false, false) => "",
        })
        .collect();
    let reason: Vec<String> = (0..n)
        .map(|i| match (used[i], i < 2, i % 10) {
            (true, _, _) => String::new(),
            (false, true, _) => "rigid mount: no corner pairs; placed by its recorded time, for its widths only".into(),
            _ if i == n - 1 => "filmed after the layer's last move: placed, but not timed".into(),
            (false, false, 4) => format!("same image as frame {}: a repeated or frozen camera frame", i - 1),
            (false, false, _) => "fewer than 4 corners".into(),
        })
        .collect();
    let recorded: Vec<f64> = (0..n).map(|i| 0.125 * i as f64).collect();
    let estimated: Vec<f64> = (0..n)
        .map(|i| if placed_by[i] == "corners" { recorded[i] + 0.004 * noise(i) - 0.003 } else { f64::NAN })
        .collect();
    declared(
        &frames::TABLE,
        df!(
            frames::layer => (0..n).map(|i| (i / 20) as i32).collect::<Vec<i32>>(),
            frames::frame => (0..n as i32).collect::<Vec<i32>>(),
            frames::recorded_time_s => recorded, frames::estimated_time_s => estimated,
            frames::corners_found => (0..n).map(|i| if used[i] { 5 } else { 2 }).collect::<Vec<i32>>(),
            frames::corners_matched => (0..n).map(|i| if used[i] { 4 } else { 1 }).collect::<Vec<i32>>(),
            frames::reproj_err_mm => (0..n).map(|i| if used[i] { 0.03 + 0.01 * noise(i) } else { f64::NAN }).collect::<Vec<f64>>(),
            frames::used => used, frames::placed_by => placed_by, frames::skip_reason => reason,
            frames::repeat_of_frame => (0..n).map(|i| if i % 10 == 4 { i as i64 - 1 } else { -1 }).collect::<Vec<i64>>()
        )
        .expect("frame"),
    )
}

/// `frame_example.parquet` (160 × 120 px: a hot V-shaped track below the nozzle),
/// `detections_example.parquet` and `frame_example_meta.parquet`.
pub fn frame_example() -> (DataFrame, DataFrame, DataFrame) {
    let track = [(20.0, 100.0), (60.0, 40.0), (100.0, 100.0), (140.0, 40.0)];
    let (mut u, mut v, mut temp) = (vec![], vec![], vec![]);
    for row in 0..120_i32 {
        for col in 0..160_i32 {
            let p = (col as f64, row as f64);
            let d = (0..3).map(|i| segment_distance(track[i], track[i + 1], p)).fold(f64::INFINITY, f64::min);
            let corner = track.iter().map(|c| (c.0 - p.0).hypot(c.1 - p.1)).fold(f64::INFINITY, f64::min);
            u.push(col);
            v.push(row);
            temp.push(
                45.0 + 110.0 * (-d / 6.0).exp()
                    + 30.0 * (-corner / 8.0).exp()
                    + 0.2 * noise((row * 160 + col) as usize),
            );
        }
    }
    let frame = declared(
        &frame_example::TABLE,
        df!(frame_example::u_px => u, frame_example::v_px => v, frame_example::temp_c => temp).expect("frame"),
    );
    let detections = declared(
        &detections_example::TABLE,
        df!(
        detections_example::u_px => [60.0, 100.0, 140.0, 20.0, 80.0], detections_example::v_px => [40.0, 100.0, 40.0, 100.0, 70.0],
        detections_example::temp_c => [182.0, 181.0, 179.0, 178.0, 120.0], detections_example::matched_vertex => [7i32, 6, 5, 8, -1]
        )
        .expect("frame"),
    );
    let meta = declared(
        &frame_example_meta::TABLE,
        df!(frame_example_meta::layer => [0i32], frame_example_meta::frame => [12i32], frame_example_meta::nozzle_u_px => [140.0], frame_example_meta::nozzle_v_px => [40.0]).expect("frame"),
    );
    (frame, detections, meta)
}

/// `mosaic.parquet`: a 0.1 mm grid around the path, hot along it (hotter at the
/// vertices), cells below y = 3 mm never seen by the camera (absent).
pub fn mosaic(poly: &[(f64, f64)]) -> DataFrame {
    let (mut x, mut y, mut temp) = (vec![], vec![], vec![]);
    for j in 30..150 {
        for i in -10..385 {
            let p = (i as f64 * 0.1, j as f64 * 0.1);
            let (d, dv) = distances(poly, p);
            x.push(p.0);
            y.push(p.1);
            temp.push(50.0 + 100.0 * (-d / 0.4).exp() + 40.0 * (-dv / 0.6).exp() - 20.0 * p.0 / 38.0);
        }
    }
    declared(&mosaic::TABLE, df!(mosaic::x_mm => x, mosaic::y_mm => y, mosaic::temp_c => temp).expect("frame"))
}

/// `widths.parquet`: two layers of measured half widths (NaN where not measured).
pub fn widths(poly: &[(f64, f64)]) -> DataFrame {
    let s = samples(poly);
    let (mut layer, mut sample, mut t, mut x, mut y, mut temp) = (vec![], vec![], vec![], vec![], vec![], vec![]);
    let (mut wl, mut wr, mut wd, mut dw, mut frame) = (vec![], vec![], vec![], vec![], vec![]);
    let duration = s.last().map_or(1.0, |x| x.t_s);
    for lay in 0..2 {
        for (i, q) in s.iter().enumerate() {
            let bulge = (-q.to_vertex_mm / 0.25).exp();
            let measured = i % 97 != 0;
            let (l, r) = if measured {
                (W0_MM * (1.0 + 1.2 * bulge) + 0.01 * noise(i), W0_MM * (1.0 + 0.6 * bulge) + 0.01 * noise(i + 7))
            } else {
                (f64::NAN, f64::NAN)
            };
            let desired = W0_MM * (1.0 + 0.15 * bulge);
            layer.push(lay);
            sample.push(i as i32);
            t.push(q.t_s + lay as f64 * duration);
            x.push(q.xy.0);
            y.push(q.xy.1);
            temp.push(120.0 + 30.0 * bulge + 2.0 * noise(i + 3));
            wl.push(l);
            wr.push(r);
            wd.push(desired);
            dw.push(l + r - 2.0 * desired);
            frame.push((q.t_s / 0.125) as i32);
        }
    }
    declared(
        &widths::TABLE,
        df!(
            widths::layer => layer, widths::sample => sample, widths::t_s => t, widths::x_mm => x, widths::y_mm => y,
            widths::temp_c => temp, widths::w_left_mm => wl, widths::w_right_mm => wr, widths::w_desired_mm => wd,
            widths::dw_mm => dw, widths::frame_index => frame
        )
        .expect("frame"),
    )
}

/// The time at which the path passes vertex `k` (the first sample within 0.02 mm).
pub fn vertex_time_s(poly: &[(f64, f64)], k: usize) -> f64 {
    let v = poly[k];
    samples(poly).iter().find(|s| (s.xy.0 - v.0).hypot(s.xy.1 - v.1) < 0.021).map_or(0.0, |s| s.t_s)
}

/// Writes `spans.parquet` and `compensation.parquet` for the four apexes.
pub fn write_compensate(dir: &Path) {
    let poly = corner_path();
    let (mut span, mut vertex, mut angle, mut t0, mut t1, mut e0, mut e1) =
        (vec![], vec![], vec![], vec![], vec![], vec![], vec![]);
    let (mut temp, mut gain, mut max_dw) = (vec![], vec![], vec![]);
    let (mut c_span, mut c_vertex, mut c_t, mut c_dw) = (vec![], vec![], vec![], vec![]);
    let (mut c_measured, mut c_wanted) = (Vec::new(), Vec::new());
    let (mut desired, mut output, mut input) = (vec![], vec![], vec![]);
    for (k, &apex) in APEXES.iter().enumerate() {
        let tc = vertex_time_s(&poly, apex);
        let corner_temp = 145.0 + 2.0 * k as f64;
        let ke = 1.0 + (150.0 - corner_temp) / 15.0;
        span.push(k as i32);
        vertex.push(apex as i32);
        angle.push(angle_deg(&poly, apex));
        t0.push(tc - 0.08);
        t1.push(tc + 0.08);
        e0.push(tc - 0.18);
        e1.push(tc + 0.18);
        temp.push(corner_temp);
        gain.push(ke);
        max_dw.push(0.3);
        let mut lagged = 0.0;
        for j in 0..=360 {
            let t = tc - 0.18 + 0.001 * j as f64;
            let dw_mm = 0.3 * (-((t - tc) / 0.05).powi(2)).exp();
            let want = ke * 20.0 * dw_mm;
            let command = (ke * 20.0 * 0.3 * (-((t - tc + 0.06) / 0.05).powi(2)).exp()).clamp(-2.0, 4.0);
            // The first-order lag of eq. 34 (τ = 0.0873 s), explicit Euler at 1 ms.
            lagged += (command - lagged) * 0.001 / 0.0873;
            c_span.push(k as i32);
            c_vertex.push(apex as i32);
            c_t.push(t);
            c_dw.push(dw_mm);
            c_measured.push(0.45 + dw_mm);
            c_wanted.push(0.45);
            desired.push(want);
            input.push(command);
            output.push(lagged);
        }
    }
    let spans = df!(
        spans::span => span, spans::vertex => vertex, spans::angle_deg => angle, spans::t_start_s => t0, spans::t_end_s => t1,
        spans::t_ext_start_s => e0, spans::t_ext_end_s => e1, spans::corner_temp_c => temp, spans::gain_ke => gain,
        spans::max_dw_mm => max_dw
    )
    .expect("frame");
    let comp = df!(
        compensation::span => c_span, compensation::vertex => c_vertex, compensation::t_s => c_t, compensation::dw_mm => c_dw, compensation::w_measured_mm => c_measured,
        compensation::w_desired_mm => c_wanted, compensation::dv_desired_mm_s => desired, compensation::dv_output_mm_s => output, compensation::dv_input_mm_s => input
    )
    .expect("frame");
    write_declared(dir, &spans::TABLE, declared(&spans::TABLE, spans));
    write_declared(dir, &compensation::TABLE, declared(&compensation::TABLE, comp));
}

/// Writes every `thermal.reprint` table into `dir`.
pub fn write_reprint(dir: &Path) {
    let poly = corner_path();
    write_declared(dir, &path::TABLE, declared(&path::TABLE, path_table(&poly)));
    write_declared(dir, &corners::TABLE, declared(&corners::TABLE, corners(&poly)));
    let contour_summary = df!(
        contour::variant => ["conventional", "compensated"], contour::max_mm => [1.52, 0.27], contour::rms_mm => [0.41, 0.19]
    )
    .expect("frame");
    write_declared(dir, &contour::TABLE, declared(&contour::TABLE, contour_summary));
    write_declared(dir, &contour_points::TABLE, declared(&contour_points::TABLE, contour_points(&poly)));
    write_declared(dir, &deposit_regions::TABLE, declared(&deposit_regions::TABLE, deposit_regions(&poly)));
    write_declared(dir, &contour_regions::TABLE, declared(&contour_regions::TABLE, contour_regions(&poly)));
}

/// `contour_regions.parquet`: one row per vertex (even vertices apexes, odd ones valleys),
/// then the seam and the straight runs; the largest error at the first valley before
/// compensation (a bulge) and at the first apex after (short).
pub fn contour_regions(poly: &[(f64, f64)]) -> DataFrame {
    let n = poly.len();
    let mut kind: Vec<&str> = (0..n).map(|k| if k % 2 == 0 { "apex" } else { "valley" }).collect();
    kind.extend(["seam", "straight"]);
    let mut region = vec!["corner"; n];
    region.extend(["seam", "straight"]);
    let mut corner: Vec<i64> = (0..n as i64).collect();
    corner.extend([-1, -1]);
    let mut angle: Vec<f64> = (0..n).map(|k| angle_deg(poly, k)).collect();
    angle.extend([f64::NAN, f64::NAN]);
    let rows = n + 2;
    let max_before: Vec<f64> = (0..rows).map(|k| if k == 1 { 1.52 } else { 0.5 + 0.1 * noise(k) }).collect();
    let max_after: Vec<f64> = (0..rows).map(|k| if k == 0 { 0.27 } else { 0.1 + 0.05 * noise(k + 7) }).collect();
    df!(
        contour_regions::region => region, contour_regions::corner => corner, contour_regions::angle_deg => angle, contour_regions::kind => kind,
        contour_regions::points => vec![100i64; rows],
        contour_regions::max_before_mm => max_before, contour_regions::max_after_mm => max_after,
        contour_regions::max_before_short => (0..rows).map(|k| k % 2 == 0).collect::<Vec<bool>>(),
        contour_regions::max_after_short => (0..rows).map(|k| k % 2 == 0).collect::<Vec<bool>>(),
        contour_regions::rms_before_mm => vec![0.41; rows], contour_regions::rms_after_mm => vec![0.19; rows],
        contour_regions::sq_share_before => vec![1.0 / rows as f64; rows], contour_regions::sq_share_after => vec![1.0 / rows as f64; rows]
    )
    .expect("frame")
}

/// `corners.parquet` for every vertex: O_E falls from about 100 % to about 30 %.
pub fn corners(poly: &[(f64, f64)]) -> DataFrame {
    let n = poly.len();
    let angle: Vec<f64> = (0..n).map(|k| angle_deg(poly, k)).collect();
    let a_c: Vec<f64> = angle.iter().map(|a| 0.2 / (a.to_radians() / 2.0).tan()).collect();
    let before: Vec<f64> = (0..n).map(|k| 100.0 + 10.0 * noise(k)).collect();
    let after: Vec<f64> = (0..n).map(|k| 30.0 + 10.0 * noise(k + 50)).collect();
    df!(
        corners::corner => (0..n as i32).collect::<Vec<i32>>(), corners::angle_deg => angle,
        corners::oe_before_pct => before.clone(), corners::oe_after_pct => after.clone(),
        corners::a_c_mm2 => a_c.clone(),
        corners::a_o_before_mm2 => a_c.iter().zip(&before).map(|(a, o)| a * o / 100.0).collect::<Vec<f64>>(),
        corners::a_o_after_mm2 => a_c.iter().zip(&after).map(|(a, o)| a * o / 100.0).collect::<Vec<f64>>()
    )
    .expect("frame")
}

/// `contour_points.parquet`: every 0.1 mm of the CAD contour, three layers, the error
/// peaking at the vertices (more so for the conventional print, most in layer 1).
pub fn contour_points(poly: &[(f64, f64)]) -> DataFrame {
    let (mut variant, mut layer, mut x, mut y, mut err) = (vec![], vec![], vec![], vec![], vec![]);
    for (name, peak) in [("conventional", 1.4), ("compensated", 0.2)] {
        for lay in 0..3 {
            for (i, s) in samples(poly).iter().enumerate().step_by(5) {
                variant.push(name);
                layer.push(lay);
                x.push(s.xy.0);
                y.push(s.xy.1);
                let scale = if lay == 1 { 1.0 } else { 0.8 };
                err.push(0.05 + 0.02 * noise(i) + scale * peak * (-s.to_vertex_mm / 0.5).exp());
            }
        }
    }
    df!(contour_points::variant => variant, contour_points::layer => layer, contour_points::x_mm => x, contour_points::y_mm => y, contour_points::error_mm => err).expect("frame")
}

/// `deposit_regions.parquet` on a 0.02 mm grid: the ideal bead of half width w0 along
/// the path; the conventional print bulges by up to 0.35 mm at the vertices, the
/// compensated one by 0.08 mm and falls short by 0.04 mm just before each vertex.
pub fn deposit_regions(poly: &[(f64, f64)]) -> DataFrame {
    let (mut variant, mut x, mut y, mut class) = (vec![], vec![], vec![], vec![]);
    let step = 0.02;
    for (name, bulge_mm, short_mm) in [("conventional", 0.35, 0.0), ("compensated", 0.08, 0.04)] {
        for j in -20..670 {
            for i in -20..1880 {
                let p = (i as f64 * step, j as f64 * step);
                let (d, dv) = distances(poly, p);
                if d > 0.7 {
                    continue;
                }
                let ideal = d <= W0_MM;
                let reach = W0_MM + bulge_mm * (-dv / 0.25).exp() - short_mm * (-((dv - 0.4) / 0.15).powi(2)).exp();
                let filled = d <= reach;
                let c = match (ideal, filled) {
                    (true, true) => "desired",
                    (false, true) => "over",
                    (true, false) => "under",
                    (false, false) => continue,
                };
                variant.push(name);
                x.push(p.0);
                y.push(p.1);
                class.push(c);
            }
        }
    }
    df!(deposit_regions::variant => variant, deposit_regions::x_mm => x, deposit_regions::y_mm => y, deposit_regions::class => class).expect("frame")
}

/// `accuracy.parquet`.
pub fn accuracy() -> DataFrame {
    let rows: [(&str, f64, &str, i64, &str); 8] = [
        ("capture_time_err_median_ms", 2.1, "ms", 32, "estimated vs true capture time"),
        ("capture_time_err_baseline_median_ms", 6.4, "ms", 32, "recorded time"),
        ("reprojection_rms_mm", 0.031, "mm", 128, ""),
        ("width_err_median_mm", 0.012, "mm", 9000, ""),
        ("corner_precision", 0.96, "", 150, ""),
        ("corner_recall", 0.91, "", 160, ""),
        ("frames_used", 32.0, "", 40, ""),
        ("frames_skipped", 8.0, "", 40, ""),
    ];
    df!(
        accuracy::metric => rows.iter().map(|r| r.0).collect::<Vec<_>>(),
        accuracy::value => rows.iter().map(|r| r.1).collect::<Vec<_>>(),
        accuracy::unit => rows.iter().map(|r| r.2).collect::<Vec<_>>(),
        accuracy::n => rows.iter().map(|r| r.3).collect::<Vec<_>>(),
        accuracy::note => rows.iter().map(|r| r.4).collect::<Vec<_>>()
    )
    .expect("frame")
}
