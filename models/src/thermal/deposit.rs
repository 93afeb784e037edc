//! A deposited layer on the print plane: the fraction of the layer height filled in
//! each cell of a regular grid. The virtual printer (`datasets`) writes it, the
//! over-deposition index (paper 003 eq. 40) and the contour error (eq. 41) read it.

/// Fill fractions on a regular grid of square cells, row-major (y rows, x columns).
#[derive(Debug, Clone, PartialEq)]
pub struct DepositGrid {
    /// Plane coordinates of the lower-left corner of cell (0, 0) (mm).
    pub origin_mm: [f64; 2],
    /// Cell edge length (mm).
    pub cell_mm: f64,
    /// Number of columns (x).
    pub nx: usize,
    /// Number of rows (y).
    pub ny: usize,
    /// Filled fraction of the layer height per cell, 0 (empty) to 1 (full).
    pub fill: Vec<f32>,
}

impl DepositGrid {
    /// An empty grid covering `[min_mm, max_mm]` with cells of `cell_mm`.
    pub fn covering(min_mm: [f64; 2], max_mm: [f64; 2], cell_mm: f64) -> Self {
        let nx = ((max_mm[0] - min_mm[0]) / cell_mm).ceil().max(1.0) as usize;
        let ny = ((max_mm[1] - min_mm[1]) / cell_mm).ceil().max(1.0) as usize;
        Self { origin_mm: min_mm, cell_mm, nx, ny, fill: vec![0.0; nx * ny] }
    }

    /// Index of cell (ix, iy) in `fill`.
    pub fn index(&self, ix: usize, iy: usize) -> usize {
        iy * self.nx + ix
    }

    /// Centre of cell (ix, iy) (mm).
    pub fn cell_center_mm(&self, ix: usize, iy: usize) -> [f64; 2] {
        [self.origin_mm[0] + (ix as f64 + 0.5) * self.cell_mm, self.origin_mm[1] + (iy as f64 + 0.5) * self.cell_mm]
    }

    /// The cell containing `point_mm`, if inside the grid.
    pub fn cell_of(&self, point_mm: [f64; 2]) -> Option<(usize, usize)> {
        let fx = (point_mm[0] - self.origin_mm[0]) / self.cell_mm;
        let fy = (point_mm[1] - self.origin_mm[1]) / self.cell_mm;
        let inside = fx >= 0.0 && fy >= 0.0 && fx < self.nx as f64 && fy < self.ny as f64;
        inside.then_some((fx as usize, fy as usize))
    }

    /// Deposited area (mm²): the fill fractions times the cell area.
    pub fn area_mm2(&self) -> f64 {
        self.fill.iter().map(|f| f64::from(*f)).sum::<f64>() * self.cell_mm * self.cell_mm
    }

    /// Fill fraction at `point_mm`, bilinear between cell centres (0 beyond the grid):
    /// the field whose 0.5 iso-line is the printed edge (eq. 41, [`super::metrics`]).
    pub fn fill_at(&self, point_mm: [f64; 2]) -> f64 {
        let fx = (point_mm[0] - self.origin_mm[0]) / self.cell_mm - 0.5;
        let fy = (point_mm[1] - self.origin_mm[1]) / self.cell_mm - 0.5;
        let (x0, y0) = (fx.floor(), fy.floor());
        let (ax, ay) = (fx - x0, fy - y0);
        let get = |x: f64, y: f64| -> f64 {
            if x < 0.0 || y < 0.0 || x >= self.nx as f64 || y >= self.ny as f64 {
                0.0
            } else {
                f64::from(self.fill[y as usize * self.nx + x as usize])
            }
        };
        let bottom = get(x0, y0) * (1.0 - ax) + get(x0 + 1.0, y0) * ax;
        let top = get(x0, y0 + 1.0) * (1.0 - ax) + get(x0 + 1.0, y0 + 1.0) * ax;
        bottom * (1.0 - ay) + top * ay
    }

    /// True where a cell is at least half filled: the printed footprint.
    pub fn footprint(&self) -> Vec<bool> {
        self.fill.iter().map(|f| *f >= 0.5).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cells_and_centres_agree() {
        let grid = DepositGrid::covering([-1.0, 2.0], [1.0, 3.0], 0.1);
        assert_eq!((grid.nx, grid.ny), (20, 10));
        let c = grid.cell_center_mm(3, 4);
        assert_eq!(grid.cell_of(c), Some((3, 4)));
        assert_eq!(grid.cell_of([1.5, 2.5]), None);
    }

    #[test]
    fn fill_is_bilinear_between_cell_centres_and_zero_beyond() {
        let mut grid = DepositGrid::covering([0.0, 0.0], [1.0, 1.0], 0.5);
        grid.fill = vec![1.0, 0.0, 0.0, 0.0];
        assert!((grid.fill_at(grid.cell_center_mm(0, 0)) - 1.0).abs() < 1e-12);
        assert!((grid.fill_at([0.5, 0.25]) - 0.5).abs() < 1e-12, "halfway to the next centre");
        assert!((grid.fill_at([0.0, 0.25]) - 0.5).abs() < 1e-12, "halfway to the empty outside");
        assert_eq!(grid.fill_at([5.0, 5.0]), 0.0);
    }

    #[test]
    fn area_counts_fractions() {
        let mut grid = DepositGrid::covering([0.0, 0.0], [1.0, 1.0], 0.5);
        grid.fill = vec![1.0, 0.5, 0.0, 0.25];
        assert!((grid.area_mm2() - 1.75 * 0.25).abs() < 1e-12);
    }
}
