//! The layer-to-layer height-change model of paper 002, Sec. III (eqs 2-7), in the
//! corrected form of DESIGN §5.2 (the paper's eq. 4 is OCR-damaged).
//!
//! A droplet at `p` on the previous profile `H`:
//! - `p` gains `h1`;
//! - each side neighbour `q` gains `h2·sat_{h1+h2}(H_p − H_q)` and `p` keeps the rest
//!   `h2·(1 − sat_{h1+h2}(H_p − H_q))` (Fig. 6: the pair always gains `h1 + h2`);
//! - each corner neighbour `r` likewise with `h3` and `sat_{h1+h3}`;
//! - `sat_a(b)` is eq. 5.
//!
//! All droplets of a layer are computed from the same `H` and their contributions add
//! (eq. 3). Each droplet therefore adds exactly `h1 + 4h2 + 4h3` (mass conservation).
//!
//! **Boundary rule** (the paper is silent): a neighbour outside the grid receives
//! nothing and the droplet's own cell keeps that whole share, as if the wall of the
//! printing region were infinitely high (`sat = 0`). This keeps every droplet's volume
//! on the grid, so mass is conserved at the boundary too. Parts are normally placed
//! with a margin of unprinted cells, so the rule only matters for tests such as the
//! Sec. IV-C recovery check on a fully printable 20 × 20 grid.
//!
//! Coefficients are given per cell (`&[DropletCoeffs]`): a "truth" printer scales each
//! droplet by `(1 − u)`, and the two-material model (eqs 6-7) picks the part material's
//! `(h1, h2, h3)` or the support's `(g1, g2, g3)` per cell. The `sat` widths use the
//! depositing droplet's own coefficients, as in eq. 7.
//!
//! Two equivalent evaluations are provided: [`deposit_layer_into`] scatters each
//! droplet's shares (the reference), [`increment_at_um`] gathers one cell's increment
//! from its 3 × 3 neighbourhood (used by the controller's local flip evaluation).

use super::errors::InkjetError;
use super::grid::{Grid, HeightMap, Pattern, CORNER_OFFSETS, SIDE_OFFSETS};

/// Height-change coefficients of one droplet (paper Fig. 5b, Table I).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DropletCoeffs {
    /// Height change at the droplet's own cell on a flat surface, µm.
    pub h1_um: f64,
    /// Height change at each side neighbour on a flat surface, µm.
    pub h2_um: f64,
    /// Height change at each corner neighbour on a flat surface, µm.
    pub h3_um: f64,
}

impl DropletCoeffs {
    /// Paper Table I (identified in Sec. V-C): h1 = 4.4, h2 = 0.6, h3 = 0.2 µm.
    pub fn paper_table1() -> Self {
        Self { h1_um: 4.4, h2_um: 0.6, h3_um: 0.2 }
    }

    /// Checks `h1 > 0`, `h2, h3 >= 0`, all finite.
    pub fn check(self) -> Result<Self, InkjetError> {
        let finite = self.h1_um.is_finite() && self.h2_um.is_finite() && self.h3_um.is_finite();
        if finite && self.h1_um > 0.0 && self.h2_um >= 0.0 && self.h3_um >= 0.0 {
            Ok(self)
        } else {
            Err(InkjetError::InvalidCoefficients { h1_um: self.h1_um, h2_um: self.h2_um, h3_um: self.h3_um })
        }
    }

    /// All three coefficients multiplied by `factor` (e.g. a droplet volume shortfall).
    pub fn scaled(self, factor: f64) -> Self {
        Self { h1_um: self.h1_um * factor, h2_um: self.h2_um * factor, h3_um: self.h3_um * factor }
    }

    /// Height one droplet adds to the grid in total: `h1 + 4h2 + 4h3` (eq. 2 summed).
    ///
    /// This is also the nominal layer height of a uniform layer on a flat surface.
    pub fn droplet_volume_um(self) -> f64 {
        self.h1_um + 4.0 * self.h2_um + 4.0 * self.h3_um
    }

