//! The noise covariances W and V, given as SKOs or as full matrices: symmetric,
//! positive semi-definite, variances normal f64s.

use super::Errors;
use super::matrices::{check_shape, const_vector};
use crate::expr::compile_const;
use crate::model::Value;
use crate::text::num;
use std::collections::BTreeMap;

/// SKOs (diagonal covariance) or a full covariance matrix: returns (cov, skos).
pub(crate) fn noise_cov(
    sko: Option<&[Value]>,
    cov: Option<&[Vec<Value>]>,
    dim: usize,
    (sko_path, cov_path, sym): (&str, &str, &str),
    params: &BTreeMap<String, f64>,
    errs: &mut Errors,
) -> (Vec<f64>, Vec<f64>) {
    match (sko, cov) {
        (Some(_), Some(_)) => {
            errs.at(
                cov_path,
                format!(
                    "give either {} or {}, not both",
                    leaf(sko_path),
                    leaf(cov_path)
                ),
            );
            (vec![0.0; dim * dim], vec![0.0; dim])
        }
        (None, None) => {
            errs.at(
                sko_path,
                format!(
                    "missing: give the SKOs {} ({sym} entries) or the covariance {}",
                    leaf(sko_path),
                    leaf(cov_path)
                ),
            );
            (vec![0.0; dim * dim], vec![0.0; dim])
        }
        (Some(s), None) => {
            let s = const_vector(Some(s), dim, sko_path, sym, params, errs, true);
            let mut cov = vec![0.0; dim * dim];
            for i in 0..dim {
                cov[i * dim + i] = s[i] * s[i];
            }
            (cov, s)
        }
        (None, Some(m)) => {
            let mut cov = vec![0.0; dim * dim];
            if !check_shape(m, dim, Some(dim), cov_path, sym, sym, errs) {
                return (cov, vec![0.0; dim]);
            }
            let before = errs.0.len();
            for i in 0..dim {
                for j in 0..dim {
                    let p = format!("{cov_path}[{i}][{j}]");
                    match compile_const(&m[i][j], params, &p) {
                        Ok(x) => cov[i * dim + j] = x,
                        Err(e) => errs.push(e),
                    }
                }
            }
            if errs.0.len() == before {
                // Variances below f64's normal range, as for SKOs (const_vector).
                for i in 0..dim {
                    let x = cov[i * dim + i];
                    if x > 0.0 && x < f64::MIN_POSITIVE {
                        errs.at(
                            &format!("{cov_path}[{i}][{i}]"),
                            format!("a variance must be 0 or at least 2.2e-308 (a normal f64), got {x:e}"),
                        );
                    }
                }
                for i in 0..dim {
                    for j in 0..i {
                        let (x, y) = (cov[i * dim + j], cov[j * dim + i]);
                        if (x - y).abs() > 1e-12 * x.abs().max(y.abs()) {
                            errs.at(
                                &format!("{cov_path}[{i}][{j}]"),
                                format!("a covariance must be symmetric: this entry is {} but its mirror across the diagonal is {}", num(x), num(y)),
                            );
                        }
                    }
                }
                if let Some(why) = not_semi_definite(&cov, dim) {
                    errs.at(cov_path, why);
                }
            }
            let s = (0..dim).map(|i| cov[i * dim + i].max(0.0).sqrt()).collect();
            (cov, s)
        }
    }
}

