//! Tests of the `fdm-photos` reader and its G-code reader, on a small G-code of our own:
//! a frame, then three slow–fast–slow lines each under its own pressure advance.

use super::*;
use models::fdm::planner::Cornering;

/// Our fixture: a 30 × 20 mm frame at 20 mm/s, three slow–fast–slow lines 3 mm apart.
fn fixture_gcode(relative_e: bool) -> String {
    let mut g = String::from("; test pattern of our own\nG21\nG90\n");
    g += if relative_e { "M83\n" } else { "M82\n" };
    g += "G92 E0\nSET_VELOCITY_LIMIT ACCEL=2000 SQUARE_CORNER_VELOCITY=5\nG1 Z0.2 F600\nG1 X5 Y5 F6000\n";
    let mut e = 0.0;
    let mut extrude = |g: &mut String, x: f64, y: f64, mm: f64, feed: Option<f64>| {
        let amount = 0.05 * mm;
        e += amount;
        let word = if relative_e { amount } else { e };
        let feed = feed.map(|f| format!(" F{f}")).unwrap_or_default();
        *g += &format!("G1 X{x} Y{y} E{word:.5}{feed} ; edge\n");
    };
    extrude(&mut g, 35.0, 5.0, 30.0, Some(1200.0));
    extrude(&mut g, 35.0, 25.0, 20.0, None);
    extrude(&mut g, 5.0, 25.0, 30.0, None);
    extrude(&mut g, 5.0, 5.0, 20.0, None);
    for (k, advance) in [0.0, 0.01, 0.02].iter().enumerate() {
        let y = 10.0 + 3.0 * k as f64;
        g += &format!("G1 Z0.4 F600\nG1 X8 Y{y} F9000\nG1 Z0.2 F600\nSET_PRESSURE_ADVANCE ADVANCE={advance}\n");
        extrude(&mut g, 10.0, y, 2.0, Some(600.0));
        extrude(&mut g, 24.0, y, 14.0, Some(6000.0));
        extrude(&mut g, 30.0, y, 6.0, Some(600.0));
    }
    g + "M107 ; fan off\nM117 Done printing\n"
}

const TOML: &str = r#"kind = "fdm-photos"
format_version = 1
printer = "our_printer"
description = "a frame and three slow-fast-slow lines"

[units]
length = "mm"

[provenance]
type = "measured"
source = "test"
license = "CC0-1.0"
imported_by = "hand"

[printer_settings]
firmware = "klipper"
filament_diameter_mm = 1.75
nozzle_diameter_mm = 0.4
"#;

fn write_dataset(dir: &Path, gcode: &str) {
    std::fs::create_dir_all(dir.join("photos")).unwrap();
    std::fs::write(dir.join("dataset.toml"), TOML).unwrap();
    std::fs::write(dir.join("print.gcode"), gcode).unwrap();
    std::fs::write(dir.join("photos.csv"), "photo_id,image,height_mm\nh45,photos/h45.JPG,45\nh50,photos/h50.png,50\n")
        .unwrap();
    std::fs::write(dir.join("photos/h45.JPG"), b"not decoded here").unwrap();
    std::fs::write(dir.join("photos/h50.png"), b"not decoded here").unwrap();
}

fn klipper_start() -> StartSettings {
    StartSettings {
        firmware: Firmware::Klipper,
        accel_mm_s2: 3000.0,
        square_corner_velocity_mm_s: 5.0,
        minimum_cruise_ratio: 0.5,
        max_velocity_mm_s: f64::INFINITY,
        extruder_corner_mm_s: 1.0,
        jerk_mm_s: 10.0,
        jerk_z_mm_s: 0.3,
        pressure_advance_s: 0.0,
        smooth_time_s: 0.04,
    }
}

fn read(text: &str, start: StartSettings) -> Result<GcodeProgram, GcodeError> {
    read_gcode(Path::new("print.gcode"), text, start)
}

