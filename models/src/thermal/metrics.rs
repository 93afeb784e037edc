//! Evaluation metrics of paper 003, Sec. 3.3, on deposited layers ([`DepositGrid`]):
//! the over-deposition index at a corner (eq. 40) and the contour error (eq. 41).
//!
//! - The CAD part is the unblended polygon swept by a bead of half width w0 with mitered
//!   (sharp) joins: the region between the inner and outer offset polygons at ±w0
//!   ([`IdealBead`]). Offsets of a counter-clockwise polygon are taken to the left
//!   (inside) for +w0; a clockwise one is handled by its signed area.
//! - Eq. 40: O_E = A_o/A_c in a corner window, a disc of radius R_c about the CAD
//!   vertex. The paper does not define the window; we default to R_c = 4·w0 (two bead
//!   widths, [`default_corner_radius_mm`]), which holds the corner's bulge of the lagged
//!   flow while staying clear of the neighbouring corners of the test path (≥ 5 mm apart).
//!   A_c ("perfect corner polytope area") is the ideal bead's area in the window, A_o the
//!   deposited area (fill-weighted cells) in the window outside the ideal bead; the
//!   under-deposited area (ideal, not filled) is returned for the figure. Cells are
//!   classified by their centres, so areas are exact to about one cell along the edges.
//! - Eq. 41: CAD contour points P_t every 0.05 mm along both offset polygons; the measured
//!   profile P_m is the fill = 0.5 iso-line of the deposit (marching squares between cell
//!   centres, linear interpolation, cells outside the grid count as empty so contours
//!   close); e_t = distance from each CAD point to the nearest iso-line segment (a point on
//!   the segment rather than a segment end, so e_t is not limited by the sampling of P_m),
//!   found through a uniform bucket grid. Summary: max and RMS over all points of all layers.
//!   Eq. 41 is unsigned; each point also records whether the print covers it (the error is
//!   a bulge beyond it) or not (the print falls short of it), and [`summarize_regions`]
//!   breaks the error down by where on the part it lies ([`ContourRegion`]).

use super::deposit::DepositGrid;
use super::errors::{positive, ThermalError};

/// Spacing of the CAD contour points P_t (mm).
pub const CONTOUR_SPACING_MM: f64 = 0.05;
/// Fill level of the measured profile.
pub const FOOTPRINT_LEVEL: f64 = 0.5;
/// Bucket edge of the nearest-segment search, in cells.
const BUCKET_CELLS: usize = 8;

/// The ideal (CAD) bead: a closed polygon swept by a bead of half width w0, mitered.
#[derive(Debug, Clone, PartialEq)]
pub struct IdealBead {
    /// The polygon the nozzle follows (mm).
    pub centre_mm: Vec<[f64; 2]>,
    /// Half width w0 (mm).
    pub half_width_mm: f64,
    /// Offset polygon inside the part (mm).
    pub inner_mm: Vec<[f64; 2]>,
    /// Offset polygon outside the part (mm).
    pub outer_mm: Vec<[f64; 2]>,
}

/// Over-deposition in one corner window (eq. 40).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CornerDeposition {
    /// Window centre: the CAD vertex (mm).
    pub centre_mm: [f64; 2],
    /// Window radius R_c (mm).
    pub radius_mm: f64,
    /// A_c: ideal bead area in the window (mm²).
    pub ideal_area_mm2: f64,
    /// A_o: deposited area in the window outside the ideal bead (mm²).
    pub over_area_mm2: f64,
    /// Ideal bead area in the window left unfilled (mm²).
    pub under_area_mm2: f64,
    /// O_E = A_o/A_c.
    pub index: f64,
}

/// One element (x_t, y_t, e_t) of the error set of eq. 41.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContourPoint {
    /// CAD point x_t (mm).
    pub x_mm: f64,
    /// CAD point y_t (mm).
    pub y_mm: f64,
    /// Contour error e_t (mm); ∞ if the layer has no footprint.
    pub error_mm: f64,
    /// True if the CAD point lies inside the printed footprint (fill ≥ 0.5): the printed
    /// edge is beyond it, a bulge; false: the print falls short of it.
    pub covered: bool,
}

/// Where on the part a CAD contour point lies, to break eq. 41's error down.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum ContourRegion {
    /// Within the corner radius of CAD vertex `i`, its nearest vertex.
    Corner(usize),
    /// Within the seam radius of the point where every layer starts and ends.
    Seam,
    /// Anywhere else: the straight runs between corners.
    Straight,
}

