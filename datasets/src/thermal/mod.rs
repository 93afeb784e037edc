//! The virtual extrusion printer with a nozzle-mounted thermal camera (DESIGN §5.3,
//! paper 003: Chen, Yang, Liu, Duan), writing `thermal-sequence` datasets (DESIGN §4).
//!
//! Code map, one file per step:
//! - [`effects`]: the named, switchable extra effects and their strengths.
//! - [`deposition`]: v_e → E = G(s)·E_cmd (eq. 34) → material on a fine grid by mass conservation.
//! - [`heat`]: the temperature field: Newton cooling plus lateral diffusion (exact Green's function, binned).
//! - [`camera`]: the nozzle-mounted Lepton: mount, distortion, rendering, capture schedule (eq. 28).
//! - [`sequence`]: the dataset folder: writer, reader ([`ThermalSequence`]) and truth reader ([`ThermalTruth`]).
//! - this file: [`generate`], which prints the corner test part (Fig. 7) and films it.
//!
//! Architecture Invariant: the printer simulates physics richer than the paper's model
//! (no slender-bead equations, no drawn over-deposition) and writes only through the
//! documented format; its internals reach the analysis only through `truth/`.

pub mod camera;
pub mod capillary;
pub mod deposition;
pub mod effects;
pub mod heat;
pub mod sequence;

pub use camera::LeptonHabits;
pub use effects::{EffectError, Effects, KNOWN_EFFECTS};
pub use sequence::{ThermalSequence, ThermalTruth};

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use models::progress::Progress;
use models::thermal::{setup::corner_test_path, PrintSetup, Trajectory};
use rand::Rng;
use rayon::prelude::*;

use crate::error::DatasetError;
use crate::limits::{check_option, THERMAL_LAYERS};
use crate::manifest::{DatasetManifest, Provenance, MANIFEST_FILE};
use crate::output::{write_file, OutputDir, Ownership};
use crate::stream;
use camera::{Distortion, FrameCapture, Intrinsics, Mount, Pose, HEIGHT_PX, WIDTH_PX};
use deposition::LayerDeposit;
use heat::{HeatParams, LayerHeat};
use sequence::{CameraFile, ProcessFile, TruthFile};

/// Generator name recorded in the provenance.
pub const GENERATOR: &str = "amrepro-thermal";
/// Time between the end of one layer and the start of the next (travel and z move) (s);
/// the nozzle stands at the layer's end point and the camera films on.
pub const LAYER_CHANGE_S: f64 = 1.0;

/// What to generate (the CLI `amrepro datasets generate thermal --seed S [--layers L]
/// [--effect NAME --strength X]...` maps onto it).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GenerateConfig {
    /// Seed of every random stream.
    pub seed: u64,
    /// Layers printed and filmed.
    pub layers: usize,
    /// Checked extra effects.
    pub effects: Effects,
    /// Lepton habits of the camera.
    pub lepton_habits: LeptonHabits,
}

impl Default for GenerateConfig {
    fn default() -> Self {
        Self { seed: 1, layers: 1, effects: Effects::none(), lepton_habits: LeptonHabits::default() }
    }
}

/// What was written.
#[derive(Debug, Clone, PartialEq)]
pub struct GenerateSummary {
    /// Layers printed and filmed.
    pub layers: usize,
    /// Frames written (all layers).
    pub frames: usize,
    /// Frames that repeat an earlier image (Lepton habits).
    pub repeated_frames: usize,
    /// Rows of `truth/corners.csv`.
    pub corners_in_view: usize,
    /// Duration of one layer (s).
    pub layer_duration_s: f64,
}

/// One rendered image with its truth.
struct Shot {
    png: Vec<u8>,
    nozzle_mm: [f64; 2],
    corners: Vec<(usize, [f64; 2], f64, f64)>,
}

/// The folders [`generate`] may replace: absent, empty, or a dataset it wrote.
pub const OUTPUT: Ownership = Ownership {
    kind: sequence::KIND,
    versions: sequence::READABLE_VERSIONS,
    writer: "datasets generate thermal",
    written_by_us: |p| matches!(p, Provenance::Virtual { generator, .. } if generator == GENERATOR),
};

