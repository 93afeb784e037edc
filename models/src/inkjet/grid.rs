//! The discretised printing region of paper 002 (Sec. III-A, Fig. 4, eq. 1): an
//! `m_x × m_y` grid of droplet positions with spacing `L_x = L_y = γ·d`, the height map
//! `H_k` on it and a droplet pattern `U_k ∈ {0,1}^{m_x × m_y}`.
//!
//! Storage is row-major: cell `(i, j)` (column `i` along x, row `j` along y) has index
//! `j·m_x + i`. Cell `(i, j)` sits at `(i·L_x, j·L_y)` in µm, as in Sec. IV-B.

use super::errors::InkjetError;

/// Offsets of the four side neighbours of a cell (paper Fig. 5a, magenta).
pub const SIDE_OFFSETS: [(isize, isize); 4] = [(1, 0), (-1, 0), (0, 1), (0, -1)];

/// Offsets of the four corner neighbours of a cell (paper Fig. 5a, green).
pub const CORNER_OFFSETS: [(isize, isize); 4] = [(1, 1), (1, -1), (-1, 1), (-1, -1)];

/// The droplet grid: its size and the droplet spacing (eq. 1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Grid {
    /// Number of cells along x.
    pub m_x: usize,
    /// Number of cells along y.
    pub m_y: usize,
    /// Centre-to-centre droplet spacing `L_x = L_y` in µm.
    pub spacing_um: f64,
}

impl Grid {
    /// A checked grid: at least one cell each way and a positive, finite spacing.
    pub fn new(m_x: usize, m_y: usize, spacing_um: f64) -> Result<Self, InkjetError> {
        if m_x == 0 || m_y == 0 || !(spacing_um.is_finite() && spacing_um > 0.0) {
            return Err(InkjetError::InvalidGrid { m_x, m_y, spacing_um });
        }
        Ok(Self { m_x, m_y, spacing_um })
    }

    /// Spacing of paper Table I: `γ·d = 0.6268 · 420 µm` (eq. 1).
    pub fn paper_spacing_um() -> f64 {
        0.6268 * 420.0
    }

    /// Number of cells.
    pub fn len(&self) -> usize {
        self.m_x * self.m_y
    }

    /// Whether the grid has no cell (never true for a checked grid).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Row-major index of cell `(i, j)`.
    #[inline]
    pub fn index(&self, i: usize, j: usize) -> usize {
        j * self.m_x + i
    }

    /// Cell `(i, j)` of a row-major index.
    #[inline]
    pub fn coords(&self, index: usize) -> (usize, usize) {
        (index % self.m_x, index / self.m_x)
    }

    /// The cell at offset `(di, dj)` from `(i, j)`, or `None` outside the grid.
    #[inline]
    pub fn offset(&self, i: usize, j: usize, di: isize, dj: isize) -> Option<(usize, usize)> {
        let ni = i.checked_add_signed(di)?;
        let nj = j.checked_add_signed(dj)?;
        (ni < self.m_x && nj < self.m_y).then_some((ni, nj))
    }

    /// Position `(x, y)` in µm of cell `(i, j)`: `(i·L_x, j·L_y)` (Sec. IV-B).
    pub fn position_um(&self, i: usize, j: usize) -> (f64, f64) {
        (i as f64 * self.spacing_um, j as f64 * self.spacing_um)
    }

    /// Checks that a per-cell slice has one value per cell.
    pub fn check_len(&self, what: &'static str, found: usize) -> Result<(), InkjetError> {
        if found == self.len() {
            Ok(())
        } else {
            Err(InkjetError::GridMismatch { what, found, expected: self.len() })
        }
    }

    /// Checks that a pattern has this grid's shape.
    pub fn check_pattern(&self, pattern: &Pattern) -> Result<(), InkjetError> {
        if pattern.fits(*self) {
            Ok(())
        } else {
            Err(InkjetError::PatternShape { found_x: pattern.m_x, found_y: pattern.m_y, m_x: self.m_x, m_y: self.m_y })
        }
    }
}

/// A height profile `H_k` in µm on a grid (row-major).
#[derive(Debug, Clone, PartialEq)]
pub struct HeightMap {
    /// The grid the heights live on.
    pub grid: Grid,
    /// Height of each cell in µm, row-major.
    pub height_um: Vec<f64>,
}