/// Eq. 41's error over one [`ContourRegion`], all layers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RegionSummary {
    /// Number of (point, layer) pairs.
    pub points: usize,
    /// Largest e_t (mm).
    pub max_mm: f64,
    /// Whether the print covers the CAD point of the largest e_t (a bulge) or not (short).
    pub max_covered: bool,
    /// Sum of e_t² (mm²): its share of the whole is the region's share of the squared RMS.
    pub sum_sq_mm2: f64,
}

/// Max and RMS of e_t over all points of all layers (Table 3).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContourSummary {
    /// Largest e_t (mm).
    pub max_mm: f64,
    /// Root mean square of e_t (mm).
    pub rms_mm: f64,
    /// Number of points.
    pub points: usize,
}

impl IdealBead {
    /// The bead of half width `half_width_mm` along the closed polygon `vertices`.
    pub fn new(vertices: &[[f64; 2]], half_width_mm: f64) -> Result<Self, ThermalError> {
        positive("half_width_mm", half_width_mm)?;
        if vertices.len() < 3 {
            return Err(ThermalError::TooFewVertices { found: vertices.len() });
        }
        let inward = signed_area_mm2(vertices).signum() * half_width_mm;
        Ok(Self {
            centre_mm: vertices.to_vec(),
            half_width_mm,
            inner_mm: offset_polygon(vertices, inward),
            outer_mm: offset_polygon(vertices, -inward),
        })
    }

    /// True if `point_mm` lies in the ideal bead (inside the outer, outside the inner polygon).
    pub fn contains(&self, point_mm: [f64; 2]) -> bool {
        point_in_polygon(point_mm, &self.outer_mm) && !point_in_polygon(point_mm, &self.inner_mm)
    }

    /// Distance (mm) from `point_mm` along the unit direction `dir` to the first
    /// crossing of the bead's boundary (either offset polygon); 0 if `point_mm` lies
    /// outside the bead. This is the ideal deposit's half width along a deposition
    /// direction, the exact form of eq. 31's w0/cos φ (which assumes a straight bead).
    pub fn edge_distance_mm(&self, point_mm: [f64; 2], dir: [f64; 2]) -> f64 {
        if !self.contains(point_mm) {
            return 0.0;
        }
        [&self.outer_mm, &self.inner_mm]
            .iter()
            .flat_map(|polygon| {
                (0..polygon.len())
                    .filter_map(|i| ray_segment_mm(point_mm, dir, polygon[i], polygon[(i + 1) % polygon.len()]))
            })
            .fold(f64::INFINITY, f64::min)
    }

    /// CAD contour points P_t of eq. 41, every `spacing_mm`: the outer offset polygon,
    /// the part's external surface the paper's profiler measures (Sec. 3.3), and with
    /// `with_inner_face` the inner one too (the wall's inside face).
    pub fn contour_points(&self, spacing_mm: f64, with_inner_face: bool) -> Vec<[f64; 2]> {
        let mut points = sample_polygon(&self.outer_mm, spacing_mm);
        if with_inner_face {
            points.extend(sample_polygon(&self.inner_mm, spacing_mm));
        }
        points
    }
}

/// Default corner window radius R_c = 4·w0 (mm), see the module doc.
pub fn default_corner_radius_mm(half_width_mm: f64) -> f64 {
    4.0 * half_width_mm
}

/// The polygon with every edge moved `left_offset_mm` to its left, joined with miters.
pub fn offset_polygon(vertices: &[[f64; 2]], left_offset_mm: f64) -> Vec<[f64; 2]> {
    let n = vertices.len();
    let normal = |i: usize| {
        let (a, b) = (vertices[i % n], vertices[(i + 1) % n]);
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let len = dx.hypot(dy);
        [-dy / len, dx / len]
    };
    (0..n)
        .map(|i| {
            let (np, nn) = (normal(i + n - 1), normal(i));
            let scale = left_offset_mm / (1.0 + np[0] * nn[0] + np[1] * nn[1]);
            [vertices[i][0] + scale * (np[0] + nn[0]), vertices[i][1] + scale * (np[1] + nn[1])]
        })
        .collect()
}