/// Prints the corner test part (paper Fig. 7, Table 1) conventionally (v_e = |v|),
/// films it and writes a `thermal-sequence` dataset as `out` atomically ([`OutputDir`]:
/// `out` must be absent, empty or an earlier output of this generator).
/// The output is byte-identical for the same config whatever the thread count.
pub fn generate(config: &GenerateConfig, out: &Path) -> Result<GenerateSummary, DatasetError> {
    let output = OutputDir::begin(out, &OUTPUT)?;
    let summary = generate_into(config, output.path())?;
    output.commit()?;
    Ok(summary)
}

/// [`generate`] into the empty folder `out_dir` (a stage's output folder, which the
/// engine swaps in).
pub fn generate_into(config: &GenerateConfig, out_dir: &Path) -> Result<GenerateSummary, DatasetError> {
    generate_into_observed(config, out_dir, &())
}

/// [`generate_into`], telling `progress` of each layer printed and each frame shot.
pub fn generate_into_observed(
    config: &GenerateConfig,
    out_dir: &Path,
    progress: &dyn Progress,
) -> Result<GenerateSummary, DatasetError> {
    let model_error = |e: models::thermal::ThermalError| DatasetError::Malformed {
        file: out_dir.to_path_buf(),
        location: None,
        expected: format!("virtual printer: {e}"),
    };
    let layers = config.layers.max(1);
    check_option("--layers", layers, &THERMAL_LAYERS)?;
    let setup = PrintSetup::paper_defaults();
    let trajectory = Trajectory::corner_test(&setup).map_err(model_error)?;
    let v_e = setup.conventional_command(&trajectory);
    let mut rng_print = stream(config.seed, 1);
    let deposits =
        deposition::print_part_observed(&setup, &trajectory, &v_e, layers, &config.effects, &mut rng_print, progress)
            .map_err(model_error)?;
    let heats = layer_heats(&setup, &trajectory, &deposits, &config.effects);
    let (intrinsics, distortion) = (Intrinsics::lepton35(), Distortion::lepton35());
    let true_mount = Mount::nominal().with_mounting_error(&mut stream(config.seed, 2));
    let mut rng_schedule = stream(config.seed, 3);
    let schedules: Vec<Vec<FrameCapture>> = (0..layers)
        .map(|_| {
            camera::schedule(
                trajectory.duration_s() + LAYER_CHANGE_S,
                config.effects.camera_latency_s,
                &config.lepton_habits,
                &mut rng_schedule,
            )
        })
        .collect();
    let rays = camera::pixel_rays(&intrinsics, &distortion);
    let jobs: Vec<(usize, FrameCapture)> = schedules
        .iter()
        .enumerate()
        .flat_map(|(l, s)| s.iter().filter(|f| f.source == f.frame).map(move |f| (l, *f)))
        .collect();
    progress.add(jobs.len() as u64);
    let shots: Vec<Shot> = jobs
        .par_iter()
        .map(|&(layer, capture)| {
            let mut rng = stream(config.seed, 1000 + (layer as u64) * 100_000 + capture.frame as u64);
            let shot = shoot(
                &heats[layer],
                &trajectory,
                &true_mount,
                &intrinsics,
                &distortion,
                &rays,
                capture.capture_time_s,
                &mut rng,
            );
            progress.done(1);
            shot
        })
        .collect();
    let shot_of: BTreeMap<(usize, usize), &Shot> = jobs.iter().map(|(l, f)| (*l, f.frame)).zip(&shots).collect();
    let nozzle_px = camera::project_px(&true_mount.pose([0.0, 0.0]), &intrinsics, &distortion, [0.0, 0.0])
        .expect("the nozzle is in front of the camera");
    write_description(out_dir, config, &setup, &trajectory, &intrinsics, &distortion, nozzle_px)?;
    let (frames, corners) = write_frames(out_dir, &schedules, &shot_of)?;
    write_truth(out_dir, &setup, &trajectory, &deposits, &heats, &true_mount, &config.effects, &schedules, &shot_of)?;
    let repeated_frames = schedules.iter().flatten().filter(|f| f.source != f.frame).count();
    Ok(GenerateSummary {
        layers,
        frames,
        repeated_frames,
        corners_in_view: corners,
        layer_duration_s: trajectory.duration_s(),
    })
}

