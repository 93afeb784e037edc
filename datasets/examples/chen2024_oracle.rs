//! Oracle study of paper 003's compensation (Sec. 2.4, eqs 31-39) on the virtual printer:
//! the compensation computed from the TRUE deposit instead of the thermal camera, so
//! that what is left is the method's limit on this printer, apart from measurement.
//!
//! The part is printed conventionally (20 layers); the true half widths of the monitored
//! layers are read along the allocated deposition directions (eqs 13-26, nominal lagged
//! flow) where the fill drops below one half, as `thermal.accuracy_evaluate` does, and
//! combined per sample by the median over the monitored layers, as `thermal.compensate`
//! does; each variant turns them into a compensated command; the 20 layers are printed
//! again with it (same flow draws) and scored like `thermal.reprint_evaluate`: O_E per
//! corner on the first layer (eq. 40, A_c = W²/sin θ, window radius 1 mm) and the contour
//! error (eq. 41) over all layers, with where its maximum lies.
//!
//! Two monitorings: layer 0 alone (the paper's one-layer verification, what
//! `specs/chen2024.toml` reads), and the median of layers 1-4 per sample.
//!
//! Variants:
//! - `lag model`: no widths: the desired output is the flow excess eq. 34 predicts,
//!   lag(v_e) − v_e, on the whole layer (the extension, stage `compensate_lag`).
//! - `eqs 31-33`: Δw = w_l + w_r − 2w0/cos ψ (eqs 31-32), ΔE = h|v|cos ψ·Δw (eq. 33 with
//!   K_e = 1), only Δw > 0, the fit over the extended window only: the paper as printed.
//! - `+signed`: also Δw < 0 (material added where the bead is thin).
//! - `+cad`: desired half widths = the ideal (CAD, mitred) bead's extent along each
//!   deposition direction instead of w0/cos ψ.
//! - `+tail`: the fit also drives the lagged output to zero for 3τ after each window, and
//!   later spans account for the tails of earlier ones (the defaults of `thermal.compensate`).
//! - `+sweep`: ΔE from the area swept by the turning deposition segments (with the
//!   ½κ_eff w² sectors) instead of eq. 33's h|v|cos ψ·Δw (`volume = "sweep"`).
//!
//! Run: `cargo run --release -p datasets --example chen2024_oracle` (about a minute).

use datasets::thermal::deposition::{edge_distance_mm, print_part};
use datasets::thermal::effects::Effects;
use models::stats::finite_median;
use models::thermal::compensation::{
    apply_spans, compensate_spans, velocity_change_from_sweep_mm_s, FbsParams, SpanParams, SweepSample,
};
use models::thermal::dda::{allocate_directions, DdaParams};
use models::thermal::dynamics::{first_order_lag, lag_excess};
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
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let setup = PrintSetup::paper_defaults();
    let trajectory = Trajectory::corner_test(&setup)?;
    let path = corner_test_path();
    let bead = IdealBead::new(&path, setup.bead_width_mm / 2.0)?;
    let v_e = setup.conventional_command(&trajectory);
    let conventional = print(&setup, &trajectory, &v_e)?;
    let before = score(&setup, &path, &bead, &conventional);
    let excess = lag_excess(&v_e, trajectory.dt_s, setup.tau_s); // eq. 34's flow excess (mm/s of filament)
    println!("variant       mean_OE%  contour_max_mm (where)        contour_rms_mm  spans | O_E per corner %");
    before.print("before", 0);
    let fbs = FbsParams { tail_s: 3.0 * setup.tau_s, ..FbsParams::paper_defaults() };
    let whole = vec![1.0; trajectory.len()];
    let spans = compensate_spans(&whole, &excess, trajectory.dt_s, &span_params(fbs, 0.0), |_| 1.0)?;
    let after = score(&setup, &path, &bead, &print(&setup, &trajectory, &apply_spans(&v_e, &spans))?);
    after.print("lag model", spans.len());
    for monitored in [0..1, 1..5] {
        let truth = TrueWidths::read(&setup, &trajectory, &bead, &conventional[monitored.clone()])?;
        let (over, under) = truth.seen_excess_mm3(&setup, trajectory.dt_s);
        let (lag_over, lag_under) = split_volume_mm3(&excess, setup.filament_area_mm2() * trajectory.dt_s);
        println!(
            "-- true widths of layers {}..={}: the lag delivers +{lag_over:.3} / -{lag_under:.3} mm³ per layer, \
             the widths see +{over:.3} / -{under:.3} mm³",
            monitored.start,
            monitored.end - 1
        );
        for variant in VARIANTS {
            let (command, count) = truth.command(&setup, &trajectory, &v_e, variant)?;
            let after = score(&setup, &path, &bead, &print(&setup, &trajectory, &command)?);
            after.print(variant.name, count);
        }
    }
    Ok(())
}

