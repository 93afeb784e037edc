//! Reading the G-code of a photographed print into the moves the firmware planned
//! ([`models::fdm::planner::Move`]), each with the limits and the pressure advance in
//! force when it was read.
//!
//! Read: `G0`/`G1` (X Y Z E F, F in mm/min), `G90`/`G91` (G91 makes E relative too, as
//! in Marlin and Klipper), `M82`/`M83`, `G92` (E and axes; without words it zeroes all,
//! and the machine position does not move: later moves are offset), `G21` (`G20`,
//! inches, is refused), `G28` (homing: the named axes, or all, at 0), `M220 S` (speed
//! factor), `M221 S` (flow factor), `M204` (Klipper: S, or the smaller of P and T;
//! Marlin: P or S for moves that extrude, T or S for travels), and per firmware:
//! Marlin's `M205 X Y Z` (classic jerk) and `M205 J` (switches to junction deviation),
//! `M900 K` (linear advance, s); Klipper's extended commands `SET_PRESSURE_ADVANCE
//! ADVANCE= SMOOTH_TIME=` and `SET_VELOCITY_LIMIT VELOCITY= ACCEL=
//! SQUARE_CORNER_VELOCITY= MINIMUM_CRUISE_RATIO= ACCEL_TO_DECEL=` (the last as the
//! ratio `1 − ACCEL_TO_DECEL/ACCEL`, as Klipper converts it). A command the other
//! firmware would not know (Klipper has no `M205`, Marlin no `SET_…`) is ignored as that
//! firmware ignores it. Comments (`;`, `( )`), blank lines, `N` line numbers and `*`
//! checksums are skipped; every other command is ignored and counted in
//! [`GcodeProgram::ignored`] — except arcs (`G2`/`G3`), which would move the nozzle
//! where this reader cannot follow, and are refused.
//!
//! Why not the `gcode` crate (0.7.0, tried): it fails on Klipper's extended commands and
//! on text arguments (`M117 Hello`), so every line would have to be sorted before it,
//! its diagnostics give byte spans rather than what was expected, and it reads
//! `X-1.5e1` as X −1.5 followed by a word `e1`, an extrusion, without a word. The words
//! of a G-code line are simple enough to read here (letter, number), and this reader
//! refuses such an exponent.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use models::fdm::planner::{Cornering, MotionLimits, Move, PressureAdvance};

use crate::error::DatasetError;
use crate::limits::{MAX_GCODE_BYTES, MAX_GCODE_COORDINATE_MM, MAX_GCODE_MOVES};

/// The firmware that ran the G-code: which commands mean what, how joints are planned.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Firmware {
    /// Klipper: square-corner velocity, minimum cruise ratio, pressure advance.
    Klipper,
    /// Marlin: classic jerk (or junction deviation after `M205 J`), linear advance.
    Marlin,
}

/// The printer's settings where the G-code starts, before any command changes them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StartSettings {
    /// The firmware.
    pub firmware: Firmware,
    /// Acceleration (mm/s²).
    pub accel_mm_s2: f64,
    /// Klipper's square-corner velocity (mm/s).
    pub square_corner_velocity_mm_s: f64,
    /// Klipper's minimum cruise ratio (0 to < 1; Klipper's default 0.5).
    pub minimum_cruise_ratio: f64,
    /// Klipper's `max_velocity` (mm/s); infinite for none.
    pub max_velocity_mm_s: f64,
    /// Klipper's extruder `instantaneous_corner_velocity` (mm/s; default 1).
    pub extruder_corner_mm_s: f64,
    /// Marlin's classic X and Y jerk (mm/s).
    pub jerk_mm_s: f64,
    /// Marlin's Z jerk (mm/s; Marlin's default 0.3).
    pub jerk_z_mm_s: f64,
    /// Pressure (linear) advance (s).
    pub pressure_advance_s: f64,
    /// Klipper's pressure-advance smooth time (s; 0 for Marlin).
    pub smooth_time_s: f64,
}