/// Why a symmetric `m` (dim × dim) is not positive semi-definite, or `None`: its
/// smallest eigenvalue below −1e-12 of the largest. The eigenvalue algorithm's
/// iterations are bounded (an unbounded one can loop for ever on some matrices,
/// dimforge/nalgebra#611); should it not converge, a Cholesky factorisation of m
/// scaled to a unit diagonal, plus 1e-12 on it, decides instead.
fn not_semi_definite(m: &[f64], dim: usize) -> Option<String> {
    let mat = nalgebra::DMatrix::from_row_slice(dim, dim, m);
    match nalgebra::SymmetricEigen::try_new(mat.clone(), f64::EPSILON, 1000 * dim.max(1)) {
        Some(eig) => {
            let min = eig
                .eigenvalues
                .iter()
                .cloned()
                .fold(f64::INFINITY, f64::min);
            let max = eig.eigenvalues.iter().cloned().fold(0.0, f64::max);
            (min < -1e-12 * max.max(f64::MIN_POSITIVE)).then(|| {
                format!("a covariance must be positive semi-definite; its smallest eigenvalue is {min:e}")
            })
        }
        None => (!semi_definite_by_cholesky(m, dim)).then(|| {
            "a covariance must be positive semi-definite; it is not (its Cholesky factorisation fails)".to_string()
        }),
    }
}

/// Whether a symmetric `m` (dim × dim) is positive semi-definite to 1e-12 relative, by a
/// Cholesky factorisation of m scaled to a unit diagonal plus 1e-12 on it. A negative
/// variance, or a zero one with a non-zero covariance in its row, is not.
fn semi_definite_by_cholesky(m: &[f64], dim: usize) -> bool {
    let row_nonzero = |i: usize| (0..dim).any(|j| m[i * dim + j] != 0.0);
    if (0..dim).any(|i| m[i * dim + i] < 0.0 || (m[i * dim + i] == 0.0 && row_nonzero(i))) {
        return false;
    }
    let d: Vec<f64> = (0..dim).map(|i| m[i * dim + i].sqrt()).collect();
    let scaled = nalgebra::DMatrix::from_fn(dim, dim, |i, j| {
        let s = d[i] * d[j];
        let x = if s > 0.0 { m[i * dim + j] / s } else { 0.0 };
        if i == j { x + 1e-12 } else { x }
    });
    scaled.cholesky().is_some()
}

fn leaf(path: &str) -> &str {
    path.rsplit('.').next().unwrap_or(path)
}

#[cfg(test)]
mod tests {
    /// The fallback semi-definiteness check (where the eigenvalue algorithm does not
    /// converge) against the eigenvalues, on random covariances G Gᵀ of full and low
    /// rank, and on them less a multiple of the identity beyond the tolerance.
    #[test]
    fn the_cholesky_check_agrees_with_the_eigenvalues() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        for dim in [1, 2, 4, 9] {
            for rank in [1, dim / 2 + 1, dim] {
                let g: Vec<f64> = (0..dim * rank)
                    .map(|_| rng.random_range(-1.0..1.0))
                    .collect();
                let mut m = vec![0.0; dim * dim];
                for i in 0..dim {
                    for j in 0..dim {
                        m[i * dim + j] = (0..rank).map(|k| g[i * rank + k] * g[j * rank + k]).sum();
                    }
                }
                assert!(
                    super::semi_definite_by_cholesky(&m, dim),
                    "G Gᵀ, {dim} × {dim}, rank {rank}"
                );
                assert_eq!(super::not_semi_definite(&m, dim), None);
                let largest = (0..dim).map(|i| m[i * dim + i]).fold(0.0, f64::max);
                for i in 0..dim {
                    m[i * dim + i] -= 1e-6 * largest;
                }
                let by_eigen = super::not_semi_definite(&m, dim).is_none();
                assert_eq!(
                    super::semi_definite_by_cholesky(&m, dim),
                    by_eigen,
                    "less 1e-6, {dim} × {dim}, rank {rank}"
                );
                assert_eq!(by_eigen, rank == dim && by_eigen, "{dim}, {rank}");
            }
        }
        // A zero variance with a covariance beside it, and a negative variance.
        assert!(!super::semi_definite_by_cholesky(&[0.0, 1.0, 1.0, 1.0], 2));
        assert!(!super::semi_definite_by_cholesky(&[-1.0, 0.0, 0.0, 1.0], 2));
        assert!(super::semi_definite_by_cholesky(&[0.0, 0.0, 0.0, 1.0], 2));
    }
}
