//! The virtual ink-jet printer and laser profiler of paper 002 (DESIGN §5.2): the one
//! implementation of the "truth" machine, used by the simulated experiments (Figs 11-15,
//! Table II) and by the `inkjet-scans` dataset generator alike.
//!
//! **Printing** follows the height model of eqs 2-7 (corrected, [`super::height_model`]),
//! but every droplet has its own volume: its coefficients are the nominal ones of its
//! cell (part or support material) scaled by
//! `(1 − u) · b_i · (1 + drift · k)`, where `u ~ U[0, p]` is the paper's "[0 p]
//! variation" read as a volume shortfall (DESIGN §5.2), `b_i` the nozzle bias of grid
//! column `i` and `k` the 0-based layer index (both 1 / 0 unless their effect is on).
//!
//! **Profiler** (Sec. V-B: 1 µm repeatability): the reported height of a cell is the true
//! profile averaged over a Gaussian laser spot of standard deviation `spot_sigma_um`
//! (weights over the cells within 3σ, renormalised at the grid boundary; finite lateral
//! resolution), plus independent Gaussian noise of `noise_um`.
//!
//! **Extra effects** (DESIGN §5.2), each named, with a strength, off at strength 0; they
//! exist so that the paper's model can be tested against physics it lacks:
//! - `curing_shrinkage` (fraction): each freshly printed layer loses this fraction of
//!   its height when cured.
//! - `levelling_flow` (diffusion number `D`, at most 0.25 for a stable explicit step):
//!   before cure the fresh layer's increment `Δ` flows once, `Δ ← Δ + D·∇²Δ` over side
//!   neighbours with no flux across the grid boundary (volume conserved).
//! - `nozzle_bias` (relative std): nozzle `i` prints every droplet of grid column `i`
//!   with volume factor `b_i = max(0, 1 + σ·z_i)`, `z_i ~ N(0, 1)` drawn once per print.
//! - `substrate_tilt` (µm per mm): the substrate is not level, its height is
//!   `tilt · x` before the first layer.
//! - `volume_drift` (fraction per layer): droplet volume changes by `drift · k` at layer
//!   `k` (factor clamped at 0).
//!
//! Random streams: a print draws three seeds from the caller's generator (droplets,
//! profiler, nozzles), so measuring more or less often, or switching an effect on, never
//! changes the droplets drawn.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal, StandardNormal};

use super::errors::InkjetError;
use super::grid::{Grid, HeightMap, Pattern, SIDE_OFFSETS};
use super::height_model::{deposit_layer_into, DropletCoeffs};

/// A named extra physical effect of the virtual printer (DESIGN §5.2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Effect {
    /// Each layer loses a fraction of its height when cured.
    CuringShrinkage,
    /// Diffusive smoothing of the fresh layer before cure (strength: diffusion number).
    LevellingFlow,
    /// A fixed relative droplet-volume bias per grid column (strength: its std).
    NozzleBias,
    /// Substrate height rising along x (strength: µm per mm).
    SubstrateTilt,
    /// Droplet volume changing by strength × layer index.
    VolumeDrift,
}

impl Effect {
    /// Every effect, in name order.
    pub const ALL: [Effect; 5] = [
        Effect::CuringShrinkage,
        Effect::LevellingFlow,
        Effect::NozzleBias,
        Effect::SubstrateTilt,
        Effect::VolumeDrift,
    ];

    /// The effect's name as written in `dataset.toml` and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Effect::CuringShrinkage => "curing_shrinkage",
            Effect::LevellingFlow => "levelling_flow",
            Effect::NozzleBias => "nozzle_bias",
            Effect::SubstrateTilt => "substrate_tilt",
            Effect::VolumeDrift => "volume_drift",
        }
    }

    /// The effect of that name; unknown names are an error listing the known ones.
    pub fn parse(name: &str) -> Result<Self, InkjetError> {
        Self::ALL.into_iter().find(|e| e.name() == name).ok_or_else(|| InkjetError::UnknownEffect {
            name: name.to_string(),
            known: Self::ALL.map(Effect::name).join(", "),
        })
    }

    /// Admissible strengths `[min, max]` and their unit.
    pub fn range(self) -> (f64, f64, &'static str) {
        match self {
            Effect::CuringShrinkage => (0.0, 0.5, "fraction of the layer height"),
            Effect::LevellingFlow => (0.0, 0.25, "diffusion number per layer"),
            Effect::NozzleBias => (0.0, 0.5, "relative std of the per-column volume"),
            Effect::SubstrateTilt => (-50.0, 50.0, "um per mm along x"),
            Effect::VolumeDrift => (-0.01, 0.01, "relative volume change per layer"),
        }
    }
}

