//! `thermal.generate_sequence`: the virtual extrusion printer with its nozzle-mounted
//! thermal camera (DESIGN §5.3, `datasets::thermal`) prints and films the corner test
//! path; the stage's output folder *is* the `thermal-sequence` dataset (DESIGN §4), so
//! the analysis stages downstream read it exactly as they would read a measured one.

use datasets::thermal::effects::Effects;
use datasets::thermal::{generate_into_observed, GenerateConfig, LeptonHabits};

use crate::progress::StageProgress;
use pipeline::params::ParamDefault;
use pipeline::stage::Arity;
use pipeline::{ParamSpec, ParamType, StageContext, StageError, StageKind};

/// The `thermal.generate_sequence` stage kind.
pub struct GenerateSequenceStage;

const PARAMS: &[ParamSpec] = &[
    ParamSpec {
        name: "layers",
        ty: ParamType::Int { min: 1, max: 20 },
        default: ParamDefault::Int(1),
        doc: "Layers printed and filmed (the paper's one-layer verification print films one; its part has 20).",
    },
    ParamSpec {
        name: "effects",
        ty: ParamType::Text,
        default: ParamDefault::Str(""),
        doc: "Extra physical effects as `name=strength` pairs separated by commas (camera_latency, tau_mismatch, heat_diffusion_widening, layer_heat_accumulation, melt_squeeze_out); empty: none.",
    },
    ParamSpec {
        name: "lepton_habits",
        ty: ParamType::Bool,
        default: ParamDefault::Bool(false),
        doc: "Let the camera repeat frames and freeze ~0.9 s for its shutter, as real FLIR Leptons do (DESIGN §5.3).",
    },
];

impl StageKind for GenerateSequenceStage {
    fn name(&self) -> &'static str {
        "thermal.generate_sequence"
    }
    fn version(&self) -> u32 {
        6
    }
    fn summary(&self) -> &'static str {
        "Virtual extrusion printer + nozzle-mounted thermal camera → a thermal-sequence dataset (the output folder)"
    }
    fn implements(&self) -> &'static str {
        "DESIGN §5.3; paper 003 Tables 1-2, Fig. 7, eqs 28 and 34"
    }
    fn params(&self) -> &'static [ParamSpec] {
        PARAMS
    }
    fn arity(&self) -> Arity {
        Arity::exactly(0)
    }

    fn run(&self, ctx: &mut StageContext) -> Result<(), StageError> {
        let effects = parse_effects(ctx.params.str("effects"))
            .map_err(|message| StageError::Params { stage: ctx.stage.clone(), message })?;
        let habits = ctx.params.bool("lepton_habits");
        let config = GenerateConfig {
            seed: ctx.seed,
            layers: ctx.params.i64("layers") as usize,
            effects,
            lepton_habits: LeptonHabits { repeated_frames: habits, shutter_freeze: habits },
        };
        generate_into_observed(&config, ctx.output_dir(), &StageProgress::new(ctx)).map_err(StageError::domain)?;
        Ok(())
    }
}

/// Parses `name=strength, name=strength` into checked effects.
pub fn parse_effects(text: &str) -> Result<Effects, String> {
    Effects::from_pairs(crate::effects::pairs(text)?).map_err(|e| format!("effects: {e}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn effects_parse_and_reject_unknown_names() {
        let effects = parse_effects("camera_latency=0.02, tau_mismatch=0.3").unwrap();
        assert_eq!(effects.camera_latency_s, 0.02);
        assert_eq!(effects.tau_mismatch, 0.3);
        assert_eq!(parse_effects("").unwrap(), Effects::none());
        assert!(parse_effects("gravity=1").is_err());
        assert!(parse_effects("camera_latency").is_err());
        assert!(parse_effects("camera_latency=fast").is_err());
    }
}