/// The moves of a G-code file and what was read around them.
#[derive(Debug, Clone, PartialEq)]
pub struct GcodeProgram {
    /// Every move (XYZ or E changes), in order.
    pub moves: Vec<Move>,
    /// The 1-based line of each move.
    pub move_lines: Vec<usize>,
    /// Commands ignored: command → (count, first line).
    pub ignored: BTreeMap<String, (usize, usize)>,
    /// Settings the G-code sets (`accel`, `square_corner_velocity`, `jerk`,
    /// `pressure_advance`, `smooth_time`, …) → the first line that sets it.
    pub sets: BTreeMap<&'static str, usize>,
}

/// A G-code line that cannot be read, or a file beyond the bounds.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GcodeError {
    /// A line is not what the reader expects.
    #[error("{}:line {line}: {expected}", file.display())]
    Line {
        /// The file.
        file: PathBuf,
        /// 1-based line.
        line: usize,
        /// What was expected and what was found.
        expected: String,
    },
    /// The file is larger than [`MAX_GCODE_BYTES`] or has more than [`MAX_GCODE_MOVES`].
    #[error("{}: {what}", file.display())]
    TooLarge {
        /// The file.
        file: PathBuf,
        /// Which bound, and the value.
        what: String,
    },
}

impl From<GcodeError> for DatasetError {
    fn from(e: GcodeError) -> Self {
        match e {
            GcodeError::Line { file, line, expected } => DatasetError::at_line(file, line, expected),
            GcodeError::TooLarge { file, what } => DatasetError::Malformed { file, location: None, expected: what },
        }
    }
}

/// The machine's state as the G-code runs.
struct State {
    start: StartSettings,
    position_mm: [f64; 3],
    offset_mm: [f64; 3],
    e_mm: f64,
    feed_mm_s: f64,
    absolute_xyz: bool,
    absolute_e: bool,
    speed_factor: f64,
    flow_factor: f64,
    accel_mm_s2: f64,
    travel_accel_mm_s2: f64,
    minimum_cruise_ratio: f64,
    max_velocity_mm_s: f64,
    square_corner_velocity_mm_s: f64,
    jerk_mm_s: [f64; 3],
    junction_deviation_mm: Option<f64>,
    pressure_advance: PressureAdvance,
}

/// Reads the G-code `text` of `file` (named in errors), starting from `start`.
pub fn read_gcode(file: &Path, text: &str, start: StartSettings) -> Result<GcodeProgram, GcodeError> {
    if text.len() > MAX_GCODE_BYTES {
        let what = format!("expected at most {MAX_GCODE_BYTES} bytes of G-code, got {}", text.len());
        return Err(GcodeError::TooLarge { file: file.to_path_buf(), what });
    }
    let mut state = State::new(start);
    let mut program =
        GcodeProgram { moves: Vec::new(), move_lines: Vec::new(), ignored: BTreeMap::new(), sets: BTreeMap::new() };
    for (i, raw) in text.lines().enumerate() {
        let line = i + 1;
        let err = |expected: String| GcodeError::Line { file: file.to_path_buf(), line, expected };
        let body = strip_line(raw);
        if body.is_empty() {
            continue;
        }
        let mut reader = LineReader { state: &mut state, program: &mut program, line };
        reader.command(&body).map_err(err)?;
        if program.moves.len() > MAX_GCODE_MOVES {
            let what = format!("expected at most {MAX_GCODE_MOVES} moves, line {line} makes more");
            return Err(GcodeError::TooLarge { file: file.to_path_buf(), what });
        }
    }
    Ok(program)
}