#[test]
fn the_fixture_reads_as_a_frame_and_three_slow_fast_slow_lines() {
    let tmp = tempfile::tempdir().unwrap();
    write_dataset(tmp.path(), &fixture_gcode(false));
    let data = FdmPhotos::read(tmp.path()).unwrap();
    assert_eq!(data.lines.len(), 7, "{:#?}", data.lines);
    let frame: Vec<_> = data.lines[..4].iter().map(|l| (l.start_mm, l.end_mm)).collect();
    assert_eq!(frame[0], ([5.0, 5.0], [35.0, 5.0]));
    for (k, line) in data.lines[4..].iter().enumerate() {
        assert_eq!(line.moves.len(), 3);
        assert_eq!(line.pressure_advance.advance_s, 0.01 * k as f64);
        assert_eq!(line.pressure_advance.smooth_time_s, 0.04);
        assert!((line.length_mm() - 22.0).abs() < 1e-9);
        assert!((line.speed_at_mm(9.0) - 100.0).abs() < 1e-9, "{:?}", line.moves[1]);
        assert_eq!(line.moves[1].planned.accel_mm_s2, 2000.0);
        assert!((line.layer_height_mm - 0.2).abs() < 1e-12);
    }
    // The G-code sets the accel, scv and pressure advance; the rest is assumed.
    let assumed: Vec<_> = data.assumed.iter().map(|a| a.setting).collect();
    assert_eq!(assumed, ["minimum_cruise_ratio", "max_velocity_mm_s", "smooth_time_s"]);
    assert_eq!(data.gcode.ignored.get("M117"), Some(&(1, 35)));
    assert_eq!(data.photos[0].image, tmp.path().join("photos/h45.JPG"));
    assert_eq!(data.photos[1].extra, [("height_mm".to_string(), "50".to_string())]);
}

#[test]
fn a_printer_table_with_its_name_reads_as_printer_settings_beside_the_name() {
    let tmp = tempfile::tempdir().unwrap();
    write_dataset(tmp.path(), &fixture_gcode(false));
    let as_printer_table = TOML
        .replace("printer = \"our_printer\"\n", "")
        .replace("[printer_settings]", "[printer]\nname = \"lab_printer\"");
    std::fs::write(tmp.path().join("dataset.toml"), &as_printer_table).unwrap();
    let data = FdmPhotos::read(tmp.path()).unwrap();
    assert_eq!(data.manifest.printer, "lab_printer");
    assert_eq!(data.printer.filament_diameter_mm, 1.75);
    assert_eq!(data.lines.len(), 7);
    // without a name the folder names the printer
    std::fs::write(tmp.path().join("dataset.toml"), as_printer_table.replace("name = \"lab_printer\"\n", "")).unwrap();
    let folder = tmp.path().file_name().unwrap().to_string_lossy().into_owned();
    assert_eq!(FdmPhotos::read(tmp.path()).unwrap().manifest.printer, folder);
}

#[test]
fn relative_and_absolute_e_give_the_same_lines() {
    let absolute = read(&fixture_gcode(false), klipper_start()).unwrap();
    let relative = read(&fixture_gcode(true), klipper_start()).unwrap();
    assert_eq!(absolute.moves.len(), relative.moves.len());
    for (a, r) in absolute.moves.iter().zip(&relative.moves) {
        assert!((a.filament_mm - r.filament_mm).abs() < 1e-4, "{a:?} {r:?}");
        assert_eq!((a.start_mm, a.end_mm), (r.start_mm, r.end_mm));
    }
    // G91 makes E relative too.
    let g91 = read("M82\nG92 E0\nG91\nG1 X10 E1 F600\nG1 X10 E1\n", klipper_start()).unwrap();
    assert_eq!(g91.moves[1].filament_mm, 1.0);
    assert_eq!(g91.moves[1].end_mm, [20.0, 0.0, 0.0]);
}

#[test]
fn g92_offsets_later_moves_and_comments_numbers_and_checksums_are_skipped() {
    let text = "N1 G1 X10 F600*33\n(move) G92 X0 ; now X is 0 here\n\nG1 X5 E0.5\nG92\nG1 E1.5 ; prime\n";
    let p = read(text, klipper_start()).unwrap();
    assert_eq!(p.moves[1].end_mm, [15.0, 0.0, 0.0]);
    assert_eq!(p.moves[1].filament_mm, 0.5);
    // After a bare G92, E counts from 0 again.
    assert_eq!(p.moves[2].filament_mm, 1.5);
    assert_eq!(p.move_lines, [1, 4, 6]);
}

