//! Stack-allocated Cholesky and LU solves for the tiny (≤ 5 × 5) systems of the
//! per-segment least squares of eq. 3 and the MAP of eq. 5 (paper 000). It runs inside
//! the 441-point `r_a`, `r_F` grid search, so it must not allocate; the public MAP solve
//! in `transfer.rs` uses faer and a test checks that both agree. The LU solves of the
//! chain fixed point come in batches of independent systems ([`LuBatch`]), each lane
//! bit-identical to the one-system `lu_solve`.

/// Solves `A x = b` for a symmetric positive definite `A` by Cholesky factorisation.
/// Returns `None` when `A` is not numerically positive definite.
pub(crate) fn spd_solve<const N: usize>(a: &[[f64; N]; N], b: &[f64; N]) -> Option<[f64; N]> {
    let mut l = [[0.0; N]; N];
    for i in 0..N {
        for j in 0..=i {
            let mut sum = a[i][j];
            for k in 0..j {
                sum -= l[i][k] * l[j][k];
            }
            if i == j {
                let scale = a[i][i].abs().max(f64::MIN_POSITIVE);
                // Also rejects NaN.
                let positive = sum > 1e-14 * scale;
                if !positive {
                    return None;
                }
                l[i][i] = sum.sqrt();
            } else {
                l[i][j] = sum / l[j][j];
            }
        }
    }
    let mut y = [0.0; N];
    for i in 0..N {
        let mut sum = b[i];
        for k in 0..i {
            sum -= l[i][k] * y[k];
        }
        y[i] = sum / l[i][i];
    }
    let mut x = [0.0; N];
    for i in (0..N).rev() {
        let mut sum = y[i];
        for k in i + 1..N {
            sum -= l[k][i] * x[k];
        }
        x[i] = sum / l[i][i];
    }
    Some(x)
}