    /// Share `h2` or `h3` this droplet sends over a link, and the `sat` width
    /// `h1 + h2` or `h1 + h3` that governs it.
    #[inline]
    fn link(self, link: Link) -> (f64, f64) {
        match link {
            Link::Side => (self.h2_um, self.h1_um + self.h2_um),
            Link::Corner => (self.h3_um, self.h1_um + self.h3_um),
        }
    }

    /// Amount this droplet gives a neighbour over `link` when its cell is `diff_um`
    /// higher than the neighbour: `share · sat_width(diff)`.
    #[inline]
    pub fn given_um(self, link: Link, diff_um: f64) -> f64 {
        let (share, width) = self.link(link);
        share * sat(width, diff_um)
    }
}

/// The two kinds of neighbour link of Fig. 5a.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Link {
    /// A side neighbour, governed by `h2` and `sat_{h1+h2}`.
    Side,
    /// A corner neighbour, governed by `h3` and `sat_{h1+h3}`.
    Corner,
}

impl Link {
    /// Offsets `(di, dj)` of the neighbours of this kind.
    pub fn offsets(self) -> &'static [(isize, isize); 4] {
        match self {
            Link::Side => &SIDE_OFFSETS,
            Link::Corner => &CORNER_OFFSETS,
        }
    }
}

/// Both link kinds, sides first.
pub const LINKS: [Link; 2] = [Link::Side, Link::Corner];

/// The saturation function of eq. 5: 1 for `b ≥ 0`, `1 + b/a` for `−a ≤ b < 0`, else 0.
///
/// A non-positive width `a` degenerates to a step at `b = 0`.
#[inline]
pub fn sat(width_um: f64, diff_um: f64) -> f64 {
    if diff_um >= 0.0 {
        1.0
    } else if diff_um >= -width_um {
        1.0 + diff_um / width_um
    } else {
        0.0
    }
}

/// Calls `emit(cell, amount_um)` for every share of the droplet at `p` on profile
/// `height_um`: once per in-grid neighbour, then once for `p` itself (`h1` plus all
/// kept shares, including those of neighbours outside the grid). The amounts sum to
/// `coeffs.droplet_volume_um()`.
pub fn for_each_share(
    grid: Grid,
    height_um: &[f64],
    p: usize,
    coeffs: DropletCoeffs,
    mut emit: impl FnMut(usize, f64),
) {
    let (i, j) = grid.coords(p);
    let h_p = height_um[p];
    let mut kept_um = coeffs.h1_um;
    for link in LINKS {
        let (share, _) = coeffs.link(link);
        for &(di, dj) in link.offsets() {
            match grid.offset(i, j, di, dj) {
                Some((ni, nj)) => {
                    let q = grid.index(ni, nj);
                    let given = coeffs.given_um(link, h_p - height_um[q]);
                    emit(q, given);
                    kept_um += share - given;
                }
                None => kept_um += share,
            }
        }
    }
    emit(p, kept_um);
}

/// Low-level eq. 3: `after = before + C1 + C2 + C3` for the droplets in `droplet`,
/// all computed from `before`. Allocates nothing. Panics if a slice length differs from
/// the grid (checked by the wrappers).
pub fn deposit_layer_into(
    grid: Grid,
    before_um: &[f64],
    droplet: &[bool],
    coeffs: &[DropletCoeffs],
    after_um: &mut [f64],
) {
    assert!(
        before_um.len() == grid.len()
            && droplet.len() == grid.len()
            && coeffs.len() == grid.len()
            && after_um.len() == grid.len(),
        "deposit_layer_into: slice lengths must match the grid"
    );
    after_um.copy_from_slice(before_um);
    for p in 0..grid.len() {
        if droplet[p] {
            for_each_share(grid, before_um, p, coeffs[p], |q, amount| after_um[q] += amount);
        }
    }
}

/// Eq. 3 on checked inputs: the profile after printing `pattern` on `before` with the
/// per-cell droplet coefficients `coeffs`.
pub fn deposit_layer(
    before: &HeightMap,
    pattern: &Pattern,
    coeffs: &[DropletCoeffs],
) -> Result<HeightMap, InkjetError> {
    let grid = before.grid;
    grid.check_pattern(pattern)?;
    grid.check_len("coefficients", coeffs.len())?;
    let mut after_um = vec![0.0; grid.len()];
    deposit_layer_into(grid, &before.height_um, &pattern.droplet, coeffs, &mut after_um);
    Ok(HeightMap { grid, height_um: after_um })
}