/// The command part of a line: comments, a leading `N…` and a trailing `*…` removed.
fn strip_line(raw: &str) -> String {
    let mut body = String::with_capacity(raw.len());
    let mut in_paren = false;
    for c in raw.chars() {
        match c {
            ';' if !in_paren => break,
            '(' => in_paren = true,
            ')' if in_paren => in_paren = false,
            _ if !in_paren => body.push(c),
            _ => {}
        }
    }
    let mut body = body.trim();
    if let Some(star) = body.rfind('*') {
        if body[star + 1..].trim().chars().all(|c| c.is_ascii_digit()) {
            body = body[..star].trim_end();
        }
    }
    let first = body.split_whitespace().next().unwrap_or("");
    if first.len() > 1 && first.starts_with(['N', 'n']) && first[1..].chars().all(|c| c.is_ascii_digit()) {
        body = body[first.len()..].trim_start();
    }
    body.to_string()
}

struct LineReader<'a> {
    state: &'a mut State,
    program: &'a mut GcodeProgram,
    line: usize,
}

impl LineReader<'_> {
    fn command(&mut self, body: &str) -> Result<(), String> {
        let (head, rest) = body.split_once(char::is_whitespace).unwrap_or((body, ""));
        let name = head.to_ascii_uppercase();
        let firmware = self.state.start.firmware;
        match (name.as_str(), firmware) {
            ("G0" | "G00" | "G1" | "G01", _) => self.linear_move(&words(rest)?),
            ("G2" | "G02" | "G3" | "G03", _) => {
                Err(format!("expected straight moves, got the arc `{name}` (G2/G3 are not read: slice without arcs)"))
            }
            ("G90" | "G91", _) => {
                self.state.absolute_xyz = name == "G90";
                Ok(())
            }
            ("M82" | "M83", _) => {
                self.state.absolute_e = name == "M82";
                Ok(())
            }
            ("G92", _) => self.set_position(&words(rest)?),
            ("G21", _) => Ok(()),
            ("G20", _) => Err("expected millimetres (G21), got G20 (inches are not read)".into()),
            ("G28", _) => self.home(&words(rest)?),
            ("M220", _) => self.factor(&words(rest)?, true),
            ("M221", _) => self.factor(&words(rest)?, false),
            ("M204", _) => self.m204(&words(rest)?),
            ("M205", Firmware::Marlin) => self.m205(&words(rest)?),
            ("M900", Firmware::Marlin) => self.m900(&words(rest)?),
            ("SET_PRESSURE_ADVANCE", Firmware::Klipper) => self.set_pressure_advance(&parameters(rest)?),
            ("SET_VELOCITY_LIMIT", Firmware::Klipper) => self.set_velocity_limit(&parameters(rest)?),
            _ => {
                let entry = self.program.ignored.entry(name).or_insert((0, self.line));
                entry.0 += 1;
                Ok(())
            }
        }
    }

    fn note(&mut self, setting: &'static str) {
        self.program.sets.entry(setting).or_insert(self.line);
    }

    fn linear_move(&mut self, words: &[(char, f64)]) -> Result<(), String> {
        let s = &mut *self.state;
        let mut end = s.position_mm;
        let mut filament_mm = 0.0;
        for &(letter, value) in words {
            match letter {
                'X' | 'Y' | 'Z' => {
                    let k = (letter as u8 - b'X') as usize;
                    let logical = if s.absolute_xyz { value } else { end[k] - s.offset_mm[k] + value };
                    end[k] = check_coordinate(letter, logical + s.offset_mm[k])?;
                }
                'E' => {
                    let relative = !s.absolute_xyz || !s.absolute_e;
                    filament_mm = if relative { value } else { value - s.e_mm };
                    s.e_mm = if relative { s.e_mm + value } else { value };
                }
                'F' => s.feed_mm_s = positive('F', value)? / 60.0,
                _ => {}
            }
        }
        if end == s.position_mm && filament_mm == 0.0 {
            return Ok(());
        }
        let mv = Move {
            start_mm: s.position_mm,
            end_mm: end,
            filament_mm: filament_mm * s.flow_factor,
            feed_mm_s: s.feed_mm_s * s.speed_factor,
            limits: s.limits(filament_mm != 0.0),
            pressure_advance: s.pressure_advance,
        };
        s.position_mm = end;
        self.program.moves.push(mv);
        self.program.move_lines.push(self.line);
        Ok(())
    }

    fn set_position(&mut self, words: &[(char, f64)]) -> Result<(), String> {
        let s = &mut *self.state;
        let axes: Vec<(char, f64)> = if words.iter().any(|(l, _)| "XYZE".contains(*l)) {
            words.to_vec()
        } else {
            vec![('X', 0.0), ('Y', 0.0), ('Z', 0.0), ('E', 0.0)]
        };
        for (letter, value) in axes {
            match letter {
                'X' | 'Y' | 'Z' => {
                    let k = (letter as u8 - b'X') as usize;
                    s.offset_mm[k] = s.position_mm[k] - check_coordinate(letter, value)?;
                }
                'E' => s.e_mm = value,
                _ => {}
            }
        }
        Ok(())
    }

    fn home(&mut self, words: &[(char, f64)]) -> Result<(), String> {
        let named: Vec<usize> = words.iter().filter_map(|(l, _)| "XYZ".find(*l)).collect();
        let axes = if named.is_empty() { vec![0, 1, 2] } else { named };
        for k in axes {
            self.state.position_mm[k] = 0.0;
            self.state.offset_mm[k] = 0.0;
        }
        Ok(())
    }

    fn factor(&mut self, words: &[(char, f64)], speed: bool) -> Result<(), String> {
        if let Some(&(_, percent)) = words.iter().find(|(l, _)| *l == 'S') {
            let f = positive('S', percent)? / 100.0;
            if speed {
                self.state.speed_factor = f;
            } else {
                self.state.flow_factor = f;
            }
        }
        Ok(())
    }

    fn m204(&mut self, words: &[(char, f64)]) -> Result<(), String> {
        let get = |c: char| words.iter().find(|(l, _)| *l == c).map(|&(_, v)| positive(c, v)).transpose();
        let (s, p, t) = (get('S')?, get('P')?, get('T')?);
        let st = &mut *self.state;
        match st.start.firmware {
            Firmware::Klipper => {
                let accel = s.or(match (p, t) {
                    (Some(p), Some(t)) => Some(p.min(t)),
                    (p, t) => p.or(t),
                });
                if let Some(a) = accel {
                    (st.accel_mm_s2, st.travel_accel_mm_s2) = (a, a);
                }
            }
            Firmware::Marlin => {
                if let Some(a) = p.or(s) {
                    st.accel_mm_s2 = a;
                }
                if let Some(a) = t.or(s) {
                    st.travel_accel_mm_s2 = a;
                }
            }
        }
        if s.or(p).or(t).is_some() {
            self.note("accel");
        }
        Ok(())
    }

    fn m205(&mut self, words: &[(char, f64)]) -> Result<(), String> {
        for &(letter, value) in words {
            match letter {
                'X' | 'Y' | 'Z' => {
                    self.state.jerk_mm_s[(letter as u8 - b'X') as usize] = positive(letter, value)?;
                    self.state.junction_deviation_mm = None;
                    self.note("jerk");
                }
                'J' => {
                    self.state.junction_deviation_mm = Some(positive('J', value)?);
                    self.note("junction_deviation");
                }
                _ => {}
            }
        }
        Ok(())
    }

    fn m900(&mut self, words: &[(char, f64)]) -> Result<(), String> {
        if let Some(&(_, k)) = words.iter().find(|(l, _)| *l == 'K') {
            self.state.pressure_advance.advance_s = non_negative("K", k)?;
            self.note("pressure_advance");
        }
        Ok(())
    }

    fn set_pressure_advance(&mut self, params: &[(String, f64)]) -> Result<(), String> {
        for (key, value) in params {
            match key.as_str() {
                "ADVANCE" => {
                    self.state.pressure_advance.advance_s = non_negative(key, *value)?;
                    self.note("pressure_advance");
                }
                "SMOOTH_TIME" => {
                    self.state.pressure_advance.smooth_time_s = within(key, *value, 0.0, 0.2)?;
                    self.note("smooth_time");
                }
                _ => {}
            }
        }
        Ok(())
    }

    fn set_velocity_limit(&mut self, params: &[(String, f64)]) -> Result<(), String> {
        let mut accel_to_decel = None;
        for (key, value) in params {
            let s = &mut *self.state;
            match key.as_str() {
                "VELOCITY" => s.max_velocity_mm_s = positive_key(key, *value)?,
                "ACCEL" => {
                    (s.accel_mm_s2, s.travel_accel_mm_s2) = (positive_key(key, *value)?, positive_key(key, *value)?);
                    self.note("accel");
                }
                "SQUARE_CORNER_VELOCITY" => {
                    s.square_corner_velocity_mm_s = positive_key(key, *value)?;
                    self.note("square_corner_velocity");
                }
                "MINIMUM_CRUISE_RATIO" => s.minimum_cruise_ratio = within(key, *value, 0.0, 0.99)?,
                "ACCEL_TO_DECEL" => accel_to_decel = Some(positive_key(key, *value)?),
                _ => {}
            }
        }
        if let Some(atd) = accel_to_decel {
            let s = &mut *self.state;
            s.minimum_cruise_ratio = (1.0 - atd / s.accel_mm_s2).clamp(0.0, 0.99);
        }
        Ok(())
    }
}

