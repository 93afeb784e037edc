//! Oracle study of paper 003's compensation (Sec. 2.4, eqs 31-39) on the virtual printer:
//! the compensation computed from the TRUE deposit instead of the thermal camera, so
//! that what is left is the method's limit on this printer, apart from measurement.
//!
//! The first layer is printed conventionally; its true half widths are read along the
//! allocated deposition directions (eqs 13-26, nominal lagged flow) where the fill drops
//! below one half, as `thermal.accuracy_evaluate` does; each variant turns them into a
//! compensated command; 20 layers are re-printed with and without it (same flow draws)
//! and scored like `thermal.reprint_evaluate`: O_E per corner (eq. 40, A_c = W²/sin θ,
//! window radius 1 mm) and the contour error (eq. 41) over all layers.
//!
//! Variants (each changes one thing from the line above):
//! - `flow`: no widths: the desired output is the exact flow excess of the lagged
//!   deposition over the nominal, lag(v_e) − v_e, on the whole layer. The limit of
//!   eqs 34-39 themselves (bounds, spline, lag model) on this printer.
//! - `paper`: Δw = w_l + w_r − 2w0/cos ψ (eqs 31-32), ΔE = h|v|cos ψ·Δw (eq. 33 with
//!   K_e = 1), only Δw > 0, FBS over the extended window only (the stage before this study).
//! - `signed`: also Δw < 0 (material added where the bead is thin).
//! - `cad`: desired half widths = the ideal (CAD, mitred) bead's extent along each
//!   deposition direction instead of w0/cos ψ.
//! - `sweep`: ΔE from the swept area of the deposition segments (with the ½κ_eff w² sectors).
//! - `tail`: the FBS also fits the lagged output to zero for 3τ after each window, and
//!   later spans account for the tails of earlier ones.
//!
//! Run: `cargo run --release -p datasets --example chen2024_oracle`.

use datasets::thermal::deposition::{conventional_command, edge_distance_mm, print_part};
use datasets::thermal::effects::Effects;
use models::thermal::compensation::{
    apply_spans, compensate_spans, velocity_change_from_sweep_mm_s, FbsParams, SpanParams, SweepSample,
};
use models::thermal::dda::{allocate_directions, DdaParams};
use models::thermal::dynamics::first_order_lag;
use models::thermal::metrics::{contour_errors, corner_deposition, summarize, IdealBead};
use models::thermal::setup::corner_test_path;
use models::thermal::{DepositGrid, PrintSetup, Trajectory};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

const SEED: u64 = 3;
const LAYERS: usize = 20;
const CORNER_RADIUS_MM: f64 = 1.0;
const EPSILON_MM: f64 = 0.05;

