//! The straight printed lines of a print: consecutive collinear extruding XY moves at
//! one height and under one pressure advance, with the speed profile the planner
//! ([`super::planner`]) commanded along them. A photo shows a line's width; a width
//! model needs, along the line, the commanded speed, the time and the filament per mm.
//!
//! A line ends at a corner (a direction change of more than [`COLLINEAR_TOLERANCE_RAD`]),
//! a move that does not extrude (travel, retraction, prime), a Z change or a change of
//! pressure advance. Its nominal width is mass conservation with a rectangular bead,
//! `w = (π d²/4)·(filament per mm) / h`, with `h` the line's z minus the z of the next
//! lower layer that extrudes (or z itself on the first layer).

use std::f64::consts::PI;

use super::planner::{Move, PlannedMove, PressureAdvance};

/// Largest angle between two moves' directions that still continues a line (rad):
/// G-code written to 3 decimals turns a straight 20 mm line by up to about 1e-4 rad.
pub const COLLINEAR_TOLERANCE_RAD: f64 = 1e-3;

/// Heights closer than this are one layer (mm).
const SAME_Z_MM: f64 = 1e-6;

/// One move of a printed line.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LineMove {
    /// Index of the move in the G-code's move list.
    pub move_index: usize,
    /// Where the move starts along the line (mm).
    pub start_along_mm: f64,
    /// When the move starts, from the line's start (s).
    pub start_time_s: f64,
    /// Filament per mm of path (mm/mm).
    pub filament_per_mm: f64,
    /// Its planned trapezoid: length, entry, cruise and exit speed, accel, duration.
    pub planned: PlannedMove,
}

/// One straight printed line.
#[derive(Debug, Clone, PartialEq)]
pub struct PrintedLine {
    /// Index among the print's lines, 0-based, in G-code order.
    pub index: usize,
    /// Start (x, y) on the bed (mm).
    pub start_mm: [f64; 2],
    /// End (x, y) on the bed (mm).
    pub end_mm: [f64; 2],
    /// Height of the nozzle (mm).
    pub z_mm: f64,
    /// z minus the next lower extruding layer's z, or z on the first layer (mm).
    pub layer_height_mm: f64,
    /// Its moves, in print order.
    pub moves: Vec<LineMove>,
    /// The pressure advance in force.
    pub pressure_advance: PressureAdvance,
    /// Filament volume per mm of line over the layer height (mm).
    pub nominal_width_mm: f64,
}

impl PrintedLine {
    /// Length of the line (mm).
    pub fn length_mm(&self) -> f64 {
        self.moves.last().map_or(0.0, |m| m.start_along_mm + m.planned.length_mm)
    }

    /// Time the line takes (s).
    pub fn duration_s(&self) -> f64 {
        self.moves.last().map_or(0.0, |m| m.start_time_s + m.planned.duration_s)
    }

    /// Print direction (unit x, y).
    pub fn direction(&self) -> [f64; 2] {
        let (dx, dy) = (self.end_mm[0] - self.start_mm[0], self.end_mm[1] - self.start_mm[1]);
        let n = dx.hypot(dy);
        [dx / n, dy / n]
    }

    /// The move under `along_mm` (clamped to the line).
    fn move_at(&self, along_mm: f64) -> &LineMove {
        let k = self.moves.partition_point(|m| m.start_along_mm <= along_mm);
        &self.moves[k.saturating_sub(1)]
    }

    /// Commanded speed at `along_mm` from the line's start (mm/s).
    pub fn speed_at_mm(&self, along_mm: f64) -> f64 {
        let m = self.move_at(along_mm);
        m.planned.speed_at_mm(along_mm - m.start_along_mm)
    }

    /// Time from the line's start to `along_mm` (s).
    pub fn time_at_mm(&self, along_mm: f64) -> f64 {
        let m = self.move_at(along_mm);
        m.start_time_s + m.planned.time_at_mm(along_mm - m.start_along_mm)
    }

    /// Filament per mm of path at `along_mm` (mm/mm).
    pub fn filament_per_mm_at(&self, along_mm: f64) -> f64 {
        self.move_at(along_mm).filament_per_mm
    }
}

