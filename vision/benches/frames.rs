//! Frame throughput of the paper-003 thermal pipeline (Sec. 2.3-2.4) on a synthetic
//! 160 × 120 Lepton frame with 6 hot corners and 200 width queries: the whole
//! `pipeline::process_frame` (undistort, corners, matching, RANSAC homography,
//! localization, widths) and the undistortion alone.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::hint::black_box;

use vision::camera::{CameraModel, Distortion, Undistorter};
use vision::frame::ThermalFrame;
use vision::localize::TrajectoryView;
use vision::matching::PredictedCorner;
use vision::pipeline::{predict_corners_into, process_frame, FrameContext, FrameInput, FrameWorkspace, PipelineParams};
use vision::synth::{add_noise, render_raw_frame, HotPolyline};
use vision::widths::WidthQuery;

const T_CAPTURE_S: f64 = 1.5043;
const T_RECORDED_S: f64 = 1.5;

struct Setup {
    camera: CameraModel,
    frame: ThermalFrame,
    t: Vec<f64>,
    x: Vec<f64>,
    y: Vec<f64>,
    scene: HotPolyline,
    queries: Vec<WidthQuery>,
}

/// Nozzle along +x at 20 mm/s; a zigzag with 6 interior corners around it.
fn setup() -> Setup {
    let camera = CameraModel::lepton35(Distortion { k1: -0.1, k2: 0.02, p1: 0.0005, p2: -0.0005 });
    let t: Vec<f64> = (0..4000).map(|i| i as f64 * 0.001).collect();
    let (x, y): (Vec<f64>, Vec<f64>) = t.iter().map(|&t| (-30.0 + 20.0 * t, 10.0)).unzip();
    let nozzle = [-30.0 + 20.0 * T_CAPTURE_S, 10.0];
    let rel =
        [[-11.0, -1.0], [-8.0, 2.5], [-4.8, -2.0], [-1.6, 2.5], [1.6, -2.0], [4.8, 2.5], [8.0, -1.5], [11.0, 2.0]];
    let scene = HotPolyline {
        vertices_mm: rel.iter().map(|p| [p[0] + nozzle[0], p[1] + nozzle[1]]).collect(),
        background_c: 60.0,
        bead_c: 128.0,
        bead_sigma_mm: 0.25,
        corner_excess_c: 18.0,
        corner_sigma_mm: 0.45,
    };
    let mut frame = render_raw_frame(&camera, nozzle, |p| scene.temp_c(p));
    add_noise(&mut frame, 0.05, 1);
    let queries = width_queries(&scene.vertices_mm, 200);
    Setup { camera, frame, t, x, y, scene, queries }
}

/// `n` points spread evenly over the polyline's segments, with left normals.
fn width_queries(v: &[[f64; 2]], n: usize) -> Vec<WidthQuery> {
    let segs = v.len() - 1;
    (0..n)
        .map(|k| {
            let (i, s) = (k % segs, 0.1 + 0.8 * (k / segs) as f64 / (n / segs) as f64);
            let (a, b) = (v[i], v[i + 1]);
            let len = (b[0] - a[0]).hypot(b[1] - a[1]);
            let dir = [(b[0] - a[0]) / len, (b[1] - a[1]) / len];
            WidthQuery { p_mm: [a[0] + s * (b[0] - a[0]), a[1] + s * (b[1] - a[1])], n_left: [-dir[1], dir[0]] }
        })
        .collect()
}

fn bench_pipeline(c: &mut Criterion) {
    let s = setup();
    let undistorter = Undistorter::new(&s.camera).expect("correction map");
    let traj = TrajectoryView::new(&s.t, &s.x, &s.y).expect("uniform trajectory");
    let params = PipelineParams::paper_defaults(94.0);
    let ctx = FrameContext {
        undistorter: &undistorter,
        h0: s.camera.nominal_homography(),
        nozzle_px: s.camera.plane_to_raw_px([0.0, 0.0]).expect("nozzle in view"),
        trajectory: traj,
        params,
    };
    let corners: Vec<(u32, [f64; 2])> = s.scene.corners_mm().iter().enumerate().map(|(i, &p)| (i as u32, p)).collect();
    let mut predicted: Vec<PredictedCorner> = Vec::new();
    predict_corners_into(&ctx.h0, traj.position_mm(T_RECORDED_S), &corners, &mut predicted);
    let input =
        FrameInput { frame: &s.frame, t_recorded_s: T_RECORDED_S, predicted: &predicted, width_queries: &s.queries };
    let mut ws = FrameWorkspace::new(&undistorter, &params).expect("workspace");
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let check = process_frame(&ctx, &input, &mut ws, &mut rng).expect("bench frame must localize");
    assert_eq!(check.matches.len(), 6, "bench frame must show its 6 corners");

    let mut group = c.benchmark_group("thermal_frame");
    group.throughput(Throughput::Elements(1));
    group.bench_function("pipeline_160x120_6corners_200widths", |b| {
        b.iter(|| black_box(process_frame(&ctx, black_box(&input), &mut ws, &mut rng).is_ok()))
    });
    let mut out = ThermalFrame::filled(160, 120, f32::NAN);
    group.bench_function("undistort_160x120", |b| {
        b.iter(|| undistorter.undistort_into(black_box(&s.frame), &mut out).expect("same size"))
    });
    group.finish();
}

criterion_group!(benches, bench_pipeline);
criterion_main!(benches);