/// Distance along the ray p + r·dir (r > 0, `dir` unit) to the segment a-b, if it meets it.
fn ray_segment_mm(p: [f64; 2], dir: [f64; 2], a: [f64; 2], b: [f64; 2]) -> Option<f64> {
    let (ex, ey) = (b[0] - a[0], b[1] - a[1]);
    let denom = dir[0] * ey - dir[1] * ex;
    if denom.abs() < 1e-15 {
        return None;
    }
    let (qx, qy) = (a[0] - p[0], a[1] - p[1]);
    let r = (qx * ey - qy * ex) / denom;
    let u = (qx * dir[1] - qy * dir[0]) / denom;
    (r > 0.0 && (0.0..=1.0).contains(&u)).then_some(r)
}

/// Even-odd point-in-polygon test.
pub fn point_in_polygon(p: [f64; 2], polygon: &[[f64; 2]]) -> bool {
    let mut inside = false;
    let mut j = polygon.len() - 1;
    for i in 0..polygon.len() {
        let (a, b) = (polygon[i], polygon[j]);
        if (a[1] > p[1]) != (b[1] > p[1]) && p[0] < (b[0] - a[0]) * (p[1] - a[1]) / (b[1] - a[1]) + a[0] {
            inside = !inside;
        }
        j = i;
    }
    inside
}

/// Points every `spacing_mm` (or closer, evenly per edge) along the closed polygon.
pub fn sample_polygon(polygon: &[[f64; 2]], spacing_mm: f64) -> Vec<[f64; 2]> {
    let n = polygon.len();
    let mut points = Vec::new();
    for i in 0..n {
        let (a, b) = (polygon[i], polygon[(i + 1) % n]);
        let steps = ((b[0] - a[0]).hypot(b[1] - a[1]) / spacing_mm).ceil().max(1.0) as usize;
        points.extend((0..steps).map(|s| {
            let f = s as f64 / steps as f64;
            [a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1])]
        }));
    }
    points
}

/// Eq. 40 in the disc of `radius_mm` about `centre_mm`.
pub fn corner_deposition(
    grid: &DepositGrid,
    bead: &IdealBead,
    centre_mm: [f64; 2],
    radius_mm: f64,
) -> CornerDeposition {
    let cell_area = grid.cell_mm * grid.cell_mm;
    let (mut ideal, mut over, mut under) = (0.0, 0.0, 0.0);
    let (ix0, ix1) =
        index_range(centre_mm[0] - radius_mm, centre_mm[0] + radius_mm, grid.origin_mm[0], grid.cell_mm, grid.nx);
    let (iy0, iy1) =
        index_range(centre_mm[1] - radius_mm, centre_mm[1] + radius_mm, grid.origin_mm[1], grid.cell_mm, grid.ny);
    for iy in iy0..iy1 {
        for ix in ix0..ix1 {
            let c = grid.cell_center_mm(ix, iy);
            if (c[0] - centre_mm[0]).hypot(c[1] - centre_mm[1]) > radius_mm {
                continue;
            }
            let fill = f64::from(grid.fill[grid.index(ix, iy)]);
            if bead.contains(c) {
                ideal += cell_area;
                under += (1.0 - fill) * cell_area;
            } else {
                over += fill * cell_area;
            }
        }
    }
    let index = if ideal > 0.0 { over / ideal } else { f64::NAN };
    CornerDeposition { centre_mm, radius_mm, ideal_area_mm2: ideal, over_area_mm2: over, under_area_mm2: under, index }
}

/// Eq. 40 at every vertex of the CAD polygon.
pub fn corner_depositions(grid: &DepositGrid, bead: &IdealBead, radius_mm: f64) -> Vec<CornerDeposition> {
    bead.centre_mm.iter().map(|v| corner_deposition(grid, bead, *v, radius_mm)).collect()
}

/// Eq. 41 for one layer: e_t at every CAD point against the fill = 0.5 iso-line.
pub fn contour_errors(grid: &DepositGrid, cad_points_mm: &[[f64; 2]]) -> Vec<ContourPoint> {
    let segments = level_contour(grid, FOOTPRINT_LEVEL);
    let index = SegmentBuckets::new(grid, &segments);
    cad_points_mm
        .iter()
        .map(|p| ContourPoint {
            x_mm: p[0],
            y_mm: p[1],
            error_mm: index.nearest_distance_mm(*p, &segments),
            covered: grid.fill_at(*p) >= FOOTPRINT_LEVEL,
        })
        .collect()
}

