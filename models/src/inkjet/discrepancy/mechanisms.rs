//! The candidate causes of the ink-jet layer-height discrepancy: one per physical effect
//! the virtual printer can have that a layer-to-layer scan can show, and two it does
//! not have, so that the engine is not only choosing among true answers. Each has one
//! parameter; [`super::forward`] says exactly where it acts on eqs 2-7.
//!
//! Two of the printer's effects have no candidate of their own, for reasons of
//! identifiability, not omission:
//! - `substrate_tilt`: the model predicts each scan from the *measured* previous scan,
//!   which already contains the tilt, so the layer-to-layer increments carry no trace
//!   of it (the power study injects it to show exactly that);
//! - a droplet volume below nominal is, layer to layer, the same increment as curing
//!   shrinkage (both scale the fresh layer), so [`CURING_SHRINKAGE`] stands for both;
//!   its physics line says so.

pub use ::discrepancy::Candidate;
use ::discrepancy::{Mechanism, Parameter};

/// Index of curing shrinkage among the candidates.
pub const CURING_SHRINKAGE: usize = 0;
/// Index of volume drift.
pub const VOLUME_DRIFT: usize = 1;
/// Index of levelling flow.
pub const LEVELLING_FLOW: usize = 2;
/// Index of nozzle bias.
pub const NOZZLE_BIAS: usize = 3;
/// Index of the miscalibrated coefficient split (not in the virtual printer).
pub const COEFFICIENT_SPLIT: usize = 4;
/// Index of anisotropic spread (not in the virtual printer).
pub const ANISOTROPIC_SPREAD: usize = 5;

const fn one(name: &'static str, physics: &'static str, params: &'static [Parameter]) -> Candidate {
    Candidate::new(name, physics, params)
}

const fn linear(name: &'static str, unit: &'static str, lo: f64, hi: f64, meaning: &'static str) -> Parameter {
    Parameter::linear(name, unit, lo, hi, meaning)
}

static SHRINKAGE: [Parameter; 1] = [linear(
    "shrinkage",
    "1",
    -0.5,
    0.6,
    "fraction of the fresh layer's height lost on cure (negative: swelling or larger droplets)",
)];
static DRIFT: [Parameter; 1] =
    [linear("drift_per_layer", "1/layer", -0.02, 0.02, "relative change of the droplet volume per layer")];
static DIFFUSION: [Parameter; 1] =
    [linear("diffusion", "1", 0.0, 0.25, "diffusion number of the fresh layer before cure")];
static NOZZLE_STD: [Parameter; 1] =
    [linear("nozzle_std", "1", 0.0, 0.5, "spread (std) of the per-nozzle volume factors over the printed columns")];
static SPLIT: [Parameter; 1] = [linear("split", "1", -0.9, 1.0, "relative error of h2 and h3 at the droplet's volume")];
static ANISOTROPY: [Parameter; 1] =
    [linear("anisotropy", "1", -0.9, 0.9, "relative excess of the side share along x over y")];
/// Every candidate, in index order.
pub static CANDIDATES: [Candidate; 6] = [
    one(
        "curing_shrinkage",
        "each fresh layer loses a fixed fraction of its height when cured (layer to layer the same as droplets below their nominal volume)",
        &SHRINKAGE,
    ),
    one(
        "volume_drift",
        "the droplet volume changes linearly with the layer index (ink warming, a head drying out)",
        &DRIFT,
    ),
    one(
        "levelling_flow",
        "before cure the fresh layer flows once by diffusion over side neighbours, Δ ← Δ + D·∇²Δ, conserving volume",
        &DIFFUSION,
    ),
    one(
        "nozzle_bias",
        "each nozzle (grid column) prints every droplet with its own fixed volume factor, fitted per column",
        &NOZZLE_STD,
    ),
    one(
        "coefficient_split",
        "the droplet volume splits between its own cell and its neighbours otherwise than h1, h2, h3 say (h2, h3 scaled, h1 keeps the rest)",
        &SPLIT,
    ),
    one(
        "anisotropic_spread",
        "a droplet spreads more along x than along y (print direction, substrate texture): side shares h2(1 ± a)",
        &ANISOTROPY,
    ),
];

/// The candidates as the engine sees them.
pub static MECHANISMS: [&dyn Mechanism; 6] =
    [&CANDIDATES[0], &CANDIDATES[1], &CANDIDATES[2], &CANDIDATES[3], &CANDIDATES[4], &CANDIDATES[5]];

/// The candidate called `name`, by index.
pub fn candidate_index(name: &str) -> Option<usize> {
    CANDIDATES.iter().position(|c| c.name() == name)
}