/// Gather form of eq. 3 for one cell `(i, j)`: the height it gains when the droplets
/// `droplet` (row-major) are printed on the profile `height_at(i, j, index)`. Equal to
/// what [`deposit_layer_into`] adds to that cell; reads only the cell's 3 × 3 block.
#[inline]
pub fn increment_at_um(
    grid: Grid,
    i: usize,
    j: usize,
    height_at: impl Fn(usize, usize, usize) -> f64,
    droplet: &[bool],
    coeffs: &[DropletCoeffs],
) -> f64 {
    let c = grid.index(i, j);
    let h_c = height_at(i, j, c);
    let own = droplet[c];
    let mut gain_um = if own { coeffs[c].h1_um } else { 0.0 };
    for link in LINKS {
        for &(di, dj) in link.offsets() {
            let Some((ni, nj)) = grid.offset(i, j, di, dj) else {
                if own {
                    gain_um += coeffs[c].link(link).0;
                }
                continue;
            };
            let q = grid.index(ni, nj);
            let h_q = height_at(ni, nj, q);
            if own {
                let share = coeffs[c].link(link).0;
                gain_um += share - coeffs[c].given_um(link, h_c - h_q);
            }
            if droplet[q] {
                gain_um += coeffs[q].given_um(link, h_q - h_c);
            }
        }
    }
    gain_um
}

/// The same coefficients at every cell (single-material printing, nominal model).
pub fn uniform_coeffs(grid: Grid, coeffs: DropletCoeffs) -> Vec<DropletCoeffs> {
    vec![coeffs; grid.len()]
}

/// The material a cell is printed with in two-material printing (Sec. III-D, IV-B).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Material {
    /// Object material A (the part), coefficients `(h1, h2, h3)`.
    Part,
    /// Sacrificial support material B, coefficients `(g1, g2, g3)`.
    Support,
}

/// The sets `I_A,k` / `I_B,k` of Sec. IV-B (Fig. 10): cell `(i, j)` is part material iff
/// `inside(i·L_x, j·L_y, H_ij)` holds for the part geometry `M`, support otherwise.
pub fn material_map(heights: &HeightMap, inside: impl Fn(f64, f64, f64) -> bool) -> Vec<Material> {
    let grid = heights.grid;
    (0..grid.len())
        .map(|c| {
            let (i, j) = grid.coords(c);
            let (x_um, y_um) = grid.position_um(i, j);
            if inside(x_um, y_um, heights.height_um[c]) {
                Material::Part
            } else {
                Material::Support
            }
        })
        .collect()
}