/// Strengths of the extra effects (0 = off).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Effects {
    strengths: [f64; 5],
}

impl Effects {
    /// No extra effect: the paper's own physics.
    pub fn none() -> Self {
        Self::default()
    }

    /// These effects plus `effect` at `strength`, checked against [`Effect::range`].
    pub fn with(mut self, effect: Effect, strength: f64) -> Result<Self, InkjetError> {
        let (min, max, unit) = effect.range();
        if !strength.is_finite() || strength < min || strength > max {
            return Err(InkjetError::EffectStrength { name: effect.name(), strength, min, max, unit });
        }
        self.strengths[effect as usize] = strength;
        Ok(self)
    }

    /// Effects from `(name, strength)` pairs; unknown names, bad strengths and a name
    /// given twice are errors.
    pub fn from_pairs<S: AsRef<str>>(pairs: &[(S, f64)]) -> Result<Self, InkjetError> {
        let mut effects = Self::none();
        let mut seen = Vec::new();
        for (name, strength) in pairs {
            let effect = Effect::parse(name.as_ref())?;
            if seen.contains(&effect) {
                return Err(InkjetError::DuplicateEffect { name: effect.name() });
            }
            seen.push(effect);
            effects = effects.with(effect, *strength)?;
        }
        Ok(effects)
    }

    /// Effects from text `name=strength,name=strength` (empty or `none`: no effect).
    pub fn parse(text: &str) -> Result<Self, InkjetError> {
        let text = text.trim();
        if text.is_empty() || text == "none" {
            return Ok(Self::none());
        }
        let mut pairs = Vec::new();
        for item in text.split(',') {
            let (name, value) = item.split_once('=').ok_or_else(|| InkjetError::EffectSyntax { item: item.into() })?;
            let strength = value.trim().parse::<f64>().map_err(|_| InkjetError::EffectSyntax { item: item.into() })?;
            pairs.push((name.trim().to_string(), strength));
        }
        Self::from_pairs(&pairs)
    }

    /// Strength of `effect` (0 when off).
    pub fn strength(&self, effect: Effect) -> f64 {
        self.strengths[effect as usize]
    }

    /// The effects that are on, with their strengths, in name order.
    pub fn active(&self) -> Vec<(Effect, f64)> {
        Effect::ALL.into_iter().map(|e| (e, self.strength(e))).filter(|&(_, s)| s != 0.0).collect()
    }

    /// `none`, or `name=strength` pairs joined by commas (the text [`Effects::parse`] reads).
    pub fn describe(&self) -> String {
        let active = self.active();
        if active.is_empty() {
            return "none".into();
        }
        active.iter().map(|(e, s)| format!("{}={s}", e.name())).collect::<Vec<_>>().join(",")
    }
}

/// The laser profiler: repeatability noise and a Gaussian spot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Profiler {
    /// Standard deviation of the measurement noise, µm.
    pub noise_um: f64,
    /// Standard deviation of the Gaussian laser spot, µm (0: point samples at the cells).
    pub spot_sigma_um: f64,
}

impl Profiler {
    /// Sec. V-B: 1 µm repeatability. The spot (the paper gives no lateral resolution) is
    /// our choice: σ = 80 µm, about a third of the 263 µm droplet spacing, so a cell's
    /// reading takes 0.45 % from each side neighbour (a 400 µm wall edge reads ≈ 2 µm low).
    pub fn paper() -> Self {
        Self { noise_um: 1.0, spot_sigma_um: 80.0 }
    }

    /// A noiseless point profiler (reads the true heights).
    pub fn ideal() -> Self {
        Self { noise_um: 0.0, spot_sigma_um: 0.0 }
    }

    /// The spot weights `(di, dj, w)` on `grid`, unnormalised, centre included.
    pub fn kernel(&self, grid: Grid) -> Vec<(isize, isize, f64)> {
        if self.spot_sigma_um <= 0.0 {
            return vec![(0, 0, 1.0)];
        }
        let sigma_cells = self.spot_sigma_um / grid.spacing_um;
        let reach = (3.0 * sigma_cells).ceil() as isize;
        let mut kernel = Vec::new();
        for dj in -reach..=reach {
            for di in -reach..=reach {
                let d2 = (di * di + dj * dj) as f64;
                kernel.push((di, dj, (-d2 / (2.0 * sigma_cells * sigma_cells)).exp()));
            }
        }
        kernel
    }