#[test]
fn bad_lines_name_the_line_and_what_was_expected() {
    let cases = [
        ("G1 X10\nG1 Xabc Y2\n", "print.gcode:line 2: expected a number after X, got `abc`"),
        ("G1 X\n", "print.gcode:line 1: expected a number after X, got ``"),
        ("G1 X-1.5e1\n", "print.gcode:line 1: expected words separated by spaces, got `X-1.5e1`"),
        ("G20\n", "print.gcode:line 1: expected millimetres (G21), got G20"),
        ("G2 X1 Y1 I1 J0\n", "print.gcode:line 1: expected straight moves, got the arc `G2`"),
        ("G1 X1 F0\n", "print.gcode:line 1: expected a number > 0 after F, got 0"),
        ("G1 X1e9\n", "expected words separated by spaces"),
        ("G1 X100000\n", "print.gcode:line 1: expected X within ±10000 mm, got 100000"),
        ("SET_PRESSURE_ADVANCE ADVANCE=fast\n", "print.gcode:line 1: expected a number after ADVANCE=, got `fast`"),
        ("SET_PRESSURE_ADVANCE SMOOTH_TIME=1\n", "expected a number in [0, 0.2] after SMOOTH_TIME, got 1"),
        ("SET_VELOCITY_LIMIT ACCEL\n", "expected KEY=value, got `ACCEL`"),
    ];
    for (text, message) in cases {
        let err = read(text, klipper_start()).unwrap_err().to_string();
        assert!(err.starts_with(message) || err.contains(message), "{text:?}: {err}");
    }
}

#[test]
fn each_firmware_reads_its_own_commands_and_ignores_the_others() {
    let text = "M204 P500 T4000\nM205 X8 Y8\nM900 K0.06\nSET_PRESSURE_ADVANCE ADVANCE=0.5\nG1 X10 E1 F600\nG1 X20 F6000\nM205 J0.02\nG1 X30 E1\n";
    let marlin = StartSettings { firmware: Firmware::Marlin, smooth_time_s: 0.0, ..klipper_start() };
    let p = read(text, marlin).unwrap();
    let (print, travel, jd) = (p.moves[0], p.moves[1], p.moves[2]);
    assert_eq!((print.limits.accel_mm_s2, travel.limits.accel_mm_s2), (500.0, 4000.0));
    assert_eq!(print.limits.cornering, Cornering::ClassicJerk { jerk_x_mm_s: 8.0, jerk_y_mm_s: 8.0, jerk_z_mm_s: 0.3 });
    assert_eq!(print.pressure_advance.advance_s, 0.06);
    assert_eq!(jd.limits.cornering, Cornering::JunctionDeviation { deviation_mm: 0.02 });
    assert!(p.ignored.contains_key("SET_PRESSURE_ADVANCE"));
    let k = read(text, klipper_start()).unwrap();
    // Klipper's M204 takes the smaller of P and T; it has no M205 or M900.
    assert_eq!(k.moves[0].limits.accel_mm_s2, 500.0);
    assert_eq!(k.moves[0].pressure_advance.advance_s, 0.5);
    assert_eq!(k.ignored.get("M205"), Some(&(2, 2)));
    assert!(k.ignored.contains_key("M900"));
}

#[test]
fn minimum_cruise_ratio_and_accel_to_decel_set_the_smoothing() {
    let text = "SET_VELOCITY_LIMIT ACCEL=4000 ACCEL_TO_DECEL=1000 VELOCITY=150\nG1 X10 F600\nSET_VELOCITY_LIMIT MINIMUM_CRUISE_RATIO=0.25\nG1 X20\n";
    let p = read(text, klipper_start()).unwrap();
    assert_eq!(p.moves[0].limits.accel_to_decel_mm_s2, 1000.0);
    assert_eq!(p.moves[0].limits.max_velocity_mm_s, 150.0);
    assert_eq!(p.moves[1].limits.accel_to_decel_mm_s2, 3000.0);
}

