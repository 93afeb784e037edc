//! Reading and writing `inkjet-scans` folders (layout in the module doc of
//! [`crate::inkjet`]); every read error names the file, the line and the field.

use std::path::Path;

use models::inkjet::height_model::Material;
use models::inkjet::DropletCoeffs;
use serde::{Deserialize, Serialize};

use crate::csv_table::CsvTable;
use crate::error::DatasetError;
use crate::limits::{check_numbers, check_size, NumberRule::*, GRID_SIDE_CELLS, MAX_HEIGHT_UM};
use crate::manifest::{DatasetManifest, MANIFEST_FILE};
use crate::paths::file_in;
use crate::text::read_toml;

/// The kind string in `dataset.toml`.
pub const KIND: &str = "inkjet-scans";
/// Current folder layout version.
pub const FORMAT_VERSION: u32 = 1;
/// The folder layout versions this build reads.
pub const READABLE_VERSIONS: &[u32] = &[FORMAT_VERSION];

/// Droplet coefficients as written in `grid.toml`, µm.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CoeffsToml {
    /// Height change at the droplet's cell.
    pub h1_um: f64,
    /// Height change at each side neighbour.
    pub h2_um: f64,
    /// Height change at each corner neighbour.
    pub h3_um: f64,
}

impl From<DropletCoeffs> for CoeffsToml {
    fn from(c: DropletCoeffs) -> Self {
        Self { h1_um: c.h1_um, h2_um: c.h2_um, h3_um: c.h3_um }
    }
}

impl From<CoeffsToml> for DropletCoeffs {
    fn from(c: CoeffsToml) -> Self {
        Self { h1_um: c.h1_um, h2_um: c.h2_um, h3_um: c.h3_um }
    }
}

/// The profiler as written in `grid.toml`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProfilerToml {
    /// Repeatability (noise std), µm.
    pub noise_um: f64,
    /// Gaussian spot std, µm (0: point samples).
    pub spot_sigma_um: f64,
}

/// `grid.toml`: the droplet grid, the nominal droplets and how the print was run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GridToml {
    /// Cells along x.
    pub m_x: usize,
    /// Cells along y.
    pub m_y: usize,
    /// Droplet spacing `L = γ·d`, µm.
    pub spacing_um: f64,
    /// Desired part height `h_d`, µm.
    pub desired_height_um: f64,
    /// What was printed (`cylinder`, `cuboid`, `pipe_junction`, or your own name).
    pub scenario: String,
    /// How the patterns were chosen (`open_loop`, `closed_loop`, or your own name).
    pub controller: String,
    /// Largest droplet-volume shortfall, percent (virtual prints; 0 for measured data).
    #[serde(default)]
    pub variation_pct: f64,
    /// Nominal part-material droplets `(h1, h2, h3)`.
    pub part: CoeffsToml,
    /// Nominal support droplets `(g1, g2, g3)` for two-material prints.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub support: Option<CoeffsToml>,
    /// The height sensor.
    pub profiler: ProfilerToml,
}

/// A whole `inkjet-scans` dataset (without its `truth/`).
#[derive(Debug, Clone, PartialEq)]
pub struct InkjetScans {
    /// Its `dataset.toml`.
    pub manifest: DatasetManifest,
    /// Its `grid.toml`.
    pub grid: GridToml,
    /// Desired height per cell (row-major, `j·m_x + i`), `None` off the footprint.
    pub target: Vec<Option<f64>>,
    /// Measured heights per layer, row-major: `scans[0]` is the substrate, `scans[k]`
    /// the scan after layer `k`.
    pub scans: Vec<Vec<f64>>,
    /// Printed cells per layer: `patterns[k − 1]` is layer `k`, `None` where no droplet.
    pub patterns: Vec<Vec<Option<Material>>>,
}

impl InkjetScans {
    /// Number of printed layers.
    pub fn layers(&self) -> usize {
        self.patterns.len()
    }

    /// Reads and checks a dataset folder (not its `truth/`).
    pub fn read(dir: &Path) -> Result<Self, DatasetError> {
        let manifest = DatasetManifest::read(dir, KIND, READABLE_VERSIONS)?;
        let grid = read_grid(&file_in(dir, "grid.toml")?)?;
        let target = read_target(&file_in(dir, "target.csv")?, &grid)?;
        let scans_file = file_in(dir, "scans.csv")?;
        let scans = read_layers(&scans_file, &grid)?;
        if scans.len() < 2 {
            let expected = "expected the substrate (layer 0) and at least one printed layer, got layer 0 only";
            return Err(DatasetError::Malformed {
                file: scans_file,
                location: Some("layer".into()),
                expected: expected.into(),
            });
        }
        let patterns = read_patterns(&file_in(dir, "patterns.csv")?, &grid, scans.len() - 1)?;
        Ok(Self { manifest, grid, target, scans, patterns })
    }

