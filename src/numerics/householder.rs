//! Householder triangularisation of the leading columns of an array, the SRIF's one
//! operation (METHOD §3, (2.1.10), (2.1.13)): an orthogonal T with T A = [R B; 0 E],
//! R upper triangular, applied in place to every column of A.
//!
//! Hand-written rather than nalgebra's `QR` because the SRIF needs the transform of the
//! trailing columns (the right-hand sides, and later the derivative arrays of seed
//! §2.4) with only the leading `p` columns triangularised, in a buffer it reuses every
//! step; `QR::new` takes its matrix by value and triangularises every column. The
//! test compares R with nalgebra's.

/// Triangularise the first `p` columns of `a` (`rows` × `cols`, row-major) in place:
/// on return a[i][j] = 0 for j < p, i > j, and every column has been multiplied by the
/// same orthogonal matrix (a product of `min(p, rows − 1)` Householder reflections).
/// The diagonal R_jj may be of either sign (|R_jj| is what determinants use).
pub fn triangularise(a: &mut [f64], rows: usize, cols: usize, p: usize) {
    debug_assert!(a.len() >= rows * cols && p <= cols);
    for j in 0..p.min(rows) {
        // The column below the diagonal, scaled by its largest entry so that its
        // squares neither overflow nor underflow.
        let scale = (j..rows).fold(0.0f64, |s, i| s.max(a[i * cols + j].abs()));
        if scale == 0.0 {
            continue;
        }
        let norm = scale
            * (j..rows)
                .map(|i| {
                    let x = a[i * cols + j] / scale;
                    x * x
                })
                .sum::<f64>()
                .sqrt();
        let ajj = a[j * cols + j];
        // alpha of the sign opposite to a_jj: v_0 = a_jj − alpha has no cancellation.
        let alpha = if ajj > 0.0 { -norm } else { norm };
        let v0 = ajj - alpha;
        // H = I − 2 v vᵀ / (vᵀv), vᵀv = −2 alpha v_0, v = (v_0, a_{j+1,j}, …).
        let f = 1.0 / (alpha * v0);
        for c in j + 1..cols {
            let mut s = v0 * a[j * cols + c];
            for i in j + 1..rows {
                s += a[i * cols + j] * a[i * cols + c];
            }
            let s = s * f;
            a[j * cols + c] += v0 * s;
            for i in j + 1..rows {
                a[i * cols + c] += a[i * cols + j] * s;
            }
        }
        a[j * cols + j] = alpha;
        for i in j + 1..rows {
            a[i * cols + j] = 0.0;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DMatrix;

    /// R against nalgebra's QR (rows up to sign), and the transform orthogonal: the
    /// trailing columns keep their norms and their inner products with each other.
    #[test]
    fn matches_nalgebra_qr_and_keeps_norms() {
        let (rows, cols, p) = (7, 5, 3);
        let a: Vec<f64> = (0..rows * cols)
            .map(|k| ((k * 37 % 23) as f64 - 11.0) / 3.0 + if k % 6 == 0 { 1e3 } else { 0.0 })
            .collect();
        let mut t = a.clone();
        triangularise(&mut t, rows, cols, p);
        let lead = DMatrix::from_fn(rows, p, |i, j| a[i * cols + j]);
        let r = lead.qr().r();
        for i in 0..p {
            let sign = (t[i * cols + i] / r[(i, i)]).signum();
            for j in 0..p {
                let want = sign * r[(i, j)];
                assert!((t[i * cols + j] - want).abs() <= 1e-12 * (1.0 + want.abs()));
            }
        }
        for i in p..rows {
            for j in 0..p {
                assert_eq!(t[i * cols + j], 0.0);
            }
        }
        for c1 in 0..cols {
            for c2 in 0..cols {
                let dot = |m: &[f64]| {
                    (0..rows)
                        .map(|i| m[i * cols + c1] * m[i * cols + c2])
                        .sum::<f64>()
                };
                let (x, y) = (dot(&a), dot(&t));
                assert!(
                    (x - y).abs() <= 1e-9 * (1.0 + x.abs()),
                    "columns {c1},{c2}: {x} {y}"
                );
            }
        }
    }

    #[test]
    fn a_zero_column_is_left_alone() {
        let mut a = vec![0.0, 1.0, 0.0, 2.0, 0.0, 3.0];
        triangularise(&mut a, 3, 2, 1);
        assert_eq!(a, vec![0.0, 1.0, 0.0, 2.0, 0.0, 3.0]);
    }
}