/// How a variant turns the true widths into a desired output change.
#[derive(Clone, Copy)]
struct Variant {
    name: &'static str,
    cad_desired: bool,
    sweep: bool,
    signed: bool,
    tail: bool,
    gain: f64,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let setup = PrintSetup::paper_defaults();
    let trajectory = Trajectory::corner_test(&setup)?;
    let path = corner_test_path();
    let bead = IdealBead::new(&path, setup.bead_width_mm / 2.0)?;
    let v_e = conventional_command(&setup, &trajectory);
    let conventional = print(&setup, &trajectory, &v_e)?;
    let monitored: usize = std::env::var("ORACLE_LAYER").ok().and_then(|v| v.parse().ok()).unwrap_or(0);
    let truth = TrueWidths::read(&setup, &trajectory, &bead, &conventional[monitored])?;
    let before = score(&setup, &path, &bead, &conventional);
    println!("variant  mean_OE%  contour_max_mm  contour_rms_mm  under_mm2(sum)  spans | O_E per corner %");
    before.print("before", 0);
    let lagged = first_order_lag(&v_e, trajectory.dt_s, setup.tau_s, 0.0);
    let excess: Vec<f64> = lagged.iter().zip(&v_e).map(|(l, v)| l - v).collect();
    let a_fil_dt = setup.filament_area_mm2() * trajectory.dt_s;
    let flow_over_mm3: f64 = excess.iter().map(|e| e.max(0.0)).sum::<f64>() * a_fil_dt;
    let flow_under_mm3: f64 = excess.iter().map(|e| (-e).max(0.0)).sum::<f64>() * a_fil_dt;
    let dv = velocity_change_from_sweep_mm_s(
        &truth.measured,
        &truth.cad_desired,
        &truth.sweep,
        setup.layer_height_mm,
        setup.filament_area_mm2(),
        1.0,
    );
    let seen_over_mm3: f64 = dv.iter().map(|e| e.max(0.0)).sum::<f64>() * a_fil_dt;
    let seen_under_mm3: f64 = dv.iter().map(|e| (-e).max(0.0)).sum::<f64>() * a_fil_dt;
    println!(
        "flow excess of the lag: +{flow_over_mm3:.3} / -{flow_under_mm3:.3} mm³; seen in true widths (cad, sweep): \
         +{seen_over_mm3:.3} / -{seen_under_mm3:.3} mm³; A_o·h summed over corners {:.3} mm³",
        before.over_mm2 * setup.layer_height_mm
    );
    let whole = vec![1.0; trajectory.len()];
    let fbs = FbsParams { tail_s: 3.0 * setup.tau_s, ..FbsParams::paper_defaults() };
    let spans = compensate_spans(&whole, &excess, trajectory.dt_s, &span_params(fbs, 0.0), |_| 1.0)?;
    let after = score(&setup, &path, &bead, &print(&setup, &trajectory, &apply_spans(&v_e, &spans))?);
    after.print("flow", spans.len());
    let variants = [
        Variant { name: "paper", cad_desired: false, sweep: false, signed: false, tail: false, gain: 1.0 },
        Variant { name: "signed", cad_desired: false, sweep: false, signed: true, tail: false, gain: 1.0 },
        Variant { name: "cad", cad_desired: true, sweep: false, signed: true, tail: false, gain: 1.0 },
        Variant { name: "sweep", cad_desired: true, sweep: true, signed: true, tail: false, gain: 1.0 },
        Variant { name: "tail", cad_desired: true, sweep: true, signed: true, tail: true, gain: 1.0 },
        Variant { name: "cad+ovr", cad_desired: true, sweep: true, signed: false, tail: true, gain: 1.0 },
        Variant { name: "tail1.33", cad_desired: true, sweep: true, signed: true, tail: true, gain: 1.33 },
        Variant { name: "tail1.67", cad_desired: true, sweep: true, signed: true, tail: true, gain: 1.67 },
        Variant { name: "cad+tail", cad_desired: true, sweep: false, signed: true, tail: true, gain: 1.0 },
        Variant { name: "paper+tail", cad_desired: false, sweep: false, signed: false, tail: true, gain: 1.0 },
        Variant { name: "eq31sgn+t", cad_desired: false, sweep: true, signed: true, tail: true, gain: 1.0 },
    ];
    for variant in variants {
        let (command, count) = truth.command(&setup, &trajectory, &v_e, variant)?;
        let after = score(&setup, &path, &bead, &print(&setup, &trajectory, &command)?);
        after.print(variant.name, count);
    }
    Ok(())
}

fn span_params(fbs: FbsParams, epsilon_mm: f64) -> SpanParams {
    SpanParams { epsilon_mm, extension_s: 0.1, fbs }
}

fn print(
    setup: &PrintSetup,
    trajectory: &Trajectory,
    command: &[f64],
) -> Result<Vec<DepositGrid>, Box<dyn std::error::Error>> {
    let mut rng = ChaCha8Rng::seed_from_u64(SEED);
    let layers = print_part(setup, trajectory, command, LAYERS, &Effects::none(), &mut rng)?;
    Ok(layers.into_iter().map(|l| l.grid).collect())
}

/// The true deposit's half widths along the allocated directions, and the desired ones.
struct TrueWidths {
    measured: Vec<(f64, f64)>,
    paper_desired: Vec<(f64, f64)>,
    cad_desired: Vec<(f64, f64)>,
    sweep: Vec<SweepSample>,
}

impl TrueWidths {
    fn read(
        setup: &PrintSetup,
        trajectory: &Trajectory,
        bead: &IdealBead,
        grid: &DepositGrid,
    ) -> Result<Self, Box<dyn std::error::Error>> {
        let command: Vec<f64> =
            conventional_command(setup, trajectory).iter().map(|v| v * setup.filament_area_mm2()).collect();
        let flow = first_order_lag(&command, trajectory.dt_s, setup.tau_s, 0.0);
        let dirs = allocate_directions(trajectory, &flow, setup.layer_height_mm, &DdaParams::default())?;
        let speed = trajectory.speed_mm_s();
        let w0 = setup.bead_width_mm / 2.0;
        let mut out = Self { measured: vec![], paper_desired: vec![], cad_desired: vec![], sweep: vec![] };
        for k in 0..trajectory.len() {
            let p = [trajectory.x_mm[k], trajectory.y_mm[k]];
            let (sin, cos) = dirs.deposition_heading_rad[k].sin_cos();
            let (left, right) = ([-sin, cos], [sin, -cos]);
            out.measured.push((edge_distance_mm(grid, p, left), edge_distance_mm(grid, p, right)));
            let wd = w0 / dirs.psi_rad[k].cos();
            out.paper_desired.push((wd, wd));
            out.cad_desired.push((bead.edge_distance_mm(p, left), bead.edge_distance_mm(p, right)));
            out.sweep.push(SweepSample {
                speed_mm_s: speed[k],
                psi_rad: dirs.psi_rad[k],
                kappa_eff_per_mm: dirs.effective_curvature_per_mm[k],
            });
        }
        Ok(out)
    }