    /// Reads `truth/heights.csv` of a virtual dataset (evaluation stages only).
    pub fn read_truth(dir: &Path, grid: &GridToml) -> Result<Vec<Vec<f64>>, DatasetError> {
        read_layers(&file_in(dir, "truth/heights.csv")?, grid)
    }

    /// Writes the dataset into `dir` (a fresh staging folder), with `truth` (same
    /// layout as `scans`) into `truth/` when given.
    pub fn write(&self, dir: &Path, truth: Option<&[Vec<f64>]>) -> Result<(), DatasetError> {
        std::fs::create_dir_all(dir).map_err(|e| DatasetError::io(dir, e))?;
        write_file(&dir.join(MANIFEST_FILE), &self.manifest.to_toml())?;
        let grid_text = toml::to_string_pretty(&self.grid).expect("grid serialises");
        write_file(&dir.join("grid.toml"), &grid_text)?;
        let m_x = self.grid.m_x;
        let mut target = String::from("i,j,desired_um\n");
        for (c, want) in self.target.iter().enumerate() {
            if let Some(h) = want {
                target += &format!("{},{},{h}\n", c % m_x, c / m_x);
            }
        }
        write_file(&dir.join("target.csv"), &target)?;
        write_file(&dir.join("scans.csv"), &layers_csv(&self.scans, m_x))?;
        let mut patterns = String::from("layer,i,j,material\n");
        for (k, layer) in self.patterns.iter().enumerate() {
            for (c, m) in layer.iter().enumerate() {
                if let Some(m) = m {
                    patterns += &format!("{},{},{},{}\n", k + 1, c % m_x, c / m_x, material_name(*m));
                }
            }
        }
        write_file(&dir.join("patterns.csv"), &patterns)?;
        if let Some(truth) = truth {
            let truth_dir = dir.join("truth");
            std::fs::create_dir_all(&truth_dir).map_err(|e| DatasetError::io(&truth_dir, e))?;
            write_file(&truth_dir.join("heights.csv"), &layers_csv(truth, m_x))?;
        }
        Ok(())
    }
}

/// `part` / `support`.
pub fn material_name(m: Material) -> &'static str {
    match m {
        Material::Part => "part",
        Material::Support => "support",
    }
}

fn layers_csv(layers: &[Vec<f64>], m_x: usize) -> String {
    let mut text = String::from("layer,i,j,height_um\n");
    for (k, heights) in layers.iter().enumerate() {
        for (c, h) in heights.iter().enumerate() {
            text += &format!("{k},{},{},{h:.4}\n", c % m_x, c / m_x);
        }
    }
    text
}

fn write_file(path: &Path, text: &str) -> Result<(), DatasetError> {
    std::fs::write(path, text).map_err(|e| DatasetError::io(path, e))
}

fn read_grid(file: &Path) -> Result<GridToml, DatasetError> {
    let grid: GridToml = read_toml(file)?;
    check_size(file, "m_x", grid.m_x, &GRID_SIDE_CELLS)?;
    check_size(file, "m_y", grid.m_y, &GRID_SIDE_CELLS)?;
    let p = &grid.profiler;
    check_numbers(
        file,
        &[
            ("spacing_um", grid.spacing_um, Positive),
            ("desired_height_um", grid.desired_height_um, Within(0.0, MAX_HEIGHT_UM)),
            ("variation_pct", grid.variation_pct, Within(0.0, 100.0)),
            ("profiler.noise_um", p.noise_um, NonNegative),
            ("profiler.spot_sigma_um", p.spot_sigma_um, NonNegative),
        ],
    )?;
    let bad = |field: &str, expected: String| DatasetError::Malformed {
        file: file.to_path_buf(),
        location: Some(field.into()),
        expected,
    };
    for (name, c) in [("part", Some(grid.part)), ("support", grid.support)] {
        if let Some(c) = c {
            DropletCoeffs::from(c).check().map_err(|e| bad(name, e.to_string()))?;
        }
    }
    Ok(grid)
}

/// Parses the `i`, `j` fields of a row into a row-major cell index.
fn cell(
    table: &CsvTable,
    row: &(usize, Vec<String>),
    cols: (usize, usize),
    grid: &GridToml,
) -> Result<usize, DatasetError> {
    let index = |col: usize, size: usize| -> Result<usize, DatasetError> {
        let raw = &row.1[col];
        raw.parse::<usize>()
            .ok()
            .filter(|&v| v < size)
            .ok_or_else(|| table.field_error(row.0, col, format!("expected a cell index in 0..{size}, got `{raw}`")))
    };
    Ok(index(cols.1, grid.m_y)? * grid.m_x + index(cols.0, grid.m_x)?)
}