/// The region of `point_mm`: the nearest of `vertices` if within `corner_radius_mm`,
/// else the seam if within `seam_radius_mm` of `seam_mm`, else straight.
pub fn contour_region(
    point_mm: [f64; 2],
    vertices: &[[f64; 2]],
    corner_radius_mm: f64,
    seam_mm: [f64; 2],
    seam_radius_mm: f64,
) -> ContourRegion {
    let distance = |v: [f64; 2]| (v[0] - point_mm[0]).hypot(v[1] - point_mm[1]);
    let nearest = (0..vertices.len()).min_by(|&a, &b| distance(vertices[a]).total_cmp(&distance(vertices[b])));
    match nearest {
        Some(i) if distance(vertices[i]) <= corner_radius_mm => ContourRegion::Corner(i),
        _ if distance(seam_mm) <= seam_radius_mm => ContourRegion::Seam,
        _ => ContourRegion::Straight,
    }
}

/// Eq. 41 per region over all layers; `regions[j]` is the region of every layer's CAD
/// point `j` (every layer has the same CAD points). Regions without points are absent.
pub fn summarize_regions(
    layers: &[Vec<ContourPoint>],
    regions: &[ContourRegion],
) -> std::collections::BTreeMap<ContourRegion, RegionSummary> {
    let mut out = std::collections::BTreeMap::new();
    for layer in layers {
        for (p, region) in layer.iter().zip(regions) {
            let s = out.entry(*region).or_insert(RegionSummary {
                points: 0,
                max_mm: f64::NEG_INFINITY,
                max_covered: false,
                sum_sq_mm2: 0.0,
            });
            s.points += 1;
            s.sum_sq_mm2 += p.error_mm * p.error_mm;
            if p.error_mm > s.max_mm {
                s.max_mm = p.error_mm;
                s.max_covered = p.covered;
            }
        }
    }
    out
}

/// Max and RMS of e_t over all layers.
pub fn summarize(layers: &[Vec<ContourPoint>]) -> ContourSummary {
    let (mut max_mm, mut sum_sq, mut points) = (0.0_f64, 0.0, 0);
    for p in layers.iter().flatten() {
        max_mm = max_mm.max(p.error_mm);
        sum_sq += p.error_mm * p.error_mm;
        points += 1;
    }
    let rms_mm = if points > 0 { (sum_sq / points as f64).sqrt() } else { f64::NAN };
    ContourSummary { max_mm, rms_mm, points }
}

/// Marching squares on the cell-centre samples of `grid` at `level`: the iso-line as
/// segments (mm). Cells beyond the grid count as empty.
pub fn level_contour(grid: &DepositGrid, level: f64) -> Vec<[[f64; 2]; 2]> {
    let value = |ix: isize, iy: isize| -> f64 {
        let inside = ix >= 0 && iy >= 0 && (ix as usize) < grid.nx && (iy as usize) < grid.ny;
        if inside {
            f64::from(grid.fill[grid.index(ix as usize, iy as usize)])
        } else {
            0.0
        }
    };
    let mut segments = Vec::new();
    for iy in -1..grid.ny as isize {
        for ix in -1..grid.nx as isize {
            let corners = [value(ix, iy), value(ix + 1, iy), value(ix + 1, iy + 1), value(ix, iy + 1)];
            let case = corners.iter().enumerate().fold(0, |c, (i, v)| c | (usize::from(*v >= level) << i));
            if case == 0 || case == 15 {
                continue;
            }
            let origin = [
                grid.origin_mm[0] + (ix as f64 + 0.5) * grid.cell_mm,
                grid.origin_mm[1] + (iy as f64 + 0.5) * grid.cell_mm,
            ];
            let centre_inside = corners.iter().sum::<f64>() / 4.0 >= level;
            for [e0, e1] in square_edges(case, centre_inside) {
                let a = edge_point(e0, &corners, level, origin, grid.cell_mm);
                let b = edge_point(e1, &corners, level, origin, grid.cell_mm);
                segments.push([a, b]);
            }
        }
    }
    segments
}