/// Every straight printed line of `moves` (as planned in `planned`, one per move), with
/// filament of `filament_diameter_mm`.
pub fn printed_lines(moves: &[Move], planned: &[PlannedMove], filament_diameter_mm: f64) -> Vec<PrintedLine> {
    let layers = extruding_layers_mm(moves);
    let area_mm2 = PI * filament_diameter_mm.powi(2) / 4.0;
    let mut lines: Vec<PrintedLine> = Vec::new();
    let mut current: Option<PrintedLine> = None;
    for (i, (m, p)) in moves.iter().zip(planned).enumerate() {
        if !is_printing(m) {
            lines.extend(current.take());
            continue;
        }
        if let Some(line) = current.as_mut().filter(|l| continues(l, m)) {
            push_move(line, i, m, p);
            continue;
        }
        lines.extend(current.take());
        current = Some(new_line(lines.len(), i, m, p, &layers));
    }
    lines.extend(current);
    for line in &mut lines {
        let filament_mm: f64 = line.moves.iter().map(|m| m.filament_per_mm * m.planned.length_mm).sum();
        line.nominal_width_mm = area_mm2 * filament_mm / line.length_mm() / line.layer_height_mm;
    }
    lines
}

/// An XY move at constant height that pushes filament.
fn is_printing(m: &Move) -> bool {
    let xy = (m.end_mm[0] - m.start_mm[0]).hypot(m.end_mm[1] - m.start_mm[1]);
    m.filament_mm > 0.0 && xy > super::planner::MIN_LENGTH_MM && (m.end_mm[2] - m.start_mm[2]).abs() < SAME_Z_MM
}

fn continues(line: &PrintedLine, m: &Move) -> bool {
    let d = line.direction();
    let (dx, dy) = (m.end_mm[0] - m.start_mm[0], m.end_mm[1] - m.start_mm[1]);
    let n = dx.hypot(dy);
    let (cos, sin) = ((d[0] * dx + d[1] * dy) / n, (d[0] * dy - d[1] * dx) / n);
    let joined = (m.start_mm[0] - line.end_mm[0]).hypot(m.start_mm[1] - line.end_mm[1]) < SAME_Z_MM;
    joined
        && cos > 0.0
        && sin.atan2(cos).abs() <= COLLINEAR_TOLERANCE_RAD
        && (m.start_mm[2] - line.z_mm).abs() < SAME_Z_MM
        && m.pressure_advance == line.pressure_advance
}

fn push_move(line: &mut PrintedLine, move_index: usize, m: &Move, p: &PlannedMove) {
    line.moves.push(LineMove {
        move_index,
        start_along_mm: line.length_mm(),
        start_time_s: line.duration_s(),
        filament_per_mm: m.filament_per_mm(),
        planned: *p,
    });
    line.end_mm = [m.end_mm[0], m.end_mm[1]];
}

fn new_line(index: usize, move_index: usize, m: &Move, p: &PlannedMove, layers: &[f64]) -> PrintedLine {
    let z_mm = m.start_mm[2];
    let below = layers.iter().rev().find(|&&z| z < z_mm - SAME_Z_MM);
    let mut line = PrintedLine {
        index,
        start_mm: [m.start_mm[0], m.start_mm[1]],
        end_mm: [m.start_mm[0], m.start_mm[1]],
        z_mm,
        layer_height_mm: below.map_or(z_mm, |z| z_mm - z),
        moves: Vec::new(),
        pressure_advance: m.pressure_advance,
        nominal_width_mm: 0.0,
    };
    push_move(&mut line, move_index, m, p);
    line
}

/// The heights at which something is printed, ascending (mm).
fn extruding_layers_mm(moves: &[Move]) -> Vec<f64> {
    let mut zs: Vec<f64> = moves.iter().filter(|m| is_printing(m)).map(|m| m.start_mm[2]).collect();
    zs.sort_by(f64::total_cmp);
    zs.dedup_by(|a, b| (*a - *b).abs() < SAME_Z_MM);
    zs
}

#[cfg(test)]
mod tests {
    use super::super::planner::{plan, Cornering, MotionLimits};
    use super::*;

    const LIMITS: MotionLimits = MotionLimits {
        accel_mm_s2: 1000.0,
        accel_to_decel_mm_s2: 500.0,
        max_velocity_mm_s: f64::INFINITY,
        cornering: Cornering::SquareCorner { velocity_mm_s: 5.0, extruder_corner_mm_s: 1.0 },
    };

    /// A tool that moves to (x, y, z) at a feed, extruding `e_per_mm`.
    struct Tool {
        at: [f64; 3],
        moves: Vec<Move>,
        pa: PressureAdvance,
    }

