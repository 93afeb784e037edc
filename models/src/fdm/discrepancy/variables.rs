//! The candidate variables the lag model's held-out residuals are shown against
//! (step 1 of DESIGN §7): where along the line, when, how fast, how hard the head
//! accelerates, how much flow is commanded, which of paper 000's five phases (Sec.
//! II-A), and the line's own feed and acceleration.
//!
//! The phases are located on each line's own measured profile, as the paper's fitting
//! procedure does, and are used for binning only: p1 until the measured width's
//! minimum on the acceleration ramp (bp1; only with a start blob), p2 until the end of
//! the acceleration (bp2), p3 until the width first reaches the line's steady width
//! (bp3, the median of its middle third), p4 until deceleration starts (bp4), p5 after.
//! The commanded flow is per unit layer height, `w_ref·v` with the data set's typical
//! steady width: `fdm-widths` records neither layer height nor nominal width, so it
//! bins like the speed.

use ::discrepancy::{Variable, VariableKind};

use super::{middle_widths, FdmLine, FdmModel};
use crate::fdm::fit::moving_average;

/// Labels of the phase variable.
pub const PHASES: [&str; 5] = ["p1", "p2", "p3", "p4", "p5"];

const fn continuous(name: &'static str, unit: &'static str) -> Variable {
    Variable { name, unit, kind: VariableKind::Continuous }
}

/// The variables, in the order [`values`] takes them.
pub static VARIABLES: [Variable; 9] = [
    continuous("position_mm", "mm"),
    continuous("time_since_start_s", "s"),
    continuous("time_before_end_s", "s"),
    continuous("speed_mm_s", "mm/s"),
    continuous("accel_mm_s2", "mm/s²"),
    continuous("commanded_flow_mm2_s", "mm²/s"),
    Variable { name: "phase", unit: "", kind: VariableKind::Categorical(&PHASES) },
    continuous("line_feed_mm_s", "mm/s"),
    continuous("line_accel_mm_s2", "mm/s²"),
];

/// The values of variable `variable` at every measurement of `group`.
pub fn values(model: &FdmModel, group: &FdmLine, variable: usize) -> Vec<f64> {
    let line = &group.line;
    let k = &line.nominal;
    let total = k.total_time_s();
    let each = |f: &dyn Fn(f64) -> f64| line.positions_mm.iter().map(|&x| f(x)).collect();
    match variable {
        0 => line.positions_mm.clone(),
        1 => each(&|x| k.time_at_position(x)),
        2 => each(&|x| total - k.time_at_position(x)),
        3 => each(&|x| k.speed_at_position(x)),
        4 => each(&|x| k.accel_at_position(x)),
        5 => each(&|x| model.reference_width_mm * k.speed_at_position(x)),
        6 => phases(group, model.has_start_blob),
        7 => vec![k.feed_mm_s; line.len()],
        _ => vec![k.accel_mm_s2; line.len()],
    }
}

/// Phase code (0 = p1 … 4 = p5) of every measurement.
fn phases(group: &FdmLine, has_start_blob: bool) -> Vec<f64> {
    let line = &group.line;
    let k = &line.nominal;
    let smooth = moving_average(&line.positions_mm, &line.widths_mm, 1.0);
    let (bp2, bp4) = (k.accel_end_mm(), k.decel_start_mm());
    let bp1 = if has_start_blob {
        line.positions_mm
            .iter()
            .zip(&smooth)
            .filter(|(x, _)| **x <= bp2)
            .min_by(|a, b| a.1.total_cmp(b.1))
            .map_or(0.0, |(x, _)| *x)
    } else {
        0.0
    };
    let steady = crate::stats::finite_median(middle_widths(line));
    let bp3 = line
        .positions_mm
        .iter()
        .zip(&smooth)
        .find(|(x, w)| **x >= bp2 && **w >= steady)
        .map_or(bp4, |(x, _)| x.min(bp4));
    line.positions_mm
        .iter()
        .map(|&x| {
            let code = if x < bp1 {
                0
            } else if x < bp2 {
                1
            } else if x < bp3 {
                2
            } else if x <= bp4 {
                3
            } else {
                4
            };
            code as f64
        })
        .collect()
}