/// Edge pairs crossed by the iso-line for a marching-squares case (bit i: corner i
/// inside; corners 0..3 counter-clockwise from lower-left; edge i joins corners i, i+1).
fn square_edges(case: usize, centre_inside: bool) -> Vec<[usize; 2]> {
    match case {
        1 | 14 => vec![[3, 0]],
        2 | 13 => vec![[0, 1]],
        3 | 12 => vec![[3, 1]],
        4 | 11 => vec![[1, 2]],
        6 | 9 => vec![[0, 2]],
        7 | 8 => vec![[3, 2]],
        // Saddles: the centre decides whether the two inside corners connect.
        5 if centre_inside => vec![[0, 1], [2, 3]],
        5 => vec![[3, 0], [1, 2]],
        10 if centre_inside => vec![[3, 0], [1, 2]],
        10 => vec![[0, 1], [2, 3]],
        _ => Vec::new(),
    }
}

/// Where the iso-line crosses edge `edge` of the square, by linear interpolation.
fn edge_point(edge: usize, corners: &[f64; 4], level: f64, origin: [f64; 2], cell: f64) -> [f64; 2] {
    const OFFSETS: [[f64; 2]; 4] = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
    let (i, j) = (edge, (edge + 1) % 4);
    let f = (level - corners[i]) / (corners[j] - corners[i]);
    let (a, b) = (OFFSETS[i], OFFSETS[j]);
    [origin[0] + cell * (a[0] + f * (b[0] - a[0])), origin[1] + cell * (a[1] + f * (b[1] - a[1]))]
}

/// Indices of the cells overlapping [lo, hi] along one axis (half-open range).
fn index_range(lo: f64, hi: f64, origin: f64, cell: f64, n: usize) -> (usize, usize) {
    let first = ((lo - origin) / cell).floor().max(0.0) as usize;
    let last = (((hi - origin) / cell).ceil().max(0.0) as usize).min(n);
    (first.min(n), last)
}

/// Twice-signed area / 2 of a polygon (mm², + counter-clockwise).
fn signed_area_mm2(vertices: &[[f64; 2]]) -> f64 {
    let n = vertices.len();
    (0..n).map(|i| vertices[i][0] * vertices[(i + 1) % n][1] - vertices[(i + 1) % n][0] * vertices[i][1]).sum::<f64>()
        / 2.0
}

/// Distance from `p` to the segment a-b.
fn point_segment_distance(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len2 = dx * dx + dy * dy;
    let t = if len2 > 0.0 { (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / len2).clamp(0.0, 1.0) } else { 0.0 };
    (p[0] - a[0] - t * dx).hypot(p[1] - a[1] - t * dy)
}

/// A uniform bucket grid over the segments for nearest-segment queries.
struct SegmentBuckets {
    origin_mm: [f64; 2],
    size_mm: f64,
    nx: usize,
    ny: usize,
    buckets: Vec<Vec<u32>>,
}

impl SegmentBuckets {
    fn new(grid: &DepositGrid, segments: &[[[f64; 2]; 2]]) -> Self {
        let size_mm = grid.cell_mm * BUCKET_CELLS as f64;
        // One cell of margin: the iso-line can pass half a cell outside the grid.
        let origin_mm = [grid.origin_mm[0] - grid.cell_mm, grid.origin_mm[1] - grid.cell_mm];
        let nx = (grid.nx + 2).div_ceil(BUCKET_CELLS);
        let ny = (grid.ny + 2).div_ceil(BUCKET_CELLS);
        let mut out = Self { origin_mm, size_mm, nx, ny, buckets: vec![Vec::new(); nx * ny] };
        for (i, [a, b]) in segments.iter().enumerate() {
            let (bx0, by0) = out.bucket_of([a[0].min(b[0]), a[1].min(b[1])]);
            let (bx1, by1) = out.bucket_of([a[0].max(b[0]), a[1].max(b[1])]);
            for by in by0..=by1 {
                for bx in bx0..=bx1 {
                    out.buckets[by * nx + bx].push(i as u32);
                }
            }
        }
        out
    }

    /// Bucket holding `p`, clamped into the bucket grid.
    fn bucket_of(&self, p: [f64; 2]) -> (usize, usize) {
        let bx = ((p[0] - self.origin_mm[0]) / self.size_mm).floor().clamp(0.0, (self.nx - 1) as f64) as usize;
        let by = ((p[1] - self.origin_mm[1]) / self.size_mm).floor().clamp(0.0, (self.ny - 1) as f64) as usize;
        (bx, by)
    }