impl State {
    fn new(start: StartSettings) -> Self {
        Self {
            start,
            position_mm: [0.0; 3],
            offset_mm: [0.0; 3],
            e_mm: 0.0,
            feed_mm_s: 25.0,
            absolute_xyz: true,
            absolute_e: true,
            speed_factor: 1.0,
            flow_factor: 1.0,
            accel_mm_s2: start.accel_mm_s2,
            travel_accel_mm_s2: start.accel_mm_s2,
            minimum_cruise_ratio: start.minimum_cruise_ratio,
            max_velocity_mm_s: start.max_velocity_mm_s,
            square_corner_velocity_mm_s: start.square_corner_velocity_mm_s,
            jerk_mm_s: [start.jerk_mm_s, start.jerk_mm_s, start.jerk_z_mm_s],
            junction_deviation_mm: None,
            pressure_advance: PressureAdvance {
                advance_s: start.pressure_advance_s,
                smooth_time_s: start.smooth_time_s,
            },
        }
    }

    /// The planner's limits for a move that extrudes (or not).
    fn limits(&self, extrudes: bool) -> MotionLimits {
        match self.start.firmware {
            Firmware::Klipper => MotionLimits {
                accel_mm_s2: self.accel_mm_s2,
                accel_to_decel_mm_s2: self.accel_mm_s2 * (1.0 - self.minimum_cruise_ratio),
                max_velocity_mm_s: self.max_velocity_mm_s,
                cornering: Cornering::SquareCorner {
                    velocity_mm_s: self.square_corner_velocity_mm_s,
                    extruder_corner_mm_s: self.start.extruder_corner_mm_s,
                },
            },
            Firmware::Marlin => {
                let accel_mm_s2 = if extrudes { self.accel_mm_s2 } else { self.travel_accel_mm_s2 };
                let [jerk_x_mm_s, jerk_y_mm_s, jerk_z_mm_s] = self.jerk_mm_s;
                let cornering = match self.junction_deviation_mm {
                    Some(deviation_mm) => Cornering::JunctionDeviation { deviation_mm },
                    None => Cornering::ClassicJerk { jerk_x_mm_s, jerk_y_mm_s, jerk_z_mm_s },
                };
                MotionLimits {
                    accel_mm_s2,
                    accel_to_decel_mm_s2: accel_mm_s2,
                    max_velocity_mm_s: f64::INFINITY,
                    cornering,
                }
            }
        }
    }
}