    /// The true profile as seen through the spot (no noise).
    pub fn blur(&self, truth: &HeightMap) -> HeightMap {
        let grid = truth.grid;
        let kernel = self.kernel(grid);
        let height_um = (0..grid.len())
            .map(|c| {
                let (i, j) = grid.coords(c);
                let (mut sum, mut weight) = (0.0, 0.0);
                for &(di, dj, w) in &kernel {
                    if let Some((ni, nj)) = grid.offset(i, j, di, dj) {
                        sum += w * truth.at(ni, nj);
                        weight += w;
                    }
                }
                sum / weight
            })
            .collect();
        HeightMap { grid, height_um }
    }
}

/// The simulated machine: nominal droplets with a random volume shortfall, extra
/// effects, and a profiler.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TruthPrinter {
    /// Nominal droplet coefficients of the part material (Table I).
    pub nominal: DropletCoeffs,
    /// Largest shortfall `p`: each droplet is scaled by `1 − u`, `u ~ U[0, p]`.
    pub max_shortfall: f64,
    /// The height sensor.
    pub profiler: Profiler,
    /// Extra physical effects.
    pub effects: Effects,
}

impl TruthPrinter {
    /// Table I droplets, shortfall `U[0, p]`, the paper's profiler, no extra effect.
    pub fn paper(max_shortfall: f64) -> Self {
        Self {
            nominal: DropletCoeffs::paper_table1(),
            max_shortfall,
            profiler: Profiler::paper(),
            effects: Effects::none(),
        }
    }

    /// Starts a print on `grid`: the substrate (flat, or tilted), the nozzle biases and
    /// the random streams, seeded from `rng`.
    pub fn start(&self, grid: Grid, rng: &mut impl Rng) -> PrintRun {
        let droplet_rng = ChaCha8Rng::seed_from_u64(rng.next_u64());
        let profiler_rng = ChaCha8Rng::seed_from_u64(rng.next_u64());
        let mut nozzle_rng = ChaCha8Rng::seed_from_u64(rng.next_u64());
        let bias = self.effects.strength(Effect::NozzleBias);
        let nozzle_factor = (0..grid.m_x)
            .map(|_| {
                let z: f64 = StandardNormal.sample(&mut nozzle_rng);
                (1.0 + bias * z).max(0.0)
            })
            .collect();
        let tilt_um_per_mm = self.effects.strength(Effect::SubstrateTilt);
        let substrate = (0..grid.len()).map(|c| tilt_um_per_mm * grid.position_um(grid.coords(c).0, 0).0 / 1000.0);
        let truth = HeightMap { grid, height_um: substrate.collect() };
        PrintRun {
            printer: *self,
            truth,
            layers: 0,
            nozzle_factor,
            droplet_rng,
            profiler_rng,
            coeffs: Vec::with_capacity(grid.len()),
            after_um: vec![0.0; grid.len()],
        }
    }
}

/// One print in progress on the virtual printer.
#[derive(Debug, Clone)]
pub struct PrintRun {
    printer: TruthPrinter,
    truth: HeightMap,
    layers: usize,
    nozzle_factor: Vec<f64>,
    droplet_rng: ChaCha8Rng,
    profiler_rng: ChaCha8Rng,
    coeffs: Vec<DropletCoeffs>,
    after_um: Vec<f64>,
}

impl PrintRun {
    /// The true profile (ground truth; a controller sees only [`PrintRun::measure`]).
    pub fn truth(&self) -> &HeightMap {
        &self.truth
    }

    /// The nozzle (grid column) volume factors of this print (all 1 without nozzle bias).
    pub fn nozzle_factors(&self) -> &[f64] {
        &self.nozzle_factor
    }

    /// Layers printed so far.
    pub fn layers_printed(&self) -> usize {
        self.layers
    }

