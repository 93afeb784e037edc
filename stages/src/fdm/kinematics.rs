//! `fdm.kinematics`: the nozzle's motion along every measured line as the data's
//! authors assume it (paper 000 Sec. II-A, eq. 1): start at the jerk speed, constant
//! acceleration a = r_a·a0 to the feed F = r_F·F0, cruise, decelerate back to the jerk
//! speed at the line's end (no cruise when the line is too short).

use models::fdm::MotionPhase;
use pipeline::params::ParamDefault;
use pipeline::stage::Arity;
use pipeline::{ParamSpec, ParamType, StageContext, StageError, StageKind};

use crate::fdm::lines::{fit_failed, PrinterLines};
use crate::table::{f64_col, frame, str_col};

/// The `fdm.kinematics` stage kind.
pub struct KinematicsStage;

const R: ParamType = ParamType::Float { min: 0.5, max: 1.5 };

const PARAMS: &[ParamSpec] = &[
    ParamSpec {
        name: "r_a",
        ty: R,
        default: ParamDefault::Float(1.0),
        doc: "Actual / commanded acceleration (eq. 1).",
    },
    ParamSpec { name: "r_f", ty: R, default: ParamDefault::Float(1.0), doc: "Actual / commanded feed (eq. 1)." },
];

impl StageKind for KinematicsStage {
    fn name(&self) -> &'static str {
        "fdm.kinematics"
    }
    fn version(&self) -> u32 {
        1
    }
    fn summary(&self) -> &'static str {
        "Per measured sample: nominal time, speed, acceleration and motion phase of the nozzle → kinematics.parquet"
    }
    fn implements(&self) -> &'static str {
        "paper 000 Sec. II-A, eq. 1 (trapezoidal motion, r_a, r_F)"
    }
    fn params(&self) -> &'static [ParamSpec] {
        PARAMS
    }
    fn arity(&self) -> Arity {
        Arity::at_least(1)
    }

    fn run(&self, ctx: &mut StageContext) -> Result<(), StageError> {
        let (r_a, r_f) = (ctx.params.f64("r_a"), ctx.params.f64("r_f"));
        let mut rows = KinematicRows::default();
        for input in &ctx.inputs {
            let printer = PrinterLines::read(&input.dir)?;
            for (line, condition) in printer.lines.iter().zip(&printer.conditions) {
                let actual = line.nominal.scaled(r_a, r_f).map_err(|e| fit_failed(condition, e))?;
                rows.push(&printer.printer, condition, &actual.sample(&line.positions_mm));
            }
        }
        let mut table = rows.into_frame()?;
        ctx.write_table("kinematics", &mut table)?;
        Ok(())
    }
}

#[derive(Default)]
struct KinematicRows {
    printer: Vec<String>,
    condition: Vec<String>,
    position: Vec<f64>,
    time: Vec<f64>,
    speed: Vec<f64>,
    accel: Vec<f64>,
    phase: Vec<String>,
}

impl KinematicRows {
    fn push(&mut self, printer: &str, condition: &str, s: &models::fdm::KinematicSamples) {
        let n = s.positions_mm.len();
        self.printer.extend(std::iter::repeat_n(printer.to_string(), n));
        self.condition.extend(std::iter::repeat_n(condition.to_string(), n));
        self.position.extend_from_slice(&s.positions_mm);
        self.time.extend_from_slice(&s.time_s);
        self.speed.extend_from_slice(&s.speed_mm_s);
        self.accel.extend_from_slice(&s.accel_mm_s2);
        self.phase.extend(s.phase.iter().map(|p| phase_name(*p).to_string()));
    }

    fn into_frame(self) -> Result<polars::prelude::DataFrame, StageError> {
        frame(vec![
            str_col("printer", self.printer),
            str_col("condition", self.condition),
            f64_col("position_mm", self.position),
            f64_col("time_s", self.time),
            f64_col("speed_mm_s", self.speed),
            f64_col("accel_mm_s2", self.accel),
            str_col("phase", self.phase),
        ])
    }
}

/// The phase as written in tables.
pub fn phase_name(phase: MotionPhase) -> &'static str {
    match phase {
        MotionPhase::Accelerating => "accelerating",
        MotionPhase::Cruise => "cruise",
        MotionPhase::Decelerating => "decelerating",
    }
}