    /// Distance from `p` to the nearest segment: rings of buckets outwards until no
    /// unvisited bucket can hold anything closer.
    fn nearest_distance_mm(&self, p: [f64; 2], segments: &[[[f64; 2]; 2]]) -> f64 {
        let (cx, cy) = self.bucket_of(p);
        // How far p lies outside its (clamped) bucket: rings are measured from that bucket.
        let lo = [self.origin_mm[0] + cx as f64 * self.size_mm, self.origin_mm[1] + cy as f64 * self.size_mm];
        let outside = (lo[0] - p[0])
            .max(p[0] - lo[0] - self.size_mm)
            .max(0.0)
            .hypot((lo[1] - p[1]).max(p[1] - lo[1] - self.size_mm).max(0.0));
        let mut best = f64::INFINITY;
        for ring in 0..=self.nx.max(self.ny) {
            for (bx, by) in ring_buckets(cx, cy, ring, self.nx, self.ny) {
                for &i in &self.buckets[by * self.nx + bx] {
                    let [a, b] = segments[i as usize];
                    best = best.min(point_segment_distance(p, a, b));
                }
            }
            if best <= ring as f64 * self.size_mm - outside {
                break;
            }
        }
        best
    }
}

/// The buckets at Chebyshev distance `ring` from (cx, cy), within the grid.
fn ring_buckets(cx: usize, cy: usize, ring: usize, nx: usize, ny: usize) -> impl Iterator<Item = (usize, usize)> {
    let (cx, cy, r) = (cx as isize, cy as isize, ring as isize);
    (cy - r..=cy + r)
        .flat_map(move |y| (cx - r..=cx + r).map(move |x| (x, y)))
        .filter(move |&(x, y)| (x - cx).abs().max((y - cy).abs()) == r)
        .filter(move |&(x, y)| x >= 0 && y >= 0 && (x as usize) < nx && (y as usize) < ny)
        .map(|(x, y)| (x as usize, y as usize))
}

/// A_c of eq. 40: the perfect corner polytope, the rhombus where the two edges' ideal
/// beads of width `bead_width_mm` overlap at interior angle θ, W²/sin θ (mm²).
pub fn corner_polytope_area_mm2(bead_width_mm: f64, interior_angle_deg: f64) -> f64 {
    bead_width_mm * bead_width_mm / interior_angle_deg.to_radians().sin()
}

/// A printed part scored as paper 003 Sec. 3.3 scores it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PrintQuality {
    /// Mean over the CAD corners of the first layer's O_E = A_o/A_c (eq. 40), percent.
    pub mean_oe_pct: f64,
    /// Eq. 41 over every layer: the largest contour error (mm).
    pub contour_max_mm: f64,
    /// Eq. 41 over every layer: the RMS contour error (mm).
    pub contour_rms_mm: f64,
}