fn read_target(file: &Path, grid: &GridToml) -> Result<Vec<Option<f64>>, DatasetError> {
    let table = CsvTable::read(file)?;
    let cols = (table.column("i")?, table.column("j")?);
    let hc = table.column("desired_um")?;
    let mut target = vec![None; grid.m_x * grid.m_y];
    for row in &table.rows {
        let c = cell(&table, row, cols, grid)?;
        if target[c].is_some() {
            return Err(table.field_error(row.0, cols.0, "this cell is listed twice"));
        }
        target[c] = Some(height_um(&table, row, hc)?);
    }
    Ok(target)
}

/// The height in column `col` of a row, µm: a finite number of magnitude at most
/// [`MAX_HEIGHT_UM`].
fn height_um(table: &CsvTable, row: &(usize, Vec<String>), col: usize) -> Result<f64, DatasetError> {
    let h = table.number(row, col)?;
    if h.abs() <= MAX_HEIGHT_UM {
        Ok(h)
    } else {
        Err(table.field_error(
            row.0,
            col,
            format!("expected a height of at most {MAX_HEIGHT_UM:e} µm in magnitude, got {h:e}"),
        ))
    }
}

/// Reads a `layer,i,j,height_um` file: layers 0..=L, every cell of every layer once.
fn read_layers(file: &Path, grid: &GridToml) -> Result<Vec<Vec<f64>>, DatasetError> {
    let table = CsvTable::read(file)?;
    let (lc, hc) = (table.column("layer")?, table.column("height_um")?);
    let cols = (table.column("i")?, table.column("j")?);
    let cells = grid.m_x * grid.m_y;
    let mut layers: Vec<Vec<f64>> = Vec::new();
    let mut filled: Vec<usize> = Vec::new();
    for row in &table.rows {
        let k = layer_index(&table, row, lc, layers.len() + 1)?;
        if k == layers.len() {
            if filled.last().is_some_and(|&n| n != cells) {
                return Err(table.field_error(
                    row.0,
                    lc,
                    format!("layer {} has {} of {cells} cells", k - 1, filled[k - 1]),
                ));
            }
            layers.push(vec![f64::NAN; cells]);
            filled.push(0);
        }
        let c = cell(&table, row, cols, grid)?;
        if !layers[k][c].is_nan() {
            return Err(table.field_error(row.0, cols.0, format!("cell listed twice in layer {k}")));
        }
        layers[k][c] = height_um(&table, row, hc)?;
        filled[k] += 1;
    }
    if filled.last().is_some_and(|&n| n != cells) {
        let last = table.rows.last().map_or(1, |r| r.0);
        return Err(DatasetError::at_line(
            file,
            last,
            format!("the last layer has {} of {cells} cells", filled[filled.len() - 1]),
        ));
    }
    Ok(layers)
}

/// A layer number that is the current one or the next (`limit` = one past the largest
/// allowed value).
fn layer_index(table: &CsvTable, row: &(usize, Vec<String>), col: usize, limit: usize) -> Result<usize, DatasetError> {
    let raw = &row.1[col];
    let k = raw
        .parse::<usize>()
        .map_err(|_| table.field_error(row.0, col, format!("expected a layer number, got `{raw}`")))?;
    if k + 2 < limit || k >= limit {
        return Err(table.field_error(row.0, col, format!("expected layers in increasing order from 0, got {k}")));
    }
    Ok(k)
}