/// Heat sources of every layer; the substrate of layer n carries the configured
/// fraction of layer n−1's residual excess at the start of layer n.
fn layer_heats(
    setup: &PrintSetup,
    trajectory: &Trajectory,
    deposits: &[LayerDeposit],
    effects: &Effects,
) -> Vec<LayerHeat> {
    let params = HeatParams::with_effects(effects);
    let mut heats: Vec<LayerHeat> = Vec::with_capacity(deposits.len());
    let mut substrate_c = setup.bed_temp_c;
    for deposit in deposits {
        if let Some(prev) = heats.last() {
            let residual_c =
                prev.substrate_c - setup.bed_temp_c + prev.mean_excess_c(trajectory.duration_s() + LAYER_CHANGE_S);
            substrate_c = setup.bed_temp_c + effects.layer_heat_accumulation * residual_c;
        }
        heats.push(LayerHeat::new(deposit, setup.nozzle_temp_c, substrate_c, params));
    }
    heats
}

/// Nozzle position at `t_s` (linear between trajectory samples, clamped to the move).
fn nozzle_at(trajectory: &Trajectory, t_s: f64) -> [f64; 2] {
    let x = (t_s / trajectory.dt_s).clamp(0.0, (trajectory.len() - 1) as f64);
    let k = (x.floor() as usize).min(trajectory.len().saturating_sub(2));
    let f = x - k as f64;
    let lerp = |v: &[f64]| v[k] + f * (v[k + 1] - v[k]);
    [lerp(&trajectory.x_mm), lerp(&trajectory.y_mm)]
}

/// Renders the frame captured at `t_s` and the truth of the corners it shows.
#[allow(clippy::too_many_arguments)]
fn shoot<R: Rng>(
    heat: &LayerHeat,
    trajectory: &Trajectory,
    mount: &Mount,
    intrinsics: &Intrinsics,
    distortion: &Distortion,
    rays: &[[f64; 2]],
    t_s: f64,
    rng: &mut R,
) -> Shot {
    let nozzle_mm = nozzle_at(trajectory, t_s);
    let pose: Pose = mount.vibrated(rng).pose(nozzle_mm);
    let (min, max) = camera::footprint_mm(&pose, rays);
    let field = heat.field(t_s, min, max);
    let temps_c = camera::render_temperatures_c(&field, &pose, rays);
    let pixels = camera::to_radiometric(&temps_c, rng);
    let mut corners = Vec::new();
    for c in &trajectory.corners {
        let age_s = t_s - 0.5 * (c.arc_start_s + c.arc_end_s);
        let Some(px) = camera::project_px(&pose, intrinsics, distortion, c.vertex_mm) else { continue };
        let inside = px[0] >= 0.0 && px[1] >= 0.0 && px[0] <= (WIDTH_PX - 1) as f64 && px[1] <= (HEIGHT_PX - 1) as f64;
        if age_s >= 0.0 && inside {
            corners.push((c.vertex, px, field.temp_c(c.vertex_mm), age_s));
        }
    }
    Shot { png: sequence::encode_png16(WIDTH_PX, HEIGHT_PX, &pixels), nozzle_mm, corners }
}

