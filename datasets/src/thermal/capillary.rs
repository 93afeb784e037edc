//! Collapse of thin melt features in a freshly laid layer of the virtual thermal printer
//! (DESIGN §5.3 "Deposition").
//!
//! Eqs 10-11 of paper 003 give every trajectory sample a deposition segment of length
//! E/(|v|h); at a slow apex the segments grow long and fan out, and the material between
//! consecutive segments becomes a ray a few tens of micrometres wide reaching up to a
//! millimetre out of the corner. A melt of that shape cannot stand: it lies outside the
//! nozzle's face, which shapes the bead under it, and surface tension pulls such a
//! filament into the bead it hangs from. So after each layer the printer takes every
//! part of the footprint (fill ≥ 1/2) that lies farther than the nozzle radius from the
//! path and that a disc of radius [`THIN_FEATURE_RADIUS_MM`] cannot reach inside the
//! footprint (the footprint minus its morphological opening), and moves each
//! such cell's material back along the feature to the cell it hangs from (a
//! breadth-first walk through the thin cells from the cells that stay: the opened
//! footprint and the footprint under the nozzle's face), spread evenly over the cells
//! that stay within 2r of that root, where it piles up (the nozzle face's
//! squeeze then pours what stands above the nozzle plane sideways, see `deposition`). Mass is conserved exactly;
//! features at least 2r wide, beads and corner bulges, keep their shape (a square end
//! loses the cells of its corners that no disc of radius r reaches inside it).
//!
//! Simplifications, stated: the collapse is instantaneous (before the next layer and
//! before the camera looks at it: the thermal camera, about 0.14 mm per pixel, could
//! not resolve such features anyway); a thin island not connected to the bead stays;
//! fringe cells below half full stay where they are.

/// Half the width of the narrowest melt feature that stands (mm): a quarter of the
/// 0.4 mm nozzle.
pub const THIN_FEATURE_RADIUS_MM: f64 = 0.1;
/// Farthest a thin feature's material is moved (mm): longer than any apex ray.
pub const MAX_COLLAPSE_MM: f64 = 2.0;

/// Fill and first-deposit time of one layer, row-major `nx` × `ny`.
pub struct LayerFill<'a> {
    /// Fill of each cell, in layer heights.
    pub fill: &'a mut [f64],
    /// Time each cell first received material (s); infinite where empty.
    pub deposit_time_s: &'a mut [f32],
    /// Columns.
    pub nx: usize,
    /// Rows.
    pub ny: usize,
}