/// The `letter number` words of a standard command, letters upper-cased.
fn words(rest: &str) -> Result<Vec<(char, f64)>, String> {
    let mut out = Vec::new();
    for token in rest.split_whitespace() {
        let mut chars = token.char_indices().peekable();
        while let Some((i, c)) = chars.next() {
            if !c.is_ascii_alphabetic() {
                return Err(format!("expected a word (a letter and a number), got `{token}`"));
            }
            let start = i + 1;
            let mut end = start;
            while let Some(&(j, d)) = chars.peek() {
                if d.is_ascii_digit() || d == '.' || ((d == '-' || d == '+') && j == start) {
                    end = j + d.len_utf8();
                    chars.next();
                } else {
                    break;
                }
            }
            let letter = c.to_ascii_uppercase();
            let number = &token[start..end];
            if !number.is_empty() && is_exponent(&token[end..]) {
                return Err(format!(
                    "expected words separated by spaces, got `{token}` (an exponent is not G-code; a firmware reads `{}` as an extrusion)",
                    &token[end..]
                ));
            }
            let value = number.parse::<f64>().ok().filter(|x| x.is_finite()).ok_or_else(|| {
                let got = if number.is_empty() { token[start..].to_string() } else { number.to_string() };
                format!("expected a number after {letter}, got `{got}`")
            })?;
            out.push((letter, value));
        }
    }
    Ok(out)
}