    /// Prints `pattern` with the per-cell nominal coefficients `nominal` (the material
    /// chosen for each cell), one shortfall per droplet in row-major order, then applies
    /// levelling flow and curing shrinkage to the fresh layer.
    pub fn print_layer(&mut self, pattern: &Pattern, nominal: &[DropletCoeffs]) -> Result<(), InkjetError> {
        let grid = self.truth.grid;
        grid.check_pattern(pattern)?;
        grid.check_len("coefficients", nominal.len())?;
        let effects = self.printer.effects;
        let layer_factor = (1.0 + effects.strength(Effect::VolumeDrift) * self.layers as f64).max(0.0);
        self.coeffs.clear();
        for (c, (&droplet, &coeffs)) in pattern.droplet.iter().zip(nominal).enumerate() {
            let factor = if droplet {
                let u = self.droplet_rng.random_range(0.0..=self.printer.max_shortfall);
                (1.0 - u) * self.nozzle_factor[grid.coords(c).0] * layer_factor
            } else {
                1.0
            };
            self.coeffs.push(coeffs.scaled(factor));
        }
        deposit_layer_into(grid, &self.truth.height_um, &pattern.droplet, &self.coeffs, &mut self.after_um);
        let mut increment: Vec<f64> = self.after_um.iter().zip(&self.truth.height_um).map(|(a, b)| a - b).collect();
        let diffusion = effects.strength(Effect::LevellingFlow);
        if diffusion > 0.0 {
            increment = diffuse_once(grid, &increment, diffusion);
        }
        let keep = 1.0 - effects.strength(Effect::CuringShrinkage);
        for (h, d) in self.truth.height_um.iter_mut().zip(&increment) {
            *h += keep * d;
        }
        self.layers += 1;
        Ok(())
    }

    /// What the profiler reports now: the spot-averaged true profile plus noise.
    pub fn measure(&mut self) -> HeightMap {
        let profiler = self.printer.profiler;
        let mut seen = profiler.blur(&self.truth);
        if profiler.noise_um > 0.0 {
            let noise = Normal::new(0.0, profiler.noise_um).expect("finite, non-negative noise");
            for h in &mut seen.height_um {
                *h += noise.sample(&mut self.profiler_rng);
            }
        }
        seen
    }
}