impl LayerFill<'_> {
    /// Moves the material of the footprint's thin features (see the module doc) back
    /// along each feature to its root, spread over the cells that stay within 2r of that
    /// root; returns the number of cells moved.
    /// Cells where `held` is true (under the nozzle's face somewhere along the path) stay:
    /// the face shapes what lies under it, and a thin bead along the path (the start of
    /// a layer, before the flow has built up) is a real bead, not a filament. They are
    /// roots too: a ray that leaves the face's track where the bead under it is itself
    /// thin (the tip of a sharp apex) collapses into that bead.
    pub fn collapse_thin_features(&mut self, held: &[bool], radius_cells: usize, max_reach_cells: usize) -> usize {
        let footprint: Vec<bool> = self.fill.iter().map(|f| *f >= 0.5).collect();
        let chords = disc_chords(radius_cells as i64);
        // A disc centred at (x, y) lies in a set iff, on every row y + dy it spans, the
        // set's gap nearest to x in that row is farther than the disc's half chord there.
        let gaps = self.row_distance(true, |i| !footprint[i]);
        let eroded: Vec<bool> =
            (0..self.fill.len()).map(|i| footprint[i] && self.disc_clear(&gaps, i, &chords)).collect();
        let seeds = self.row_distance(false, |i| eroded[i]);
        let opened: Vec<bool> =
            (0..self.fill.len()).map(|i| footprint[i] && self.disc_touches(&seeds, i, &chords)).collect();
        // What stays: the opened footprint, and the footprint under the nozzle's face.
        let anchored: Vec<bool> = (0..self.fill.len()).map(|i| opened[i] || (footprint[i] && held[i])).collect();
        let thin: Vec<bool> = (0..self.fill.len()).map(|i| footprint[i] && !anchored[i]).collect();
        let roots = self.roots_along_features(&thin, &anchored, max_reach_cells);
        let landing = disc_offsets(2.0 * radius_cells as f64);
        let mut moved = 0;
        for (i, root) in roots.into_iter().enumerate() {
            let Some(root) = root else { continue };
            let cells: Vec<usize> =
                landing.iter().filter_map(|&o| self.offset(root, o)).filter(|&j| anchored[j]).collect();
            let share = self.fill[i] / cells.len() as f64;
            let t_s = self.deposit_time_s[i];
            for j in cells {
                self.fill[j] += share;
                self.deposit_time_s[j] = self.deposit_time_s[j].min(t_s);
            }
            self.fill[i] = 0.0;
            self.deposit_time_s[i] = f32::INFINITY;
            moved += 1;
        }
        moved
    }

    /// For every cell, the distance in cells along its row to the nearest cell where
    /// `member` holds; with `ends_are_members` the cells just outside the grid count too.
    fn row_distance(&self, ends_are_members: bool, member: impl Fn(usize) -> bool) -> Vec<u32> {
        let beyond = if ends_are_members { 0 } else { u32::MAX / 2 };
        let mut out = vec![0u32; self.fill.len()];
        for y in 0..self.ny {
            let row = y * self.nx;
            let mut last = beyond;
            for x in 0..self.nx {
                last = if member(row + x) { 0 } else { last + 1 };
                out[row + x] = last;
            }
            let mut next = beyond;
            for x in (0..self.nx).rev() {
                next = if member(row + x) { 0 } else { next + 1 };
                out[row + x] = out[row + x].min(next);
            }
        }
        out
    }

    /// True if a disc of half chords `chords` (row offset dy → half width) centred at
    /// cell `i` meets no gap: every row it spans is inside the grid and clear beyond the
    /// half chord.
    fn disc_clear(&self, gaps: &[u32], i: usize, chords: &[(i64, u32)]) -> bool {
        let (x, y) = (i % self.nx, (i / self.nx) as i64);
        chords.iter().all(|&(dy, half)| {
            let row = y + dy;
            row >= 0 && (row as usize) < self.ny && gaps[row as usize * self.nx + x] > half
        })
    }

    /// True if a disc of half chords `chords` centred at cell `i` reaches a seed.
    fn disc_touches(&self, seeds: &[u32], i: usize, chords: &[(i64, u32)]) -> bool {
        let (x, y) = (i % self.nx, (i / self.nx) as i64);
        chords.iter().any(|&(dy, half)| {
            let row = y + dy;
            row >= 0 && (row as usize) < self.ny && seeds[row as usize * self.nx + x] <= half
        })
    }

    fn offset(&self, i: usize, (dx, dy): (i64, i64)) -> Option<usize> {
        let (x, y) = ((i % self.nx) as i64 + dx, (i / self.nx) as i64 + dy);
        (x >= 0 && y >= 0 && (x as usize) < self.nx && (y as usize) < self.ny)
            .then(|| y as usize * self.nx + x as usize)
    }

    /// For every `thin` cell, the `anchored` cell its feature hangs from: a breadth-first
    /// walk from the anchored cells through the thin cells (8-connected), so a ray's
    /// material goes back along the ray to its root; at most `reach` steps. Cells the
    /// walk does not reach (islands) get None and stay.
    fn roots_along_features(&self, thin: &[bool], anchored: &[bool], reach: usize) -> Vec<Option<usize>> {
        let mut root: Vec<Option<usize>> = vec![None; self.fill.len()];
        let mut steps = vec![0usize; self.fill.len()];
        let mut queue: std::collections::VecDeque<usize> = (0..self.fill.len()).filter(|&i| anchored[i]).collect();
        queue.iter().for_each(|&i| root[i] = Some(i));
        const NEIGHBOURS: [(i64, i64); 8] = [(-1, 0), (1, 0), (0, -1), (0, 1), (-1, -1), (1, -1), (-1, 1), (1, 1)];
        while let Some(i) = queue.pop_front() {
            if steps[i] >= reach {
                continue;
            }
            for o in NEIGHBOURS {
                if let Some(j) = self.offset(i, o).filter(|&j| thin[j] && root[j].is_none()) {
                    root[j] = root[i];
                    steps[j] = steps[i] + 1;
                    queue.push_back(j);
                }
            }
        }
        (0..self.fill.len()).map(|i| if thin[i] { root[i] } else { None }).collect()
    }
}