    impl Tool {
        fn new() -> Self {
            Self { at: [0.0, 0.0, 0.2], moves: Vec::new(), pa: PressureAdvance { advance_s: 0.0, smooth_time_s: 0.04 } }
        }

        fn go(&mut self, x: f64, y: f64, z: f64, feed_mm_s: f64, e_per_mm: f64) -> &mut Self {
            let end_mm = [x, y, z];
            let length = (x - self.at[0]).hypot(y - self.at[1]);
            let m = Move {
                start_mm: self.at,
                end_mm,
                filament_mm: e_per_mm * length,
                feed_mm_s,
                limits: LIMITS,
                pressure_advance: self.pa,
            };
            self.moves.push(m);
            self.at = end_mm;
            self
        }

        fn lines(&self) -> Vec<PrintedLine> {
            printed_lines(&self.moves, &plan(&self.moves).unwrap(), 1.75)
        }
    }

    #[test]
    fn a_frame_gives_four_lines() {
        let mut t = Tool::new();
        t.go(10.0, 10.0, 0.2, 100.0, 0.0);
        for (x, y) in [(50.0, 10.0), (50.0, 80.0), (10.0, 80.0), (10.0, 10.0)] {
            t.go(x, y, 0.2, 20.0, 0.05);
        }
        let lines = t.lines();
        assert_eq!(lines.len(), 4);
        assert_eq!((lines[1].start_mm, lines[1].end_mm), ([50.0, 10.0], [50.0, 80.0]));
        assert_eq!(lines.iter().map(|l| l.index).collect::<Vec<_>>(), [0, 1, 2, 3]);
        // Each corner is passed at the square-corner velocity.
        assert!((lines[1].speed_at_mm(0.0) - 5.0).abs() < 1e-9);
        // The travel turns by 45° into the first edge: faster than at 90°, and at most
        // the extruder's 1 mm/s / 0.05 mm/mm as the flow starts.
        let v0 = lines[0].speed_at_mm(0.0);
        assert!(v0 > 5.0 && v0 <= 20.0, "{v0}");
    }

    #[test]
    fn slow_fast_slow_is_one_line_of_three_moves() {
        let mut t = Tool::new();
        t.go(2.0, 8.0, 0.2, 100.0, 0.0);
        t.pa.advance_s = 0.035;
        t.go(5.88, 8.0, 0.2, 10.0, 0.08).go(29.16, 8.0, 0.2, 100.0, 0.08).go(40.8, 8.0, 0.2, 10.0, 0.08);
        let lines = t.lines();
        assert_eq!(lines.len(), 1);
        let line = &lines[0];
        assert_eq!(line.moves.len(), 3);
        assert_eq!(line.pressure_advance.advance_s, 0.035);
        assert!((line.length_mm() - 38.8).abs() < 1e-9);
        assert!((line.moves[1].start_along_mm - 3.88).abs() < 1e-9);
        assert!((line.speed_at_mm(15.0) - 100.0).abs() < 1e-9);
        assert!((line.speed_at_mm(2.0) - 10.0).abs() < 1e-9);
        // The joints run at the slow feed; time is continuous across them.
        assert!((line.speed_at_mm(3.88) - 10.0).abs() < 1e-9);
        let t_joint = line.time_at_mm(3.88);
        assert!((t_joint - line.moves[1].start_time_s).abs() < 1e-12);
        assert!(line.time_at_mm(3.87) < t_joint && t_joint < line.time_at_mm(3.89));
        // w = (π·1.75²/4)·0.08 / 0.2 mm.
        assert!((line.nominal_width_mm - PI * 1.75f64.powi(2) / 4.0 * 0.4).abs() < 1e-9);
        assert_eq!(line.layer_height_mm, 0.2);
    }

    #[test]
    fn travel_z_change_and_pressure_advance_break_lines() {
        let mut t = Tool::new();
        t.go(10.0, 0.0, 0.2, 20.0, 0.05).go(12.0, 0.0, 0.2, 100.0, 0.0).go(20.0, 0.0, 0.2, 20.0, 0.05);
        t.pa.advance_s = 0.05;
        t.go(30.0, 0.0, 0.2, 20.0, 0.05);
        t.go(30.0, 0.0, 0.5, 10.0, 0.0).go(40.0, 0.0, 0.5, 20.0, 0.05);
        let lines = t.lines();
        assert_eq!(lines.len(), 4, "{lines:?}");
        assert_eq!(lines[3].z_mm, 0.5);
        assert!((lines[3].layer_height_mm - 0.3).abs() < 1e-12);
    }
}