/// One explicit diffusion step `Δ + D·∇²Δ` over side neighbours, no flux across the
/// grid boundary: the sum of `Δ` is unchanged.
pub fn diffuse_once(grid: Grid, increment: &[f64], diffusion: f64) -> Vec<f64> {
    (0..grid.len())
        .map(|c| {
            let (i, j) = grid.coords(c);
            let flow: f64 = SIDE_OFFSETS
                .iter()
                .filter_map(|&(di, dj)| grid.offset(i, j, di, dj))
                .map(|(ni, nj)| increment[grid.index(ni, nj)] - increment[c])
                .sum();
            increment[c] + diffusion * flow
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::inkjet::height_model::uniform_coeffs;

    fn square(grid: Grid, lo: usize, hi: usize) -> Pattern {
        let droplet = (0..grid.len())
            .map(|c| {
                let (i, j) = grid.coords(c);
                (lo..=hi).contains(&i) && (lo..=hi).contains(&j)
            })
            .collect();
        Pattern::from_vec(grid, droplet).unwrap()
    }

    fn exact(effects: Effects) -> TruthPrinter {
        TruthPrinter { max_shortfall: 0.0, profiler: Profiler::ideal(), effects, ..TruthPrinter::paper(0.0) }
    }

    fn printed_volume(printer: TruthPrinter, layers: usize) -> (f64, PrintRun) {
        let grid = Grid::new(12, 12, Grid::paper_spacing_um()).unwrap();
        let mut run = printer.start(grid, &mut ChaCha8Rng::seed_from_u64(5));
        let nominal = uniform_coeffs(grid, DropletCoeffs::paper_table1());
        for _ in 0..layers {
            run.print_layer(&square(grid, 3, 8), &nominal).unwrap();
        }
        (run.truth().height_um.iter().sum(), run)
    }

    #[test]
    fn without_shortfall_or_effects_every_droplet_adds_its_nominal_volume() {
        let (volume, _) = printed_volume(exact(Effects::none()), 2);
        assert!((volume - 2.0 * 36.0 * 7.6).abs() < 1e-9, "{volume}");
    }

    #[test]
    fn curing_shrinkage_removes_its_fraction_and_levelling_conserves_volume() {
        let shrink = Effects::none().with(Effect::CuringShrinkage, 0.1).unwrap();
        let (volume, _) = printed_volume(exact(shrink), 2);
        assert!((volume - 0.9 * 2.0 * 36.0 * 7.6).abs() < 1e-9);
        let flow = Effects::none().with(Effect::LevellingFlow, 0.2).unwrap();
        let (volume, smooth) = printed_volume(exact(flow), 2);
        let (_, rough) = printed_volume(exact(Effects::none()), 2);
        assert!((volume - 2.0 * 36.0 * 7.6).abs() < 1e-9);
        // Levelling moves material off the centre towards the rim.
        let centre = smooth.truth().grid.index(5, 5);
        assert!(smooth.truth().height_um[centre] < rough.truth().height_um[centre]);
    }

    #[test]
    fn volume_drift_and_tilt_follow_their_closed_forms() {
        let drift = Effects::none().with(Effect::VolumeDrift, 0.01).unwrap();
        // Layers 0, 1, 2 scaled by 1.00, 1.01, 1.02.
        let (volume, _) = printed_volume(exact(drift), 3);
        assert!((volume - 3.03 * 36.0 * 7.6).abs() < 1e-9);
        let tilt = Effects::none().with(Effect::SubstrateTilt, 2.0).unwrap();
        let (_, run) = printed_volume(exact(tilt), 0);
        let grid = run.truth().grid;
        // Cell (10, 4) lies 10 spacings = 2.63 mm along x: 5.27 µm up.
        assert!((run.truth().at(10, 4) - 2.0 * 10.0 * grid.spacing_um / 1000.0).abs() < 1e-12);
        assert_eq!(run.truth().at(0, 7), 0.0);
    }

    #[test]
    fn nozzle_bias_is_one_factor_per_column() {
        let bias = Effects::none().with(Effect::NozzleBias, 0.2).unwrap();
        let (_, run) = printed_volume(exact(bias), 1);
        let grid = run.truth().grid;
        // Interior cells of one column see the same droplets on both sides along y, so
        // two rows inside the square agree column by column, and columns differ.
        let row = |j: usize| (4..8).map(|i| run.truth().at(i, j)).collect::<Vec<_>>();
        assert_eq!(row(5), row(6));
        assert!(row(5).windows(2).any(|w| (w[0] - w[1]).abs() > 1e-6));
        assert_eq!(grid.m_x, 12);
    }

    #[test]
    fn unknown_effects_and_bad_strengths_are_rejected() {
        assert!(matches!(Effect::parse("warp"), Err(InkjetError::UnknownEffect { .. })));
        assert!(Effects::parse("levelling_flow=0.3").is_err(), "unstable diffusion number");
        assert!(Effects::parse("curing_shrinkage=-0.1").is_err());
        assert!(Effects::parse("curing_shrinkage=0.1,curing_shrinkage=0.2").is_err());
        assert!(Effects::parse("curing_shrinkage").is_err());
        let both = Effects::parse("volume_drift=0.002, curing_shrinkage=0.05").unwrap();
        assert_eq!(both.describe(), "curing_shrinkage=0.05,volume_drift=0.002");
        assert_eq!(Effects::parse(&both.describe()).unwrap(), both);
        assert_eq!(Effects::parse("none").unwrap().describe(), "none");
    }

    #[test]
    fn the_profiler_spot_averages_and_the_noise_has_its_std() {
        let grid = Grid::new(40, 40, 100.0).unwrap();
        let step =
            HeightMap { grid, height_um: (0..grid.len()).map(|c| (grid.coords(c).0 >= 20) as u8 as f64).collect() };
        let wide = Profiler { noise_um: 0.0, spot_sigma_um: 100.0 };
        let seen = wide.blur(&step);
        // A symmetric spot reads a step halfway between its two cells symmetrically.
        assert!((seen.at(19, 20) + seen.at(20, 20) - 1.0).abs() < 1e-12);
        assert!(seen.at(19, 20) > 0.1 && seen.at(20, 20) < 0.9);
        let flat = HeightMap::flat(grid, 3.0);
        assert!(wide.blur(&flat).height_um.iter().all(|h| (h - 3.0).abs() < 1e-12));
        let printer =
            TruthPrinter { profiler: Profiler { noise_um: 1.0, spot_sigma_um: 0.0 }, ..exact(Effects::none()) };
        let mut run = printer.start(grid, &mut ChaCha8Rng::seed_from_u64(1));
        let noise = run.measure().height_um;
        let var = noise.iter().map(|h| h * h).sum::<f64>() / noise.len() as f64;
        assert!((var.sqrt() - 1.0).abs() < 0.05, "{var}");
    }

    #[test]
    fn measuring_does_not_change_the_droplets_drawn() {
        let grid = Grid::new(10, 10, Grid::paper_spacing_um()).unwrap();
        let nominal = uniform_coeffs(grid, DropletCoeffs::paper_table1());
        let printer = TruthPrinter::paper(0.4);
        let mut a = printer.start(grid, &mut ChaCha8Rng::seed_from_u64(9));
        let mut b = printer.start(grid, &mut ChaCha8Rng::seed_from_u64(9));
        for _ in 0..3 {
            a.print_layer(&square(grid, 2, 7), &nominal).unwrap();
            b.measure();
            b.print_layer(&square(grid, 2, 7), &nominal).unwrap();
        }
        assert_eq!(a.truth(), b.truth());
    }
}
