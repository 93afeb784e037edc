//! `thermal.generate_sequence`: the virtual extrusion printer with its nozzle-mounted
//! thermal camera (DESIGN §5.3, `datasets::thermal`) prints and films the corner test
//! path; the stage's output folder *is* the `thermal-sequence` dataset (DESIGN §4), so
//! the analysis stages downstream read it exactly as they would read a measured one.

use datasets::thermal::effects::Effects;
use datasets::thermal::{generate_into_observed, GenerateConfig, LeptonHabits};

use pipeline::params::ParamError;
use pipeline::stage::{Output, Stage, StageInfo};
use pipeline::{StageContext, StageError};

use crate::progress::StageProgress;

/// The `thermal.generate_sequence` stage kind.
pub struct GenerateSequenceStage;

pipeline::params! {
    /// The parameters of `thermal.generate_sequence`.
    pub struct GenerateSequenceParams {
        /// Layers printed and filmed (the paper's one-layer verification print films one; its part has 20).
        pub layers: i64 [1, 20] = 1,
        /// Extra physical effects as `name=strength` pairs separated by commas (camera_latency, tau_mismatch, heat_diffusion_widening, layer_heat_accumulation, melt_squeeze_out); empty: none.
        pub effects: String = "",
        /// Let the camera repeat frames and freeze ~0.9 s for its shutter, as real FLIR Leptons do (DESIGN §5.3).
        pub lepton_habits: bool = false,
    }
}

impl Stage for GenerateSequenceStage {
    type Params = GenerateSequenceParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "thermal.generate_sequence",
        version: 6,
        summary:
            "Virtual extrusion printer + nozzle-mounted thermal camera → a thermal-sequence dataset (the output folder)",
        implements: "DESIGN §5.3; paper 003 Tables 1-2, Fig. 7, eqs 28 and 34",
        inputs: &[],
        output: Output::Dataset("thermal-sequence"),
    };

    fn check(p: &GenerateSequenceParams) -> Result<(), ParamError> {
        parse_effects(&p.effects).map(|_| ()).map_err(|message| ParamError::new("effects", message))
    }

    fn run(&self, ctx: &mut StageContext, p: &GenerateSequenceParams) -> Result<(), StageError> {
        let effects =
            parse_effects(&p.effects).map_err(|message| StageError::Params { stage: ctx.stage.clone(), message })?;
        let config = GenerateConfig {
            seed: ctx.seed,
            layers: p.layers as usize,
            effects,
            lepton_habits: LeptonHabits { repeated_frames: p.lepton_habits, shutter_freeze: p.lepton_habits },
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