const VARIANTS: [Variant; 5] = [
    Variant { name: "eqs 31-33", cad_desired: false, sweep: false, signed: false, tail: false },
    Variant { name: "+signed", cad_desired: false, sweep: false, signed: true, tail: false },
    Variant { name: "+cad", cad_desired: true, sweep: false, signed: true, tail: false },
    Variant { name: "+tail", cad_desired: true, sweep: false, signed: true, tail: true },
    Variant { name: "+sweep", cad_desired: true, sweep: true, signed: true, tail: true },
];

/// Positive and negative parts of a velocity series as volumes (mm³).
fn split_volume_mm3(velocity_mm_s: &[f64], mm3_per_step: f64) -> (f64, f64) {
    let over: f64 = velocity_mm_s.iter().map(|e| e.max(0.0)).sum();
    let under: f64 = velocity_mm_s.iter().map(|e| (-e).max(0.0)).sum();
    (over * mm3_per_step, under * mm3_per_step)
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
        layers: &[DepositGrid],
    ) -> Result<Self, Box<dyn std::error::Error>> {
        let command: Vec<f64> =
            setup.conventional_command(trajectory).iter().map(|v| v * setup.filament_area_mm2()).collect();
        let flow = first_order_lag(&command, trajectory.dt_s, setup.tau_s, 0.0);
        let dirs = allocate_directions(trajectory, &flow, setup.layer_height_mm, &DdaParams::default())?;
        let speed = trajectory.speed_mm_s();
        let w0 = setup.bead_width_mm / 2.0;
        let mut out = Self { measured: vec![], paper_desired: vec![], cad_desired: vec![], sweep: vec![] };
        for k in 0..trajectory.len() {
            let p = [trajectory.x_mm[k], trajectory.y_mm[k]];
            let (sin, cos) = dirs.deposition_heading_rad[k].sin_cos();
            let (left, right) = ([-sin, cos], [sin, -cos]);
            let side = |dir: [f64; 2]| finite_median(layers.iter().map(|g| edge_distance_mm(g, p, dir)));
            out.measured.push((side(left), side(right)));
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
            1.0,
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

impl TrueWidths {
    /// The flow excess the widths show over one layer, positive and negative (mm³),
    /// with the stage's defaults (CAD desired width, swept area).
    fn seen_excess_mm3(&self, setup: &PrintSetup, dt_s: f64) -> (f64, f64) {
        let area = setup.filament_area_mm2();
        let dv = velocity_change_from_sweep_mm_s(
            &self.measured,
            &self.cad_desired,
            &self.sweep,
            setup.layer_height_mm,
            area,
            1.0,
        );
        split_volume_mm3(&dv, area * dt_s)
    }
}

/// The evaluation of `thermal.reprint_evaluate`.
struct Score {
    oe_pct: Vec<f64>,
    max_mm: f64,
    /// Layer and CAD point of the largest contour error.
    max_at: (usize, [f64; 2]),
    rms_mm: f64,
}

fn score(setup: &PrintSetup, path: &[[f64; 2]], bead: &IdealBead, layers: &[DepositGrid]) -> Score {
    let w = setup.bead_width_mm;
    let n = path.len();
    let mut oe_pct = Vec::with_capacity(n);
    for i in 0..n {
        let (a, b) = (sub(path[(i + n - 1) % n], path[i]), sub(path[(i + 1) % n], path[i]));
        let cos = (a[0] * b[0] + a[1] * b[1]) / (a[0].hypot(a[1]) * b[0].hypot(b[1]));
        let polytope = w * w / cos.clamp(-1.0, 1.0).acos().sin();
        let c = corner_deposition(&layers[0], bead, path[i], CORNER_RADIUS_MM);
        oe_pct.push(100.0 * c.over_area_mm2 / polytope);
    }
    let cad = bead.contour_points(0.05, false); // the external surface, as the stage
    let errors: Vec<_> = layers.iter().map(|g| contour_errors(g, &cad)).collect();
    let summary = summarize(&errors);
    let max_at = errors
        .iter()
        .enumerate()
        .flat_map(|(l, e)| e.iter().map(move |p| (p.error_mm, l, [p.x_mm, p.y_mm])))
        .max_by(|a, b| a.0.total_cmp(&b.0))
        .map_or((0, [f64::NAN; 2]), |(_, l, p)| (l, p));
    Score { oe_pct, max_mm: summary.max_mm, max_at, rms_mm: summary.rms_mm }
}

fn sub(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

impl Score {
    fn print(&self, name: &str, spans: usize) {
        let mean = self.oe_pct.iter().sum::<f64>() / self.oe_pct.len() as f64;
        let per: Vec<String> = self.oe_pct.iter().map(|v| format!("{v:.0}")).collect();
        let (layer, [x, y]) = self.max_at;
        let at = format!("(L{layer} {x:.2}, {y:.2})");
        println!("{name:12} {mean:8.1} {:8.3} {at:22} {:12.4} {spans:6} | {}", self.max_mm, self.rms_mm, per.join(" "));
    }
}