/// `dataset.toml`, `camera.toml`, `process.toml`, `path.csv`, `trajectory.csv`.
#[allow(clippy::too_many_arguments)]
fn write_description(
    staged: &Path,
    config: &GenerateConfig,
    setup: &PrintSetup,
    trajectory: &Trajectory,
    intrinsics: &Intrinsics,
    distortion: &Distortion,
    nozzle_px: [f64; 2],
) -> Result<(), DatasetError> {
    let units = [
        ("recorded_time_s", "s"),
        ("t_s", "s"),
        ("x_mm", "mm"),
        ("y_mm", "mm"),
        ("e_mm3_s", "mm^3/s"),
        ("pixel", "centi-kelvin (K x 100), 0 = no reading"),
        ("fx_px", "px"),
        ("fy_px", "px"),
        ("cx_px", "px"),
        ("cy_px", "px"),
        ("height_mm", "mm"),
        ("tilt_deg", "deg"),
        ("look_at_mm", "mm"),
        ("roll_deg", "deg"),
        ("nozzle_px", "px"),
        ("frame_period_s", "s"),
        ("feed_mm_s", "mm/s"),
        ("accel_mm_s2", "mm/s^2"),
        ("temp_c", "degC"),
        ("tau_s", "s"),
        ("u_px", "px"),
        ("v_px", "px"),
        ("age_s", "s"),
        ("capture_time_s", "s"),
        ("w_left_mm", "mm"),
        ("w_right_mm", "mm"),
    ];
    let manifest = DatasetManifest {
        kind: sequence::KIND.into(),
        format_version: sequence::FORMAT_VERSION,
        printer: "virtual-mex".into(),
        description: "Virtual extrusion printer with a nozzle-mounted FLIR Lepton 3.5 printing the corner test part \
            of Chen et al. (paper 003, Fig. 7, Table 1); frames are radiometric centi-kelvin PNGs."
            .into(),
        units: units.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect(),
        provenance: Provenance::Virtual {
            generator: GENERATOR.into(),
            version: env!("CARGO_PKG_VERSION").into(),
            seed: config.seed,
            effects: config.effects.to_map(),
        },
    };
    write_file(staged, MANIFEST_FILE, manifest.to_toml().as_bytes())?;
    let camera = CameraFile {
        width_px: WIDTH_PX,
        height_px: HEIGHT_PX,
        frame_period_s: camera::FRAME_PERIOD_S,
        intrinsics: *intrinsics,
        distortion: *distortion,
        mount: Mount::nominal(),
        nozzle_px,
    };
    write_file(staged, "camera.toml", sequence::to_toml(&camera).as_bytes())?;
    write_file(staged, "process.toml", sequence::to_toml(&process_file(setup, config.layers.max(1))).as_bytes())?;
    let mut path = String::from("vertex,x_mm,y_mm\n");
    for (i, v) in corner_test_path().iter().enumerate() {
        let _ = writeln!(path, "{i},{},{}", v[0], v[1]);
    }
    write_file(staged, "path.csv", path.as_bytes())?;
    let mut table = String::from("t_s,x_mm,y_mm,e_mm3_s\n");
    let speeds = trajectory.speed_mm_s();
    for k in 0..trajectory.len() {
        let e = setup.nominal_flow_mm3_s(speeds[k]);
        let _ =
            writeln!(table, "{:.3},{:.6},{:.6},{:.6}", trajectory.t_s[k], trajectory.x_mm[k], trajectory.y_mm[k], e);
    }
    write_file(staged, "trajectory.csv", table.as_bytes())
}

fn process_file(setup: &PrintSetup, layers: usize) -> ProcessFile {
    ProcessFile {
        feed_mm_s: setup.feed_mm_s,
        accel_mm_s2: setup.accel_mm_s2,
        blend_tol_mm: setup.blend_tol_mm,
        layer_height_mm: setup.layer_height_mm,
        nozzle_mm: setup.nozzle_mm,
        bead_width_mm: setup.bead_width_mm,
        tau_s: setup.tau_s,
        nozzle_temp_c: setup.nozzle_temp_c,
        bed_temp_c: setup.bed_temp_c,
        filament_diameter_mm: setup.filament_diameter_mm,
        layers_printed: layers,
        sample_period_s: setup.sample_period_s,
    }
}

/// `frames.csv` and the PNGs; returns (frames written, corner rows).
fn write_frames(
    staged: &Path,
    schedules: &[Vec<FrameCapture>],
    shots: &BTreeMap<(usize, usize), &Shot>,
) -> Result<(usize, usize), DatasetError> {
    let mut table = String::from("layer,frame,recorded_time_s,file\n");
    let (mut frames, mut corners) = (0, 0);
    for (layer, schedule) in schedules.iter().enumerate() {
        for f in schedule {
            let file = sequence::frame_file_name(layer, f.frame);
            let shot = shots[&(layer, f.source)];
            write_file(staged, &file, &shot.png)?;
            let _ = writeln!(table, "{layer},{},{:.6},{}", f.frame, f.recorded_time_s, file.display());
            frames += 1;
            corners += shot.corners.len();
        }
    }
    write_file(staged, "frames.csv", table.as_bytes())?;
    Ok((frames, corners))
}