#[test]
fn dataset_errors_name_the_file_and_the_field() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    write_dataset(dir, &fixture_gcode(false));
    let csv = dir.join("photos.csv");
    let cases = [
        (
            "photo_id,image\nh45,photos/h45.bmp\n",
            "photos.csv:line 2, field image: expected a .jpg, .jpeg or .png image",
        ),
        (
            "photo_id,image\nh45,photos/none.jpg\n",
            "photos.csv:line 2, field image: expected an image file, `photos/none.jpg` is missing",
        ),
        ("photo_id,image\nh45,../h45.jpg\n", "photos.csv:line 2, field image: expected a path relative"),
        (
            "photo_id,image\nh45,photos/h45.JPG\nh45,photos/h50.png\n",
            "photos.csv:line 3, field photo_id: expected a unique id",
        ),
    ];
    for (text, message) in cases {
        std::fs::write(&csv, text).unwrap();
        let err = FdmPhotos::read(dir).unwrap_err().to_string();
        assert!(err.contains(message), "{err}");
    }
    write_dataset(dir, "G1 X1\nG1 X2 Y\n");
    let err = FdmPhotos::read(dir).unwrap_err().to_string();
    assert!(err.ends_with("print.gcode:line 2: expected a number after Y, got ``"), "{err}");
    let toml = dir.join("dataset.toml");
    let settings = [
        ("firmware = \"klipper\"", "firmware = \"reprap\"", "printer_settings"),
        ("nozzle_diameter_mm = 0.4", "nozzle_diameter_mm = 0.4\naccel_mm_s2 = -5", "printer_settings.accel_mm_s2"),
        ("nozzle_diameter_mm = 0.4", "nozzle_diameter_mm = 0.4\nspeed = 5", "unknown field `speed`"),
        ("[printer_settings]", "[other]", "expected a [printer] (or [printer_settings]) table"),
        ("fdm-photos", "fdm-lines", "dataset.toml:kind: expected kind `fdm-photos`"),
    ];
    for (from, to, message) in settings {
        std::fs::write(&toml, TOML.replace(from, to)).unwrap();
        let err = FdmPhotos::read(dir).unwrap_err().to_string();
        assert!(err.contains(message), "{from} → {to}: {err}");
    }
}

#[test]
fn replanning_with_a_lower_accel_lowers_the_short_fast_move() {
    let tmp = tempfile::tempdir().unwrap();
    write_dataset(tmp.path(), &fixture_gcode(false).replace("SET_VELOCITY_LIMIT ACCEL=2000 ", "SET_VELOCITY_LIMIT "));
    let data = FdmPhotos::read(tmp.path()).unwrap();
    assert_eq!(data.assumed[0].setting, "accel_mm_s2");
    let slow = data.replan(StartSettings { accel_mm_s2: 500.0, ..data.start }).unwrap();
    assert_eq!(slow.len(), data.lines.len());
    let (fast_line, slow_line) = (&data.lines[5], &slow[5]);
    assert!(slow_line.duration_s() > fast_line.duration_s());
    assert_eq!(fast_line.moves[1].planned.cruise_mm_s, 100.0);
    // At 500 mm/s² and Klipper's cruise ratio 0.5 the 14 mm fast move peaks at
    // √(10² + 500·(1 − 0.5)·14) = 60 mm/s.
    assert!((slow_line.moves[1].planned.cruise_mm_s - 60.0).abs() < 1e-9);
}

#[test]
fn the_worked_example_of_docs_datasets_reads_as_documented() {
    let text = "G21\nG90\nM83\nSET_VELOCITY_LIMIT ACCEL=2500\nG1 Z0.2 F600\nG1 X10 Y20 F9000\nSET_PRESSURE_ADVANCE ADVANCE=0.02\nG1 X14 Y20 E0.2 F600     ; slow\nG1 X34 Y20 E1.0 F6000    ; fast\nG1 X44 Y20 E0.5 F600     ; slow\nG1 Z0.4 F600\nG1 X10 Y23 F9000\nG1 Z0.2 F600\nSET_PRESSURE_ADVANCE ADVANCE=0.04\n";
    let p = read(text, klipper_start()).unwrap();
    let planned = models::fdm::planner::plan(&p.moves).unwrap();
    let lines = models::fdm::printed_lines::printed_lines(&p.moves, &planned, 1.75);
    assert_eq!(lines.len(), 1);
    let line = &lines[0];
    assert_eq!((line.moves.len(), line.length_mm(), line.z_mm), (3, 34.0, 0.2));
    let speeds: Vec<_> =
        line.moves.iter().map(|m| (m.planned.entry_mm_s, m.planned.cruise_mm_s, m.planned.exit_mm_s)).collect();
    assert_eq!(speeds[1], (10.0, 100.0, 10.0));
    assert_eq!((line.moves[1].planned.accel_mm_s2, line.pressure_advance.advance_s), (2500.0, 0.02));
    assert!((line.nominal_width_mm - 0.60).abs() < 0.005, "{}", line.nominal_width_mm);
}