    fn command(
        &self,
        setup: &PrintSetup,
        trajectory: &Trajectory,
        v_e: &[f64],
        variant: Variant,
    ) -> Result<(Vec<f64>, usize), Box<dyn std::error::Error>> {
        let desired = if variant.cad_desired { &self.cad_desired } else { &self.paper_desired };
        let mut dw: Vec<f64> = self.measured.iter().zip(desired).map(|(m, d)| m.0 + m.1 - d.0 - d.1).collect();
        let sweep: Vec<SweepSample> = if variant.sweep {
            self.sweep.clone()
        } else {
            self.sweep.iter().map(|s| SweepSample { kappa_eff_per_mm: 0.0, ..*s }).collect()
        };
        let mut dv = velocity_change_from_sweep_mm_s(
            &self.measured,
            desired,
            &sweep,
            setup.layer_height_mm,
            setup.filament_area_mm2(),
            variant.gain,
        );
        if !variant.signed {
            dw.iter_mut().for_each(|d| *d = d.max(0.0));
            dv.iter_mut().for_each(|d| *d = d.max(0.0));
        }
        let tail_s = if variant.tail { 3.0 * setup.tau_s } else { 0.0 };
        let fbs = FbsParams { tail_s, ..FbsParams::paper_defaults() };
        let spans = compensate_spans(&dw, &dv, trajectory.dt_s, &span_params(fbs, EPSILON_MM), |_| 1.0)?;
        Ok((apply_spans(v_e, &spans), spans.len()))
    }
}

/// The evaluation of `thermal.reprint_evaluate`.
struct Score {
    oe_pct: Vec<f64>,
    under_mm2: f64,
    over_mm2: f64,
    max_mm: f64,
    rms_mm: f64,
}

fn score(setup: &PrintSetup, path: &[[f64; 2]], bead: &IdealBead, layers: &[DepositGrid]) -> Score {
    let w = setup.bead_width_mm;
    let n = path.len();
    let mut oe_pct = Vec::with_capacity(n);
    let (mut under_mm2, mut over_mm2) = (0.0, 0.0);
    for i in 0..n {
        let (a, b) = (sub(path[(i + n - 1) % n], path[i]), sub(path[(i + 1) % n], path[i]));
        let cos = (a[0] * b[0] + a[1] * b[1]) / (a[0].hypot(a[1]) * b[0].hypot(b[1]));
        let polytope = w * w / cos.clamp(-1.0, 1.0).acos().sin();
        let c = corner_deposition(&layers[0], bead, path[i], CORNER_RADIUS_MM);
        oe_pct.push(100.0 * c.over_area_mm2 / polytope);
        under_mm2 += c.under_area_mm2;
        over_mm2 += c.over_area_mm2;
    }
    let cad = bead.contour_points(0.05);
    let errors: Vec<_> = layers.iter().map(|g| contour_errors(g, &cad)).collect();
    let summary = summarize(&errors);
    let mut worst: Vec<(f64, usize, f64, f64)> =
        errors.iter().enumerate().flat_map(|(l, e)| e.iter().map(move |p| (p.error_mm, l, p.x_mm, p.y_mm))).collect();
    worst.sort_by(|a, b| b.0.total_cmp(&a.0));
    let mut seen: Vec<(f64, f64)> = Vec::new();
    for w in &worst {
        if seen.iter().all(|s| (s.0 - w.2).hypot(s.1 - w.3) > 1.0) {
            seen.push((w.2, w.3));
            eprint!("  [{:.3} L{} ({:.2},{:.2})]", w.0, w.1, w.2, w.3);
        }
        if seen.len() >= 4 {
            break;
        }
    }
    eprintln!();
    Score { oe_pct, under_mm2, over_mm2, max_mm: summary.max_mm, rms_mm: summary.rms_mm }
}

fn sub(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

impl Score {
    fn print(&self, name: &str, spans: usize) {
        let mean = self.oe_pct.iter().sum::<f64>() / self.oe_pct.len() as f64;
        let per: Vec<String> = self.oe_pct.iter().map(|v| format!("{v:.0}")).collect();
        println!(
            "{name:8} {mean:8.1} {:14.3} {:15.4} {:15.3} {spans:6} | {}",
            self.max_mm,
            self.rms_mm,
            self.under_mm2,
            per.join(" ")
        );
    }
}