impl HeightMap {
    /// A flat profile of the given height.
    pub fn flat(grid: Grid, height_um: f64) -> Self {
        Self { grid, height_um: vec![height_um; grid.len()] }
    }

    /// A profile from row-major heights; fails when the length does not match the grid.
    pub fn from_vec(grid: Grid, height_um: Vec<f64>) -> Result<Self, InkjetError> {
        grid.check_len("height map", height_um.len())?;
        Ok(Self { grid, height_um })
    }

    /// Height of cell `(i, j)` in µm.
    pub fn at(&self, i: usize, j: usize) -> f64 {
        self.height_um[self.grid.index(i, j)]
    }
}

/// A droplet pattern `U_k`: `true` where a droplet is deposited (row-major).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Pattern {
    /// Grid size along x (cells).
    pub m_x: usize,
    /// Grid size along y (cells).
    pub m_y: usize,
    /// Whether a droplet is deposited at each cell, row-major.
    pub droplet: Vec<bool>,
}

impl Pattern {
    /// A pattern with no droplet.
    pub fn empty(grid: Grid) -> Self {
        Self { m_x: grid.m_x, m_y: grid.m_y, droplet: vec![false; grid.len()] }
    }

    /// A pattern from a row-major mask; fails when the length does not match the grid.
    pub fn from_vec(grid: Grid, droplet: Vec<bool>) -> Result<Self, InkjetError> {
        grid.check_len("pattern", droplet.len())?;
        Ok(Self { m_x: grid.m_x, m_y: grid.m_y, droplet })
    }

    /// The cells `(i, j)` for which `inside(x_um, y_um)` holds at the cell position.
    pub fn from_fn(grid: Grid, inside: impl Fn(f64, f64) -> bool) -> Self {
        let droplet = (0..grid.len())
            .map(|index| {
                let (i, j) = grid.coords(index);
                let (x_um, y_um) = grid.position_um(i, j);
                inside(x_um, y_um)
            })
            .collect();
        Self { m_x: grid.m_x, m_y: grid.m_y, droplet }
    }

    /// Number of droplets in the pattern.
    pub fn count(&self) -> usize {
        self.droplet.iter().filter(|&&d| d).count()
    }

    /// Row-major indices of the cells with a droplet.
    pub fn cells(&self) -> Vec<usize> {
        (0..self.droplet.len()).filter(|&c| self.droplet[c]).collect()
    }

    /// Whether the pattern has the size of `grid`.
    pub fn fits(&self, grid: Grid) -> bool {
        self.m_x == grid.m_x && self.m_y == grid.m_y && self.droplet.len() == grid.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn row_major_index_round_trips() {
        let grid = Grid::new(5, 3, 1.0).unwrap();
        assert_eq!(grid.index(4, 2), 14);
        assert_eq!(grid.coords(14), (4, 2));
        assert_eq!(grid.offset(4, 2, 1, 0), None);
        assert_eq!(grid.offset(0, 0, -1, 0), None);
        assert_eq!(grid.offset(1, 1, -1, 1), Some((0, 2)));
    }

    #[test]
    fn paper_spacing_is_gamma_times_diameter() {
        // Table I: d = 420 µm, γ = 0.6268, so L = 263.256 µm and a 2106 µm square is 8 cells.
        let spacing = Grid::paper_spacing_um();
        assert!((spacing - 263.256).abs() < 1e-9);
        assert!((2106.0 / spacing - 8.0).abs() < 1e-3);
    }

    #[test]
    fn invalid_grid_and_mismatched_lengths_are_errors() {
        assert!(Grid::new(0, 3, 1.0).is_err());
        assert!(Grid::new(3, 3, 0.0).is_err());
        let grid = Grid::new(2, 2, 1.0).unwrap();
        assert_eq!(
            HeightMap::from_vec(grid, vec![0.0; 3]),
            Err(InkjetError::GridMismatch { what: "height map", found: 3, expected: 4 })
        );
        assert!(Pattern::from_vec(grid, vec![true; 5]).is_err());
    }

    #[test]
    fn pattern_from_fn_uses_cell_positions() {
        let grid = Grid::new(4, 4, 10.0).unwrap();
        let pattern = Pattern::from_fn(grid, |x, y| x <= 10.0 && y <= 10.0);
        assert_eq!(pattern.count(), 4);
        assert_eq!(pattern.cells(), vec![0, 1, 4, 5]);
    }
}