/// The `KEY=value` parameters of a Klipper extended command (numbers only are kept;
/// other values, such as `EXTRUDER=extruder`, are skipped).
fn parameters(rest: &str) -> Result<Vec<(String, f64)>, String> {
    let mut out = Vec::new();
    for token in rest.split_whitespace() {
        let Some((key, value)) = token.split_once('=') else {
            return Err(format!("expected KEY=value, got `{token}`"));
        };
        let key = key.to_ascii_uppercase();
        if matches!(key.as_str(), "EXTRUDER") {
            continue;
        }
        let number = value
            .parse::<f64>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or_else(|| format!("expected a number after {key}=, got `{value}`"))?;
        out.push((key, number));
    }
    Ok(out)
}

/// A lowercase `e` and a digit or sign right after a number: `1.5e1` as `printf` writes
/// it. (An uppercase `E` there is a packed extrusion word, `X1E0.5`, and is read as one.)
fn is_exponent(after_number: &str) -> bool {
    let mut c = after_number.chars();
    c.next() == Some('e') && c.next().is_some_and(|d| d.is_ascii_digit() || d == '-' || d == '+')
}

fn check_coordinate(letter: char, value_mm: f64) -> Result<f64, String> {
    if value_mm.abs() <= MAX_GCODE_COORDINATE_MM {
        Ok(value_mm)
    } else {
        Err(format!("expected {letter} within ±{MAX_GCODE_COORDINATE_MM} mm, got {value_mm}"))
    }
}

fn positive(letter: char, value: f64) -> Result<f64, String> {
    positive_key(&letter.to_string(), value)
}

fn positive_key(key: &str, value: f64) -> Result<f64, String> {
    if value > 0.0 {
        Ok(value)
    } else {
        Err(format!("expected a number > 0 after {key}, got {value}"))
    }
}

fn non_negative(key: &str, value: f64) -> Result<f64, String> {
    within(key, value, 0.0, f64::MAX)
}

fn within(key: &str, value: f64, lo: f64, hi: f64) -> Result<f64, String> {
    if (lo..=hi).contains(&value) {
        Ok(value)
    } else if hi == f64::MAX {
        Err(format!("expected a number ≥ {lo} after {key}, got {value}"))
    } else {
        Err(format!("expected a number in [{lo}, {hi}] after {key}, got {value}"))
    }
}
