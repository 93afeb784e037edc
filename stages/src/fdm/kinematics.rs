//! `fdm.kinematics`: the nozzle's motion along every measured line as the data's
//! authors assume it (paper 000 Sec. II-A, eq. 1): start at the jerk speed, constant
//! acceleration a = r_a·a0 to the feed F = r_F·F0, cruise, decelerate back to the jerk
//! speed at the line's end (no cruise when the line is too short).

use models::fdm::MotionPhase;
use pipeline::schema::Table;
use pipeline::stage::{Output, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use tables::fdm::kinematics;

use crate::fdm::lines::{fit_failed, PrinterLines};
use crate::roles;
use crate::table::{f64_col, frame, str_col};

/// The `fdm.kinematics` stage kind.
pub struct KinematicsStage;

pipeline::params! {
    /// The parameters of `fdm.kinematics`.
    pub struct KinematicsParams {
        /// Actual / commanded acceleration (eq. 1).
        pub r_a: f64 [0.5, 1.5] = 1.0,
        /// Actual / commanded feed (eq. 1).
        pub r_f: f64 [0.5, 1.5] = 1.0,
    }
}

impl Stage for KinematicsStage {
    type Params = KinematicsParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "fdm.kinematics",
        version: 1,
        summary:
            "Per measured sample: nominal time, speed, acceleration and motion phase of the nozzle → kinematics.parquet",
        implements: "paper 000 Sec. II-A, eq. 1 (trapezoidal motion, r_a, r_F)",
        inputs: &[roles::FDM_WIDTHS_MANY],
        output: Output::Tables,
    };
    const WRITES: &'static [&'static Table] = &[&kinematics::TABLE];

    fn run(&self, ctx: &mut StageContext, p: &KinematicsParams) -> Result<(), StageError> {
        let mut rows = KinematicRows::default();
        for input in ctx.inputs_of(&roles::FDM_WIDTHS_MANY) {
            let printer = PrinterLines::read(&input.dir)?;
            for (line, condition) in printer.lines.iter().zip(&printer.conditions) {
                let actual = line.nominal.scaled(p.r_a, p.r_f).map_err(|e| fit_failed(condition, e))?;
                rows.push(&printer.printer, condition, &actual.sample(&line.positions_mm));
            }
        }
        let mut table = rows.into_frame()?;
        ctx.write_table(kinematics::TABLE.name, &mut table)?;
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
            str_col(kinematics::printer, self.printer),
            str_col(kinematics::condition, self.condition),
            f64_col(kinematics::position_mm, self.position),
            f64_col(kinematics::time_s, self.time),
            f64_col(kinematics::speed_mm_s, self.speed),
            f64_col(kinematics::accel_mm_s2, self.accel),
            str_col(kinematics::phase, self.phase),
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