fn read_patterns(file: &Path, grid: &GridToml, layers: usize) -> Result<Vec<Vec<Option<Material>>>, DatasetError> {
    let table = CsvTable::read(file)?;
    let (lc, mc) = (table.column("layer")?, table.column("material")?);
    let cols = (table.column("i")?, table.column("j")?);
    let mut patterns = vec![vec![None; grid.m_x * grid.m_y]; layers];
    for row in &table.rows {
        let raw = &row.1[lc];
        let k = raw.parse::<usize>().ok().filter(|k| (1..=layers).contains(k)).ok_or_else(|| {
            table.field_error(
                row.0,
                lc,
                format!(
                    "expected a layer in 1..={layers} (scans.csv has {layers} layers after the substrate), got `{raw}`"
                ),
            )
        })?;
        let material = match row.1[mc].as_str() {
            "part" => Material::Part,
            "support" => Material::Support,
            other => return Err(table.field_error(row.0, mc, format!("expected `part` or `support`, got `{other}`"))),
        };
        let c = cell(&table, row, cols, grid)?;
        if patterns[k - 1][c].replace(material).is_some() {
            return Err(table.field_error(row.0, cols.0, format!("cell listed twice in layer {k}")));
        }
    }
    Ok(patterns)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The files of the worked example in docs/DATASETS.md (`$ cat my-print/<file>`
    /// blocks of the inkjet-scans section).
    fn worked_example(dir: &Path) {
        let doc = include_str!("../../../docs/DATASETS.md");
        let section = &doc[doc.find("## Kind `inkjet-scans`").expect("section")..];
        let example = &section[section.find("$ cat my-print/").expect("example")..];
        let example = &example[..example.find("```").expect("end of block")];
        for block in example.split("$ cat my-print/").skip(1) {
            let (name, body) = block.split_once('\n').expect("file name line");
            std::fs::write(dir.join(name.trim()), body.trim_end().to_string() + "\n").unwrap();
        }
    }

    #[test]
    fn the_documented_worked_example_reads() {
        let dir = tempfile::tempdir().unwrap();
        worked_example(dir.path());
        let scans = InkjetScans::read(dir.path()).unwrap();
        assert_eq!((scans.grid.m_x, scans.grid.m_y, scans.layers()), (3, 2, 1));
        assert_eq!(scans.target.iter().filter(|t| t.is_some()).count(), 2);
        assert_eq!(scans.scans[1][4], 6.0);
        assert_eq!(scans.patterns[0][1], Some(Material::Part));
        assert_eq!(scans.patterns[0][0], None);
    }

    /// The worked example with `from` replaced by `to` in `file`; the read error.
    fn read_error(file: &str, from: &str, to: &str) -> String {
        let dir = tempfile::tempdir().unwrap();
        worked_example(dir.path());
        let path = dir.path().join(file);
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(text.contains(from), "{file} has no `{from}`");
        std::fs::write(&path, text.replacen(from, to, 1)).unwrap();
        InkjetScans::read(dir.path()).unwrap_err().to_string()
    }

    #[test]
    fn grid_sizes_outside_the_bounds_are_refused_before_anything_is_allocated() {
        // m_x = m_y = 10⁹ used to allocate 10¹⁸ cells for target.csv (SIGABRT).
        let err = read_error("grid.toml", "m_x = 3", "m_x = 1000000000");
        assert!(err.contains("grid.toml:m_x: expected 1 to 2048, got 1000000000"), "{err}");
        let err = read_error("grid.toml", "m_y = 2", "m_y = 0");
        assert!(err.contains("grid.toml:m_y: expected 1 to 2048, got 0"), "{err}");
        let err = read_error("grid.toml", "noise_um = 1.0", "noise_um = nan");
        assert!(err.contains("grid.toml:profiler.noise_um: expected a finite number ≥ 0, got NaN"), "{err}");
        let err = read_error("dataset.toml", "format_version = 1", "format_version = 3");
        assert!(err.contains("this build of amrepro reads `inkjet-scans` format_version 1, got 3"), "{err}");
    }

    #[test]
    fn heights_beyond_a_metre_are_refused() {
        let err = read_error("scans.csv", "1,1,0,5.9", "1,1,0,1e300");
        assert!(
            err.contains(
                "scans.csv:line 9, field height_um: expected a height of at most 1e6 µm in magnitude, got 1e300"
            ),
            "{err}"
        );
        let err = read_error("target.csv", "1,1,7.6", "1,1,-2e7");
        assert!(err.contains("target.csv:line 3, field desired_um: expected a height of at most 1e6 µm"), "{err}");
    }

    #[test]
    fn scans_without_a_printed_layer_are_named() {
        let dir = tempfile::tempdir().unwrap();
        worked_example(dir.path());
        let scans = dir.path().join("scans.csv");
        let text: String = std::fs::read_to_string(&scans).unwrap().lines().take(7).map(|l| format!("{l}\n")).collect();
        std::fs::write(&scans, text).unwrap();
        let err = InkjetScans::read(dir.path()).unwrap_err().to_string();
        assert!(
            err.contains("scans.csv:layer: expected the substrate (layer 0) and at least one printed layer"),
            "{err}"
        );
    }

    #[test]
    fn files_with_a_byte_order_mark_read() {
        let dir = tempfile::tempdir().unwrap();
        worked_example(dir.path());
        for name in ["dataset.toml", "grid.toml", "target.csv", "scans.csv", "patterns.csv"] {
            let file = dir.path().join(name);
            let text = std::fs::read_to_string(&file).unwrap();
            std::fs::write(&file, format!("\u{feff}{text}")).unwrap();
        }
        assert_eq!(InkjetScans::read(dir.path()).unwrap().layers(), 1);
    }
}