/// A cell's fill as the 16-bit value of `truth/deposit_L*.png`
/// ([`sequence::DEPOSIT_PNG_FULL_FILL`] is 65535; piles above it are clipped, which
/// the corner test path never reaches).
fn encode_fill(fill: f32) -> u16 {
    (f64::from(fill) / sequence::DEPOSIT_PNG_FULL_FILL * 65535.0).round().clamp(0.0, 65535.0) as u16
}

/// Everything under `truth/`.
#[allow(clippy::too_many_arguments)]
fn write_truth(
    staged: &Path,
    setup: &PrintSetup,
    trajectory: &Trajectory,
    deposits: &[LayerDeposit],
    heats: &[LayerHeat],
    mount: &Mount,
    effects: &Effects,
    schedules: &[Vec<FrameCapture>],
    shots: &BTreeMap<(usize, usize), &Shot>,
) -> Result<(), DatasetError> {
    let grid = &deposits[0].grid;
    let truth = TruthFile {
        mount: *mount,
        tau_s: effects.actual_tau_s(setup.tau_s),
        deposit_origin_mm: grid.origin_mm,
        deposit_cell_mm: grid.cell_mm,
        deposit_nx: grid.nx,
        deposit_ny: grid.ny,
        substrate_c: heats.iter().map(|h| h.substrate_c).collect(),
        flow_factor: deposits.iter().map(|d| d.flow_factor).collect(),
    };
    let dir = Path::new(sequence::TRUTH_DIR);
    write_file(staged, dir.join("truth.toml"), sequence::to_toml(&truth).as_bytes())?;
    let mut frames = String::from("layer,frame,capture_time_s,nozzle_x_mm,nozzle_y_mm\n");
    let mut corners = String::from("layer,frame,vertex,u_px,v_px,temp_c,age_s\n");
    for (layer, schedule) in schedules.iter().enumerate() {
        for f in schedule {
            let shot = shots[&(layer, f.source)];
            let [x, y] = shot.nozzle_mm;
            let _ = writeln!(frames, "{layer},{},{:.6},{x:.6},{y:.6}", f.frame, f.capture_time_s);
            for (vertex, px, temp_c, age_s) in &shot.corners {
                let _ =
                    writeln!(corners, "{layer},{},{vertex},{:.4},{:.4},{temp_c:.3},{age_s:.6}", f.frame, px[0], px[1]);
            }
        }
    }
    write_file(staged, dir.join("frames.csv"), frames.as_bytes())?;
    write_file(staged, dir.join("corners.csv"), corners.as_bytes())?;
    let pieces: Vec<(Vec<u8>, String)> = deposits
        .par_iter()
        .map(|d| {
            let data: Vec<u16> = d.grid.fill.iter().map(|f| encode_fill(*f)).collect();
            let png = sequence::encode_png16(d.grid.nx, d.grid.ny, &data);
            let mut rows = String::new();
            for (k, (l, r)) in deposition::half_widths_mm(&d.grid, trajectory).iter().enumerate() {
                let _ = writeln!(rows, "{},{k},{:.3},{l:.5},{r:.5}", d.layer, trajectory.t_s[k]);
            }
            (png, rows)
        })
        .collect();
    let mut widths = String::from("layer,sample,t_s,w_left_mm,w_right_mm\n");
    for (d, (png, rows)) in deposits.iter().zip(&pieces) {
        write_file(staged, dir.join(sequence::deposit_file_name(d.layer)), png)?;
        widths.push_str(rows);
    }
    write_file(staged, dir.join("widths.csv"), widths.as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    fn generated(config: &GenerateConfig) -> (tempfile::TempDir, PathBuf, GenerateSummary) {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("thermal");
        let summary = generate(config, &out).unwrap();
        (dir, out, summary)
    }

    fn all_files(root: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
        let mut out = BTreeMap::new();
        let mut stack = vec![root.to_path_buf()];
        while let Some(dir) = stack.pop() {
            for entry in std::fs::read_dir(&dir).unwrap() {
                let path = entry.unwrap().path();
                if path.is_dir() {
                    stack.push(path);
                } else {
                    out.insert(path.strip_prefix(root).unwrap().to_path_buf(), std::fs::read(&path).unwrap());
                }
            }
        }
        out
    }

    #[test]
    fn written_dataset_reads_back() {
        let effects = Effects::from_pairs([("tau_mismatch", 0.5)]).unwrap();
        let (_tmp, out, summary) = generated(&GenerateConfig { seed: 5, effects, ..GenerateConfig::default() });
        let seq = ThermalSequence::open(&out).unwrap();
        assert_eq!(seq.frames.len(), summary.frames);
        assert!(summary.frames >= 40 && summary.corners_in_view > 0);
        assert!(seq.frames.iter().all(|f| seq.frame_path(f).is_file()));
        let Provenance::Virtual { generator, seed, effects: recorded, .. } = &seq.manifest.provenance else {
            panic!("virtual provenance expected")
        };
        assert_eq!((generator.as_str(), *seed, recorded.get("tau_mismatch")), (GENERATOR, 5, Some(&0.5)));
        assert_eq!(seq.trajectory.t_s.len(), Trajectory::corner_test(&PrintSetup::paper_defaults()).unwrap().len());
        assert_eq!(seq.path_mm, corner_test_path());
        let [u, v] = seq.camera.nozzle_px;
        assert!((u - 79.5).abs() < 10.0 && (v - 59.5).abs() < 10.0, "nozzle near the image centre: {u} {v}");
        let truth = ThermalTruth::open(&out).unwrap();
        assert!((truth.truth.tau_s - 0.0873 * 1.5).abs() < 1e-12);
        assert_eq!(truth.frames.len(), summary.frames);
        assert_eq!(truth.widths.len(), seq.trajectory.t_s.len());
        // The decoded deposit holds the extruded volume ∫E dt, E = G(s)·E_cmd with the true
        // τ times the layer's flow factor, to the PNG's 1/65535 quantisation.
        let deposit = truth.deposit(0).unwrap();
        let volume = deposit.area_mm2() * seq.process.layer_height_mm;
        let dt = seq.process.sample_period_s;
        let flow = models::thermal::dynamics::first_order_lag(&seq.trajectory.e_mm3_s, dt, truth.truth.tau_s, 0.0);
        let expected = flow.iter().sum::<f64>() * dt * truth.truth.flow_factor[0];
        assert!((volume - expected).abs() < 1e-4 * expected, "{volume} vs {expected}");
    }

    #[test]
    fn output_is_byte_identical_whatever_the_thread_count() {
        let config = GenerateConfig {
            seed: 11,
            layers: 2,
            lepton_habits: LeptonHabits { repeated_frames: true, shutter_freeze: true },
            ..GenerateConfig::default()
        };
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            let (tmp, out, _) = pool.install(|| generated(&config));
            (tmp, all_files(&out))
        };
        let ((_a, one), (_b, two)) = (run(1), run(2));
        assert_eq!(one.keys().collect::<Vec<_>>(), two.keys().collect::<Vec<_>>());
        for (name, bytes) in &one {
            assert!(bytes == &two[name], "{} differs", name.display());
        }
    }

    #[test]
    fn fresh_sharp_corners_are_local_temperature_maxima() {
        // Where the bulge of a corner of 90° or less lies, the frame is hottest: the
        // brightest pixel within 6 px of the true corner pixel lies within a few px of it.
        let (_tmp, out, _) = generated(&GenerateConfig::default());
        let (seq, truth) = (ThermalSequence::open(&out).unwrap(), ThermalTruth::open(&out).unwrap());
        let tr = Trajectory::corner_test(&PrintSetup::paper_defaults()).unwrap();
        let sharp: Vec<usize> = tr.corners.iter().filter(|c| c.interior_angle_deg <= 90.0).map(|c| c.vertex).collect();
        let mut distances = Vec::new();
        for c in truth.corners.iter().filter(|c| sharp.contains(&c.vertex) && c.age_s > 0.1 && c.age_s < 0.8) {
            let entry = seq.frames.iter().find(|f| f.layer == c.layer && f.frame == c.frame).unwrap();
            let (w, h, pixels) = sequence::read_png16(&seq.frame_path(entry), WIDTH_PX, HEIGHT_PX).unwrap();
            distances.push(distance_to_local_max(&pixels, w, h, c.pixel, 6));
        }
        distances.sort_by(f64::total_cmp);
        assert!(distances.len() >= 20, "{} fresh sharp corners in view", distances.len());
        // The pile sits on the corner's bisector, on the inner side where the allocated
        // deposition directions converge, up to about 0.6 mm (≈ 4.5 px) from the vertex
        // for the sharpest corners; the median corner's peak is within 2.5 px.
        let median = distances[distances.len() / 2];
        assert!(median <= 2.5 && *distances.last().unwrap() <= 5.0, "{distances:?}");
    }

    #[test]
    fn frames_decode_to_the_rendered_temperatures() {
        // Rendered °C → centi-kelvin PNG → °C again: exact to the 0.005 K quantisation
        // without noise; with the 50 mK noise the mean absolute difference is ≈ 0.04 K.
        let setup = PrintSetup::paper_defaults();
        let tr = Trajectory::corner_test(&setup).unwrap();
        let deposits = deposition::print_part(
            &setup,
            &tr,
            &setup.conventional_command(&tr),
            1,
            &Effects::none(),
            &mut stream(1, 1),
        )
        .unwrap();
        let heat = &layer_heats(&setup, &tr, &deposits, &Effects::none())[0];
        let rays = camera::pixel_rays(&Intrinsics::lepton35(), &Distortion::lepton35());
        let pose = Mount::nominal().pose(nozzle_at(&tr, 3.0));
        let (min, max) = camera::footprint_mm(&pose, &rays);
        let temps_c = camera::render_temperatures_c(&heat.field(3.0, min, max), &pose, &rays);
        let decode = |pixels: &[u16]| {
            let png = sequence::encode_png16(WIDTH_PX, HEIGHT_PX, pixels);
            let dir = tempfile::tempdir().unwrap();
            std::fs::write(dir.path().join("f.png"), png).unwrap();
            let (_, _, back) = sequence::read_png16(&dir.path().join("f.png"), WIDTH_PX, HEIGHT_PX).unwrap();
            back.iter().map(|v| f64::from(*v) / 100.0 - camera::KELVIN_AT_ZERO_C).collect::<Vec<f64>>()
        };
        let exact: Vec<u16> = temps_c.iter().map(|t| camera::to_centikelvin(*t)).collect();
        let back = decode(&exact);
        assert!(temps_c.iter().zip(&back).all(|(a, b)| (a - b).abs() <= 0.005 + 1e-9));
        let noisy = decode(&camera::to_radiometric(&temps_c, &mut stream(1, 9)));
        let mean_abs = temps_c.iter().zip(&noisy).map(|(a, b)| (a - b).abs()).sum::<f64>() / temps_c.len() as f64;
        assert!((mean_abs - 0.05 * (2.0 / std::f64::consts::PI).sqrt()).abs() < 0.005, "{mean_abs}");
        assert!(temps_c.iter().cloned().fold(0.0, f64::max) > 200.0, "fresh material is in view");
    }

    #[test]
    fn a_layer_count_beyond_the_bound_is_refused_before_printing() {
        let out = tempfile::tempdir().unwrap();
        let config = GenerateConfig { layers: 1_000_000_000, ..GenerateConfig::default() };
        let err = generate_into(&config, out.path()).unwrap_err().to_string();
        assert_eq!(err, "--layers: expected 1 to 10000, got 1000000000");
    }

    #[test]
    fn unknown_effects_never_reach_the_generator() {
        let err = Effects::from_pairs([("nozzle_wobble", 1.0)]).unwrap_err().to_string();
        assert!(err.contains("nozzle_wobble") && err.contains("camera_latency"), "{err}");
    }

    /// Distance (px) from `at` to the brightest pixel within `radius` of it.
    fn distance_to_local_max(pixels: &[u16], w: usize, h: usize, at: [f64; 2], radius: i64) -> f64 {
        let (cu, cv) = (at[0].round() as i64, at[1].round() as i64);
        let mut best = (0u16, cu, cv);
        for dv in -radius..=radius {
            for du in -radius..=radius {
                let (u, v) = (cu + du, cv + dv);
                if u < 0 || v < 0 || u >= w as i64 || v >= h as i64 || du * du + dv * dv > radius * radius {
                    continue;
                }
                let value = pixels[v as usize * w + u as usize];
                if value > best.0 {
                    best = (value, u, v);
                }
            }
        }
        (best.1 as f64 - at[0]).hypot(best.2 as f64 - at[1])
    }
}