/// The half chords of a disc of `radius` cells: for each row offset dy, the largest dx
/// with dx² + dy² ≤ radius².
fn disc_chords(radius: i64) -> Vec<(i64, u32)> {
    (-radius..=radius)
        .map(|dy| (dy, (0..=radius).rev().find(|dx| dx * dx + dy * dy <= radius * radius).unwrap_or(0) as u32))
        .collect()
}

/// Cell offsets within a disc of `radius_cells` (dx² + dy² ≤ radius²).
pub(crate) fn disc_offsets(radius_cells: f64) -> Vec<(i64, i64)> {
    let reach = radius_cells.ceil() as i64;
    (-reach..=reach)
        .flat_map(|dy| (-reach..=reach).map(move |dx| (dx, dy)))
        .filter(|(dx, dy)| ((dx * dx + dy * dy) as f64) <= radius_cells * radius_cells)
        .collect()
}

/// The cells within `radius_cells` of any of `points` (cell coordinates, fractional):
/// where the nozzle's face passed.
pub fn cells_near(points: impl Iterator<Item = [f64; 2]>, radius_cells: f64, nx: usize, ny: usize) -> Vec<bool> {
    let mut near = vec![false; nx * ny];
    let reach = radius_cells.ceil() as i64;
    for [fx, fy] in points {
        let (cx, cy) = (fx.floor() as i64, fy.floor() as i64);
        for y in (cy - reach).max(0)..=(cy + reach).min(ny as i64 - 1) {
            for x in (cx - reach).max(0)..=(cx + reach).min(nx as i64 - 1) {
                let (dx, dy) = (x as f64 + 0.5 - fx, y as f64 + 0.5 - fy);
                if dx * dx + dy * dy <= radius_cells * radius_cells {
                    near[y as usize * nx + x as usize] = true;
                }
            }
        }
    }
    near
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(nx: usize, ny: usize, filled: impl Fn(usize, usize) -> f64) -> (Vec<f64>, Vec<f32>) {
        let fill: Vec<f64> = (0..nx * ny).map(|i| filled(i % nx, i / nx)).collect();
        let time = fill.iter().map(|f| if *f > 0.0 { 1.0 } else { f32::INFINITY }).collect();
        (fill, time)
    }

    #[test]
    fn a_thin_ray_collapses_into_its_bead_and_mass_is_kept() {
        // A 20-cell wide bead (rows 5-24) with a 2-cell wide, 20-cell long ray up from
        // its middle.
        let (nx, ny) = (60, 60);
        let shape = |x: usize, y: usize| {
            let bead = (5..55).contains(&x) && (5..25).contains(&y);
            let ray = (29..31).contains(&x) && (25..45).contains(&y);
            if bead || ray {
                1.0
            } else {
                0.0
            }
        };
        let (mut fill, mut time) = grid(nx, ny, shape);
        let before: f64 = fill.iter().sum();
        let held = vec![false; nx * ny];
        let moved =
            LayerFill { fill: &mut fill, deposit_time_s: &mut time, nx, ny }.collapse_thin_features(&held, 4, 100);
        assert!(moved >= 2 * 20, "the whole ray, and the bead's square corners: {moved}");
        let after: f64 = fill.iter().sum();
        assert!((after - before).abs() < 1e-9, "{before} → {after}");
        // (The disc's lowest point reaches one row into the ray's root: that row stays.)
        assert!((26..ny).all(|y| fill[y * nx + 29] == 0.0 && fill[y * nx + 30] == 0.0));
        assert!(fill[24 * nx + 29] > 1.0 && fill[24 * nx + 29] < 2.0, "the ray piles around its root");
        assert!(time[30 * nx + 29].is_infinite(), "an emptied cell has no deposit time");
    }

    #[test]
    fn a_thin_bead_under_the_nozzle_stays() {
        // The same ray, but printed along: the nozzle passed over it, so it is a bead.
        let (nx, ny) = (60, 60);
        let (mut fill, mut time) =
            grid(nx, ny, |x, y| if (29..31).contains(&x) && (5..45).contains(&y) { 1.0 } else { 0.0 });
        let original = fill.clone();
        let held = cells_near((5..45).map(|y| [30.0, y as f64 + 0.5]), 3.0, nx, ny);
        let moved =
            LayerFill { fill: &mut fill, deposit_time_s: &mut time, nx, ny }.collapse_thin_features(&held, 4, 100);
        assert_eq!(moved, 0);
        assert_eq!(fill, original);
    }

    #[test]
    fn a_ray_hanging_from_a_thin_bead_under_the_nozzle_collapses_into_it() {
        // A 6-cell wide bead the nozzle printed (held, narrower than the disc, so nothing
        // of it is opened), and a 4-cell wide ray off its end where the nozzle never went:
        // the ray's material goes back into the bead, which stays.
        let (nx, ny) = (60, 80);
        let bead = |x: usize, y: usize| (27..33).contains(&x) && (5..40).contains(&y);
        let ray = |x: usize, y: usize| (28..32).contains(&x) && (40..60).contains(&y);
        let (mut fill, mut time) = grid(nx, ny, |x, y| if bead(x, y) || ray(x, y) { 1.0 } else { 0.0 });
        let before: f64 = fill.iter().sum();
        let held = cells_near((5..38).map(|y| [30.0, y as f64 + 0.5]), 3.0, nx, ny);
        let moved =
            LayerFill { fill: &mut fill, deposit_time_s: &mut time, nx, ny }.collapse_thin_features(&held, 4, 100);
        assert!(moved >= 4 * 18, "{moved} cells moved");
        assert!((fill.iter().sum::<f64>() - before).abs() < 1e-9);
        assert!((43..ny).all(|y| (0..nx).all(|x| fill[y * nx + x] == 0.0)), "the ray is gone");
        assert!((5..38).all(|y| fill[y * nx + 30] >= 1.0), "the bead stays");
    }

    #[test]
    fn features_wider_than_the_disc_keep_their_material() {
        // A 12-cell wide band: only its square ends' corner cells, which no disc of
        // radius 4 reaches, may move; its body loses nothing.
        let (nx, ny) = (40, 40);
        let band = |x: usize, y: usize| if (5..35).contains(&x) && (10..22).contains(&y) { 1.0 } else { 0.0 };
        let (mut fill, mut time) = grid(nx, ny, band);
        let original = fill.clone();
        let held = vec![false; nx * ny];
        let moved =
            LayerFill { fill: &mut fill, deposit_time_s: &mut time, nx, ny }.collapse_thin_features(&held, 4, 100);
        assert!(moved <= 4 * 8, "{moved} cells moved");
        for y in 10..22 {
            for x in 9..31 {
                assert!(fill[y * nx + x] >= original[y * nx + x], "cell ({x}, {y}) lost material");
            }
        }
    }
}