/// Solves `A x = b` for a general square `A` by LU factorisation with partial pivoting,
/// after scaling every row to unit maximum (a strong prior can make rows differ by many
/// orders of magnitude). Returns `None` for a zero row, a pivot below `1e-14` of its
/// equilibrated row, or a non-finite solution. The chain solves use [`LuBatch`], which
/// does exactly this arithmetic for several systems at once; this one-system form is
/// its definition, kept for the tests that check it.
#[cfg(test)]
pub(crate) fn lu_solve<const N: usize>(a: &[[f64; N]; N], b: &[f64; N]) -> Option<[f64; N]> {
    let (mut m, mut x) = (*a, *b);
    for (row, rhs) in m.iter_mut().zip(x.iter_mut()) {
        let scale = row.iter().fold(0.0f64, |s, v| s.max(v.abs()));
        let nonzero = scale > 0.0 && scale.is_finite();
        if !nonzero {
            return None;
        }
        row.iter_mut().for_each(|v| *v /= scale);
        *rhs /= scale;
    }
    for col in 0..N {
        let pivot = (col..N).max_by(|&i, &j| m[i][col].abs().total_cmp(&m[j][col].abs()))?;
        let usable = m[pivot][col].abs() > 1e-14;
        if !usable {
            return None;
        }
        m.swap(col, pivot);
        x.swap(col, pivot);
        for row in col + 1..N {
            let f = m[row][col] / m[col][col];
            for k in col..N {
                m[row][k] -= f * m[col][k];
            }
            x[row] -= f * x[col];
        }
    }
    for row in (0..N).rev() {
        let mut sum = x[row];
        for k in row + 1..N {
            sum -= m[row][k] * x[k];
        }
        x[row] = sum / m[row][row];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// Independent `N × N` systems solved side by side, one per lane, each by exactly the
/// arithmetic of `lu_solve` (the same operations on the same values in the same order,
/// so every lane's solution is bit-identical to `lu_solve`'s). One system is a chain of
/// dependent divisions and comparisons that leaves the CPU waiting; `L` independent ones
/// interleaved keep it busy, and the lane-wise loops are vectorised (struct of arrays:
/// `m[row][col][lane]`; row swaps are lane-wise selects, not branches).
#[derive(Debug, Clone)]
pub(crate) struct LuBatch<const N: usize, const L: usize> {
    m: [[[f64; L]; N]; N],
    x: [[f64; L]; N],
}

impl<const N: usize, const L: usize> Default for LuBatch<N, L> {
    fn default() -> Self {
        Self::identity()
    }
}

impl<const N: usize, const L: usize> LuBatch<N, L> {
    /// Every lane the system `I x = 0`.
    pub(crate) fn identity() -> Self {
        let mut batch = Self { m: [[[0.0; L]; N]; N], x: [[0.0; L]; N] };
        (0..L).for_each(|l| batch.clear(l));
        batch
    }

    /// Puts the system `A x = b` in `lane`.
    #[cfg(test)]
    pub(crate) fn set(&mut self, lane: usize, a: &[[f64; N]; N], b: &[f64; N]) {
        for i in 0..N {
            for j in 0..N {
                self.m[i][j][lane] = a[i][j];
            }
            self.x[i][lane] = b[i];
        }
    }

    /// Puts row `i` of a system, `A[i] x = b[i]`, in `lane`.
    pub(crate) fn set_row(&mut self, lane: usize, i: usize, a: &[f64; N], b: f64) {
        for j in 0..N {
            self.m[i][j][lane] = a[j];
        }
        self.x[i][lane] = b;
    }

    /// Puts `I x = 0` in `lane` (a lane with no system to solve).
    pub(crate) fn clear(&mut self, lane: usize) {
        for i in 0..N {
            for j in 0..N {
                self.m[i][j][lane] = if i == j { 1.0 } else { 0.0 };
            }
            self.x[i][lane] = 0.0;
        }
    }

    /// Solves every lane in place (`lu_solve` of the lane's system) into `out`. Rows
    /// marked in `equilibrated` were put in already scaled by [`equilibrate_row`] (in
    /// every lane, which then had them pass its test): the same values `lu_solve` would
    /// compute, for a row that is the same in many solves.
    pub(crate) fn solve(&mut self, equilibrated: &[bool; N], out: &mut [Option<[f64; N]>; L]) {
        let mut ok = self.equilibrate(equilibrated);
        for col in 0..N {
            self.pivot(col, &mut ok);
            self.eliminate(col);
        }
        self.back_substitute();
        for (l, o) in out.iter_mut().enumerate() {
            let x: [f64; N] = std::array::from_fn(|i| self.x[i][l]);
            *o = (ok[l] && x.iter().all(|v| v.is_finite())).then_some(x);
        }
    }

    /// Scales every row to unit maximum; a lane with a zero or non-finite row fails.
    fn equilibrate(&mut self, done: &[bool; N]) -> [bool; L] {
        let mut ok = [true; L];
        let rows = self.m.iter_mut().zip(self.x.iter_mut()).zip(done);
        for ((row, rhs), _) in rows.filter(|(_, &done)| !done) {
            let mut scale = [0.0f64; L];
            for v in row.iter() {
                for l in 0..L {
                    scale[l] = scale[l].max(v[l].abs());
                }
            }
            for l in 0..L {
                ok[l] &= scale[l] > 0.0 && scale[l].is_finite();
            }
            for v in row.iter_mut().chain([rhs]) {
                for l in 0..L {
                    v[l] /= scale[l];
                }
            }
        }
        ok
    }

    /// Partial pivoting on column `col`: per lane the last row of largest magnitude
    /// (`Iterator::max_by` with `total_cmp`, as `lu_solve`) is swapped into place. A NaN
    /// candidate, which `total_cmp` ranks above every number and which then fails the
    /// pivot test, fails the lane; among numbers `>=` on magnitudes is that order.
    fn pivot(&mut self, col: usize, ok: &mut [bool; L]) {
        let mut best = [0.0f64; L];
        // Row indices as floats, so that the selects below compare like with like.
        let mut at = [col as f64; L];
        for i in col..N {
            for l in 0..L {
                let v = self.m[i][col][l].abs();
                ok[l] &= !v.is_nan();
                let larger = v >= best[l];
                best[l] = if larger { v } else { best[l] };
                at[l] = if larger { i as f64 } else { at[l] };
            }
        }
        for l in 0..L {
            ok[l] &= best[l] > 1e-14;
        }
        // Lanes that agree on the pivot row (often: they share the data part of their
        // systems) swap whole rows, others lane by lane, and only with the rows some lane
        // picked. Either way columns left of `col`, never read again, may or may not move.
        if at.iter().all(|&a| a == at[0]) {
            let p = at[0] as usize;
            if p != col {
                // Element by element: `<[_]>::swap` of whole rows calls memcpy.
                for k in col..N {
                    for l in 0..L {
                        (self.m[col][k][l], self.m[p][k][l]) = (self.m[p][k][l], self.m[col][k][l]);
                    }
                }
                for l in 0..L {
                    (self.x[col][l], self.x[p][l]) = (self.x[p][l], self.x[col][l]);
                }
            }
            return;
        }
        let (top, below) = self.m.split_at_mut(col + 1);
        let (xt, xb) = self.x.split_at_mut(col + 1);
        let (pivot, x_pivot) = (&mut top[col], &mut xt[col]);
        for (i, (row, x)) in below.iter_mut().zip(xb.iter_mut()).enumerate() {
            let i = (col + 1 + i) as f64;
            if !at.contains(&i) {
                continue;
            }
            for k in col..N {
                swap_where(&at, i, &mut pivot[k], &mut row[k]);
            }
            swap_where(&at, i, x_pivot, x);
        }
    }

    /// Eliminates column `col` below the pivot.
    fn eliminate(&mut self, col: usize) {
        let (top, below) = self.m.split_at_mut(col + 1);
        let (xt, xb) = self.x.split_at_mut(col + 1);
        let (pivot, x_pivot) = (&top[col], &xt[col]);
        for (row, x) in below.iter_mut().zip(xb.iter_mut()) {
            let mut f = [0.0; L];
            for l in 0..L {
                f[l] = row[col][l] / pivot[col][l];
            }
            for k in col..N {
                for l in 0..L {
                    row[k][l] -= f[l] * pivot[k][l];
                }
            }
            for l in 0..L {
                x[l] -= f[l] * x_pivot[l];
            }
        }
    }

    fn back_substitute(&mut self) {
        for row in (0..N).rev() {
            let mut sum = self.x[row];
            for k in row + 1..N {
                for l in 0..L {
                    sum[l] -= self.m[row][k][l] * self.x[k][l];
                }
            }
            for l in 0..L {
                self.x[row][l] = sum[l] / self.m[row][row][l];
            }
        }
    }
}

/// The first step of `lu_solve` for one row `A[i] x = b[i]`: scaled to unit maximum,
/// as `lu_solve` scales it. `false` (the solve fails) for a zero or non-finite row.
pub(crate) fn equilibrate_row<const N: usize>(row: &mut [f64; N], rhs: &mut f64) -> bool {
    let scale = row.iter().fold(0.0f64, |s, v| s.max(v.abs()));
    row.iter_mut().for_each(|v| *v /= scale);
    *rhs /= scale;
    scale > 0.0 && scale.is_finite()
}

/// Swaps `a[l]` and `b[l]` in the lanes where `at[l] == i`.
fn swap_where<const L: usize>(at: &[f64; L], i: f64, a: &mut [f64; L], b: &mut [f64; L]) {
    for l in 0..L {
        let hit = at[l] == i;
        let (x, y) = (a[l], b[l]);
        a[l] = if hit { y } else { x };
        b[l] = if hit { x } else { y };
    }
}

#[cfg(test)]
mod tests {
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;

    #[test]
    fn solves_spd_system_to_rounding() {
        // A = MᵀM + I is SPD; check A·x ≈ b with a size-scaled tolerance.
        let m = [[1.0, 2.0, 0.5, -1.0], [0.3, -0.7, 1.1, 0.2], [2.0, 0.1, 0.0, 1.5], [-0.4, 0.9, 0.6, 0.8]];
        let mut a = [[0.0; 4]; 4];
        for i in 0..4 {
            for j in 0..4 {
                a[i][j] = (0..4).map(|k| m[k][i] * m[k][j]).sum::<f64>() + f64::from(i == j);
            }
        }
        let b = [1.0, -2.0, 0.5, 3.0];
        let x = spd_solve(&a, &b).unwrap();
        for i in 0..4 {
            let ax: f64 = (0..4).map(|j| a[i][j] * x[j]).sum();
            assert!((ax - b[i]).abs() < 4.0 * 1e-14 * 10.0);
        }
    }

    #[test]
    fn lu_solves_nonsymmetric_system() {
        // A needs a row swap (zero leading pivot); check A·x ≈ b.
        let a = [[0.0, 2.0, 1.0], [1.0, 1.0, 0.0], [3.0, 0.0, 4.0]];
        let b = [1.0, 2.0, 3.0];
        let x = lu_solve(&a, &b).unwrap();
        for i in 0..3 {
            let ax: f64 = (0..3).map(|j| a[i][j] * x[j]).sum();
            assert!((ax - b[i]).abs() < 1e-13);
        }
        assert!(lu_solve(&[[1.0, 2.0], [2.0, 4.0]], &[1.0, 1.0]).is_none());
        // Rows scaled by 1e12 and 1: equilibration keeps the solve accurate.
        let a = [[4e12, 1e12], [1.0, 3.0]];
        let x = lu_solve(&a, &[1e12, 2.0]).unwrap();
        assert!((4.0 * x[0] + x[1] - 1.0).abs() < 1e-12 && (x[0] + 3.0 * x[1] - 2.0).abs() < 1e-12);
    }

    /// A system whose entries mix magnitudes, exact ties of magnitude (several rows
    /// competing for a pivot), zeros, and now and then a zero row, a NaN or an infinity.
    fn awkward_system(rng: &mut ChaCha8Rng) -> ([[f64; 5]; 5], [f64; 5]) {
        let entry = |rng: &mut ChaCha8Rng| -> f64 {
            match rng.random_range(0..40) {
                0..=5 => 0.0,
                6..=11 => [1.0, -1.0, 2.0, -2.0][rng.random_range(0..4)],
                12 => f64::NAN,
                13 => f64::INFINITY,
                14 => 1e-300,
                _ => rng.random_range(-1.0..1.0) * 10f64.powi(rng.random_range(-12..12)),
            }
        };
        let mut a = [[0.0; 5]; 5];
        for row in a.iter_mut() {
            for v in row.iter_mut() {
                *v = entry(rng);
            }
        }
        if rng.random_range(0..10) == 0 {
            a[rng.random_range(0..5)] = [0.0; 5];
        }
        if rng.random_range(0..10) == 0 {
            a[4] = a[0];
        }
        (a, std::array::from_fn(|_| entry(rng)))
    }

    #[test]
    fn batched_lu_equals_lu_solve_bit_for_bit() {
        // Every lane of a batch must give exactly lu_solve's answer (bits, and None where
        // it fails), whatever its neighbours hold, on systems built to hit every branch:
        // pivot ties, rejected pivots, zero rows, NaN and infinite entries.
        let mut rng = ChaCha8Rng::seed_from_u64(18);
        let bits = |x: Option<[f64; 5]>| x.map(|v| v.map(f64::to_bits));
        let (mut solved, mut failed) = (0, 0);
        for round in 0..20_000 {
            let mut systems: Vec<_> = (0..3).map(|_| awkward_system(&mut rng)).collect();
            if round % 2 == 0 {
                // The same matrix in every used lane (other right-hand sides): lanes that
                // agree on their pivots, as a training set's configurations often do.
                let a = systems[0].0;
                systems.iter_mut().for_each(|s| s.0 = a);
            }
            let mut batch = LuBatch::<5, 4>::identity();
            for (lane, (a, b)) in systems.iter().enumerate() {
                batch.set(lane, a, b);
            }
            let mut lanes = [None; 4];
            batch.solve(&[false; 5], &mut lanes);
            for ((a, b), got) in systems.iter().zip(lanes) {
                let expected = lu_solve(a, b);
                assert_eq!(bits(got), bits(expected), "{a:?} {b:?}");
                if expected.is_some() {
                    solved += 1
                } else {
                    failed += 1
                }
            }
            assert_eq!(bits(lanes[3]), Some([0; 5]), "an unused lane solves I x = 0");
        }
        assert!(solved > 10_000 && failed > 5_000, "{solved} solved, {failed} failed");
    }

    #[test]
    fn rejects_indefinite_matrix() {
        let a = [[1.0, 2.0], [2.0, 1.0]];
        assert!(spd_solve(&a, &[1.0, 1.0]).is_none());
    }
}
