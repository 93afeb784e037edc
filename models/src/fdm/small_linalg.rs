//! Stack-allocated Cholesky and LU solves for the tiny (≤ 5 × 5) systems of the
//! per-segment least squares of eq. 3 and the MAP of eq. 5 (paper 000). It runs inside
//! the 441-point `r_a`, `r_F` grid search, so it must not allocate; the public MAP solve
//! in `transfer.rs` uses faer and a test checks that both agree.

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
/// equilibrated row, or a non-finite solution.
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

#[cfg(test)]
mod tests {
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

    #[test]
    fn rejects_indefinite_matrix() {
        let a = [[1.0, 2.0], [2.0, 1.0]];
        assert!(spd_solve(&a, &[1.0, 1.0]).is_none());
    }
}