/// Per-cell coefficients of the two-material model (eqs 6-7): `part` where the
/// material map says part, `support` elsewhere.
pub fn two_material_coeffs(materials: &[Material], part: DropletCoeffs, support: DropletCoeffs) -> Vec<DropletCoeffs> {
    materials
        .iter()
        .map(|m| match m {
            Material::Part => part,
            Material::Support => support,
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    const P: DropletCoeffs = DropletCoeffs { h1_um: 4.4, h2_um: 0.6, h3_um: 0.2 };

    fn random_case(rng: &mut ChaCha8Rng, m_x: usize, m_y: usize) -> (Grid, Vec<f64>, Vec<bool>, Vec<DropletCoeffs>) {
        let grid = Grid::new(m_x, m_y, 1.0).unwrap();
        // Heights span several droplet heights so every branch of sat is exercised.
        let heights = (0..grid.len()).map(|_| rng.random_range(0.0..12.0)).collect();
        let droplet = (0..grid.len()).map(|_| rng.random_bool(0.6)).collect();
        let coeffs = (0..grid.len()).map(|_| P.scaled(1.0 - rng.random_range(0.0..0.4))).collect();
        (grid, heights, droplet, coeffs)
    }

    fn deposit(grid: Grid, before: &[f64], droplet: &[bool], coeffs: &[DropletCoeffs]) -> Vec<f64> {
        let mut after = vec![0.0; grid.len()];
        deposit_layer_into(grid, before, droplet, coeffs, &mut after);
        after
    }

    #[test]
    fn sat_follows_eq5() {
        assert_eq!(sat(5.0, 0.0), 1.0);
        assert_eq!(sat(5.0, 3.0), 1.0);
        assert!((sat(5.0, -1.0) - 0.8).abs() < 1e-15);
        assert_eq!(sat(5.0, -5.0), 0.0);
        assert_eq!(sat(5.0, -7.0), 0.0);
    }

    #[test]
    fn a_neighbour_pair_always_gains_h1_plus_h2() {
        // Fig. 6: whatever H1 - H2, the centre and its side neighbour together gain h1 + h2
        // (plus the centre's other shares, which we remove by setting h3 = 0 and making the
        // other neighbours lie outside a 2 x 1 grid, where the centre keeps them).
        let grid = Grid::new(2, 1, 1.0).unwrap();
        let coeffs = [DropletCoeffs { h3_um: 0.0, ..P }; 2];
        for diff in [-10.0, -5.0, -2.5, -0.1, 0.0, 3.0] {
            let before = [0.0, -diff];
            let after = deposit(grid, &before, &[true, false], &coeffs);
            let to_neighbour = after[1] - before[1];
            assert!((to_neighbour - 0.6 * sat(5.0, diff)).abs() < 1e-12);
            let total = after[0] + after[1] - before[0] - before[1];
            assert!((total - (4.4 + 4.0 * 0.6)).abs() < 1e-12);
        }
    }

    #[test]
    fn every_droplet_adds_its_volume_boundary_included() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for _ in 0..20 {
            let (grid, before, droplet, coeffs) = random_case(&mut rng, 7, 5);
            let after = deposit(grid, &before, &droplet, &coeffs);
            let added: f64 = after.iter().sum::<f64>() - before.iter().sum::<f64>();
            let expected: f64 = (0..grid.len()).filter(|&c| droplet[c]).map(|c| coeffs[c].droplet_volume_um()).sum();
            assert!((added - expected).abs() < 1e-9, "{added} vs {expected}");
        }
        // A lone droplet in a corner cell keeps its five off-grid shares.
        let grid = Grid::new(3, 3, 1.0).unwrap();
        let mut droplet = vec![false; 9];
        droplet[0] = true;
        let after = deposit(grid, &[0.0; 9], &droplet, &uniform_coeffs(grid, P));
        assert!((after[0] - (4.4 + 2.0 * 0.6 + 3.0 * 0.2)).abs() < 1e-12);
        assert!((after.iter().sum::<f64>() - P.droplet_volume_um()).abs() < 1e-12);
    }

    #[test]
    fn flat_surface_reduces_to_eq2() {
        // On a flat surface every sat is 1, so away from the grid boundary eq. 3 is the
        // additive model of eq. 2 for any pattern.
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let grid = Grid::new(9, 8, 1.0).unwrap();
        let interior = |i: usize, j: usize| i > 0 && j > 0 && i + 1 < grid.m_x && j + 1 < grid.m_y;
        let droplet: Vec<bool> = (0..grid.len())
            .map(|c| {
                let (i, j) = grid.coords(c);
                interior(i, j) && rng.random_bool(0.5)
            })
            .collect();
        let after = deposit(grid, &[2.0; 72], &droplet, &uniform_coeffs(grid, P));
        for c in 0..grid.len() {
            let (i, j) = grid.coords(c);
            let u = |di, dj| match grid.offset(i, j, di, dj) {
                Some((a, b)) if droplet[grid.index(a, b)] => 1.0,
                _ => 0.0,
            };
            let sides: f64 = SIDE_OFFSETS.iter().map(|&(a, b)| u(a, b)).sum();
            let corners: f64 = CORNER_OFFSETS.iter().map(|&(a, b)| u(a, b)).sum();
            let eq2 = 4.4 * u(0, 0) + 0.6 * sides + 0.2 * corners;
            assert!((after[c] - 2.0 - eq2).abs() < 1e-12);
        }
        // A uniform layer raises every cell whose 3 x 3 block is printed by h1 + 4h2 + 4h3.
        let full = vec![true; grid.len()];
        let after = deposit(grid, &[0.0; 72], &full, &uniform_coeffs(grid, P));
        assert!((after[grid.index(4, 4)] - 7.6).abs() < 1e-12);
    }

    #[test]
    fn single_line_printed_twice_shows_the_edge_shrink_closed_form() {
        // Sec. III-C: a line of droplets (one droplet wide) on a flat surface, printed
        // twice. The row's cells receive only from their two in-line neighbours (the rows
        // above and below are never printed and stay lower, so every share sent there
        // flows fully and none comes back), so the row follows the paper's 1-D model
        // exactly, whatever h3. Expected after two layers:
        //   edge      2h1 + 3h2 - h1 h2/(h1+h2)
        //   near edge 2h1 + 3h2 + h1 h2/(h1+h2)
        //   others    2h1 + 4h2
        let grid = Grid::new(14, 5, 1.0).unwrap();
        let (first, last, row) = (2, 11, 2);
        let line: Vec<bool> = (0..grid.len())
            .map(|c| {
                let (i, j) = grid.coords(c);
                j == row && (first..=last).contains(&i)
            })
            .collect();
        let coeffs = uniform_coeffs(grid, P);
        let layer1 = deposit(grid, &vec![0.0; grid.len()], &line, &coeffs);
        let layer2 = deposit(grid, &layer1, &line, &coeffs);
        let (h1, h2) = (P.h1_um, P.h2_um);
        let flow_back = h1 * h2 / (h1 + h2);
        let at = |i| layer2[grid.index(i, row)];
        for edge in [first, last] {
            assert!((at(edge) - (2.0 * h1 + 3.0 * h2 - flow_back)).abs() < 1e-12);
        }
        for near in [first + 1, last - 1] {
            assert!((at(near) - (2.0 * h1 + 3.0 * h2 + flow_back)).abs() < 1e-12);
        }
        for i in first + 2..=last - 2 {
            assert!((at(i) - (2.0 * h1 + 4.0 * h2)).abs() < 1e-12);
        }
    }

    #[test]
    fn gather_equals_scatter() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        for (m_x, m_y) in [(1, 1), (1, 6), (6, 1), (8, 7)] {
            let (grid, before, droplet, coeffs) = random_case(&mut rng, m_x, m_y);
            let after = deposit(grid, &before, &droplet, &coeffs);
            for c in 0..grid.len() {
                let (i, j) = grid.coords(c);
                let inc = increment_at_um(grid, i, j, |_, _, q| before[q], &droplet, &coeffs);
                assert!((before[c] + inc - after[c]).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn two_material_cells_follow_the_geometry() {
        // Part material inside x < 2.5 µm while below 5 µm height; support elsewhere.
        let grid = Grid::new(4, 2, 1.0).unwrap();
        let mut heights = HeightMap::flat(grid, 0.0);
        heights.height_um[0] = 6.0;
        let materials = material_map(&heights, |x, _, h| x < 2.5 && h < 5.0);
        assert_eq!(materials[0], Material::Support);
        assert_eq!(materials[1], Material::Part);
        assert_eq!(materials[3], Material::Support);
        let support = DropletCoeffs { h1_um: 3.0, h2_um: 1.0, h3_um: 0.5 };
        let coeffs = two_material_coeffs(&materials, P, support);
        let pattern = Pattern::from_vec(grid, vec![true; 8]).unwrap();
        let after = deposit_layer(&heights, &pattern, &coeffs).unwrap();
        let added = after.height_um.iter().sum::<f64>() - heights.height_um.iter().sum::<f64>();
        let expected: f64 = coeffs.iter().map(|c| c.droplet_volume_um()).sum();
        assert!((added - expected).abs() < 1e-12);
    }

    #[test]
    fn checked_inputs() {
        assert!(P.check().is_ok());
        assert!(DropletCoeffs { h1_um: 0.0, ..P }.check().is_err());
        assert!(DropletCoeffs { h2_um: -0.1, ..P }.check().is_err());
        let grid = Grid::new(2, 2, 1.0).unwrap();
        let other = Grid::new(3, 2, 1.0).unwrap();
        let result = deposit_layer(&HeightMap::flat(grid, 0.0), &Pattern::empty(other), &uniform_coeffs(grid, P));
        assert!(result.is_err());
    }
}