/// [`PrintQuality`] of the printed `layers` against the ideal `bead` of width
/// `bead_width_mm` along the CAD polygon `path_mm`: O_E in a window of `corner_radius_mm`
/// around each vertex, eq. 41 at the CAD points `cad_points_mm`.
pub fn print_quality(
    layers: &[DepositGrid],
    bead: &IdealBead,
    path_mm: &[[f64; 2]],
    bead_width_mm: f64,
    corner_radius_mm: f64,
    cad_points_mm: &[[f64; 2]],
) -> PrintQuality {
    let angles = super::setup::interior_angles_deg(path_mm);
    let oe: Vec<f64> = match layers.first() {
        Some(first) => path_mm
            .iter()
            .zip(&angles)
            .map(|(v, a)| {
                let corner = corner_deposition(first, bead, *v, corner_radius_mm);
                100.0 * corner.over_area_mm2 / corner_polytope_area_mm2(bead_width_mm, *a)
            })
            .collect(),
        None => vec![],
    };
    let mean_oe_pct = if oe.is_empty() { f64::NAN } else { oe.iter().sum::<f64>() / oe.len() as f64 };
    let errors: Vec<Vec<ContourPoint>> = layers.iter().map(|g| contour_errors(g, cad_points_mm)).collect();
    let contour = summarize(&errors);
    PrintQuality { mean_oe_pct, contour_max_mm: contour.max_mm, contour_rms_mm: contour.rms_mm }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::thermal::setup::corner_test_path;

    /// Fill = fraction of `sub`×`sub` sub-samples of each cell for which `inside` holds.
    fn rasterise(grid: &mut DepositGrid, sub: usize, inside: impl Fn([f64; 2]) -> bool + Sync) {
        let (cell, origin, nx) = (grid.cell_mm, grid.origin_mm, grid.nx);
        for (i, fill) in grid.fill.iter_mut().enumerate() {
            let (ix, iy) = (i % nx, i / nx);
            let mut count = 0;
            for sy in 0..sub {
                for sx in 0..sub {
                    let x = origin[0] + (ix as f64 + (sx as f64 + 0.5) / sub as f64) * cell;
                    let y = origin[1] + (iy as f64 + (sy as f64 + 0.5) / sub as f64) * cell;
                    count += usize::from(inside([x, y]));
                }
            }
            *fill = count as f32 / (sub * sub) as f32;
        }
    }

    #[test]
    fn offsets_of_a_square_are_squares() {
        let square = [[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]];
        let bead = IdealBead::new(&square, 1.0).unwrap();
        let close =
            |a: &[[f64; 2]], b: &[[f64; 2]]| a.iter().zip(b).all(|(p, q)| (p[0] - q[0]).hypot(p[1] - q[1]) < 1e-12);
        assert!(close(&bead.inner_mm, &[[1.0, 1.0], [9.0, 1.0], [9.0, 9.0], [1.0, 9.0]]));
        assert!(close(&bead.outer_mm, &[[-1.0, -1.0], [11.0, -1.0], [11.0, 11.0], [-1.0, 11.0]]));
        // Clockwise input gives the same bead.
        let mut cw = square.to_vec();
        cw.reverse();
        let bead_cw = IdealBead::new(&cw, 1.0).unwrap();
        assert!(bead_cw.contains([0.5, 5.0]) && !bead_cw.contains([5.0, 5.0]) && !bead_cw.contains([-1.5, 5.0]));
    }

    #[test]
    fn ideal_deposit_has_no_over_deposition_and_sub_cell_contour_error() {
        let w0 = 0.225;
        let bead = IdealBead::new(&corner_test_path(), w0).unwrap();
        let cell = 0.025;
        let mut grid = DepositGrid::covering([-1.5, -6.5], [39.0, 16.5], cell);
        rasterise(&mut grid, 3, |p| bead.contains(p));
        for c in corner_depositions(&grid, &bead, default_corner_radius_mm(w0)) {
            // Only boundary cells split by the edge carry fill outside the ideal bead.
            assert!(c.index < 0.05, "corner at {:?}: O_E {}", c.centre_mm, c.index);
            assert!(c.ideal_area_mm2 > 0.5);
        }
        let errors = contour_errors(&grid, &bead.contour_points(CONTOUR_SPACING_MM, true));
        let summary = summarize(&[errors]);
        eprintln!("ideal deposit: max {} mm rms {} mm over {} points", summary.max_mm, summary.rms_mm, summary.points);
        assert!(summary.rms_mm < 0.1 * cell, "rms {}", summary.rms_mm);
        assert!(summary.max_mm < cell, "max {}", summary.max_mm);
    }

    #[test]
    fn grown_deposit_gives_the_margin_and_the_analytic_area_ratio() {
        // A square path; the window sits on the middle of the bottom edge, where the
        // ideal bead is the strip |y| ≤ w0. The deposit is the strip |y| ≤ w0 + d.
        let (w0, d, radius) = (0.225, 0.1, 0.9);
        let bead = IdealBead::new(&[[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]], w0).unwrap();
        let cell = 0.005;
        let mut grid = DepositGrid::covering([3.0, -1.5], [7.0, 1.5], cell);
        rasterise(&mut grid, 1, |p| p[1].abs() <= w0 + d);
        // Area of the strip |y| ≤ a inside a disc of radius R: 2(a·sqrt(R²−a²) + R²·asin(a/R)).
        let strip = |a: f64| 2.0 * (a * (radius * radius - a * a).sqrt() + radius * radius * (a / radius).asin());
        let expected = (strip(w0 + d) - strip(w0)) / strip(w0);
        let c = corner_deposition(&grid, &bead, [5.0, 0.0], radius);
        assert!((c.index - expected).abs() < 0.01 * expected, "O_E {} vs {expected}", c.index);
        assert!(c.under_area_mm2.abs() < 1e-12);
        let cad: Vec<[f64; 2]> =
            (0..=40).flat_map(|i| [[4.0 + 0.05 * i as f64, w0], [4.0 + 0.05 * i as f64, -w0]]).collect();
        let errors = contour_errors(&grid, &cad);
        assert!(errors.iter().all(|e| (e.error_mm - d).abs() < cell), "{:?}", errors[0]);
        assert!(errors.iter().all(|e| e.covered), "a bulge covers the CAD points");
        assert!((summarize(&[errors]).max_mm - d).abs() < cell);
        // The strip shrunk by d instead: the same error, but the print falls short.
        rasterise(&mut grid, 1, |p| p[1].abs() <= w0 - d);
        let short = contour_errors(&grid, &cad);
        assert!(short.iter().all(|e| (e.error_mm - d).abs() < cell && !e.covered));
    }

    #[test]
    fn regions_split_the_error_and_add_up_to_the_whole() {
        let vertices = [[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]];
        let seam = [10.0, 5.0];
        let region = |p: [f64; 2]| contour_region(p, &vertices, 1.0, seam, 2.0);
        assert_eq!(region([10.5, 0.5]), ContourRegion::Corner(1));
        assert_eq!(region([-0.5, 10.5]), ContourRegion::Corner(3));
        assert_eq!(region([10.2, 6.0]), ContourRegion::Seam);
        assert_eq!(region([5.0, -0.2]), ContourRegion::Straight);
        let point = |x: f64, e: f64, covered: bool| ContourPoint { x_mm: x, y_mm: 0.0, error_mm: e, covered };
        let layers = vec![
            vec![point(0.0, 0.3, false), point(5.0, 0.1, true), point(6.0, 0.2, true)],
            vec![point(0.0, 0.1, true), point(5.0, 0.4, true), point(6.0, 0.0, false)],
        ];
        let regions = [ContourRegion::Corner(0), ContourRegion::Straight, ContourRegion::Straight];
        let by = summarize_regions(&layers, &regions);
        let corner = by[&ContourRegion::Corner(0)];
        assert_eq!((corner.points, corner.max_mm, corner.max_covered), (2, 0.3, false));
        let straight = by[&ContourRegion::Straight];
        assert_eq!((straight.points, straight.max_mm, straight.max_covered), (4, 0.4, true));
        let total: f64 = by.values().map(|r| r.sum_sq_mm2).sum();
        let whole = summarize(&layers);
        assert!((total - whole.rms_mm.powi(2) * whole.points as f64).abs() < 1e-12);
    }

    #[test]
    fn edge_distance_is_the_strip_width_over_cos_and_the_mitre_at_a_corner() {
        // Bottom edge of a square, w0 = 0.2: along a direction tilted by φ from the normal
        // the strip's half width is w0/cos φ (eq. 31); at the vertex along the inner
        // bisector the mitred inner corner lies w0·√2 away.
        let (w0, phi) = (0.2_f64, 0.4_f64);
        let bead = IdealBead::new(&[[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]], w0).unwrap();
        let d = bead.edge_distance_mm([5.0, 0.0], [phi.sin(), phi.cos()]);
        assert!((d - w0 / phi.cos()).abs() < 1e-12, "{d}");
        let inner = bead.edge_distance_mm([0.0, 0.0], [0.5_f64.sqrt(), 0.5_f64.sqrt()]);
        assert!((inner - w0 * 2.0_f64.sqrt()).abs() < 1e-12, "{inner}");
        assert_eq!(bead.edge_distance_mm([5.0, 5.0], [0.0, 1.0]), 0.0);
    }

    #[test]
    fn iso_line_of_a_disc_lies_on_the_circle() {
        let (radius, cell) = (1.0, 0.02);
        let mut grid = DepositGrid::covering([-1.5, -1.5], [1.5, 1.5], cell);
        rasterise(&mut grid, 8, |p| p[0].hypot(p[1]) <= radius);
        let segments = level_contour(&grid, FOOTPRINT_LEVEL);
        assert!(segments.len() > 300);
        for [a, b] in &segments {
            for p in [a, b] {
                assert!((p[0].hypot(p[1]) - radius).abs() < 0.1 * cell, "{p:?}");
            }
        }
        // The contour error of CAD points on the circle is then within the same bound.
        let cad: Vec<[f64; 2]> = (0..100).map(|i| (i as f64 * 0.0628).sin_cos()).map(|(s, c)| [c, s]).collect();
        assert!(contour_errors(&grid, &cad).iter().all(|e| e.error_mm < 0.1 * cell));
    }
}
