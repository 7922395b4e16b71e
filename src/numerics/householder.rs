//! Householder triangularisation of the leading columns of an array, the SRIF's one
//! operation (METHOD §3, (2.1.10), (2.1.13)): an orthogonal T with T A = [R B; 0 E],
//! R upper triangular, applied in place to every column of A.
//!
//! Hand-written rather than nalgebra's `QR` because the SRIF needs the transform of the
//! trailing columns (the right-hand sides, and later the derivative arrays of seed
//! §2.4) with only the leading `p` columns triangularised, in a buffer it reuses every
//! step; `QR::new` takes its matrix by value and triangularises every column. The
//! test compares R with nalgebra's.

/// The columns' scales between which a reflection is formed as it is; outside, from
/// the column divided by its scale.
const SMALL: f64 = 1e-140;
const LARGE: f64 = 1e140;

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
        // H = I − 2 v vᵀ / (vᵀv), vᵀv = −2 alpha v_0, v = (v_0, a_{j+1,j}, …). H is the
        // same for any multiple of v: a column far from 1 (a derivative decayed to
        // 1e-160) takes v / scale, so that alpha·v_0 neither underflows to 0 nor
        // overflows.
        let (v0, f) = if (SMALL..=LARGE).contains(&scale) {
            let v0 = ajj - alpha;
            (v0, 1.0 / (alpha * v0))
        } else {
            for i in j + 1..rows {
                a[i * cols + j] /= scale;
            }
            let (alpha, v0) = (alpha / scale, ajj / scale - alpha / scale);
            (v0, 1.0 / (alpha * v0))
        };
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

/// The derivatives of a triangularisation (METHOD §3, seed (2.4.1)–(2.4.8)).
///
/// `a` is `rows` × (`cols` · (1 + `np`)), row-major: block 0 an array A, block 1 + i its
/// derivative ∂_iA. After [`triangularise`] of its first `p` columns (which applies T to
/// every block), block 0 is B = T A = [R B12; 0 B22] and block 1 + i is X = T ∂_iA;
/// this turns each X into ∂_iB = Ω B + X, with Ω = ∂T Tᵀ skew (2.4.3): Ω21 = −X2 R⁻¹
/// (the zeros under R stay zero), Ω11 = L_Yᵀ − L_Y with Y = X1 R⁻¹ (so that
/// ∂R = (L_Yᵀ + D_Y + U_Y) R is upper triangular (2.4.8)), Ω12 = −Ω21ᵀ, Ω22 = 0 (the
/// rows under R are free up to a rotation; the seed's W22 = 0). No inverse of A.
/// `y` (rows × p) and `omega` (rows × rows) are work buffers. R must be non-singular.
pub fn differentiate(
    a: &mut [f64],
    rows: usize,
    cols: usize,
    p: usize,
    np: usize,
    y: &mut [f64],
    omega: &mut [f64],
) {
    let width = cols * (1 + np);
    let p = p.min(rows);
    for d in 0..np {
        let off = cols * (1 + d);
        // Y = X[:, :p] R⁻¹, row by row: y R = x (R upper triangular).
        for r in 0..rows {
            for j in 0..p {
                let mut v = a[r * width + off + j];
                for k in 0..j {
                    v -= y[r * p + k] * a[k * width + j];
                }
                y[r * p + j] = v / a[j * width + j];
            }
        }
        omega[..rows * rows].fill(0.0);
        for r in 0..rows {
            for j in 0..p.min(r) {
                // r > j: below the diagonal of the first p columns.
                omega[r * rows + j] = -y[r * p + j];
                omega[j * rows + r] = y[r * p + j];
            }
        }
        for r in 0..rows {
            for c in 0..cols {
                let v = if c < p && r > c {
                    0.0
                } else {
                    let mut s = a[r * width + off + c];
                    for k in 0..rows {
                        s += omega[r * rows + k] * a[k * width + c];
                    }
                    s
                };
                a[r * width + off + c] = v;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DMatrix;

    /// A matrix scaled by 1e-200 or 1e200 (a derivative decayed, or grown, far from 1)
    /// triangularises to the unscaled one's result times the scale — with no NaN, where
    /// alpha·v_0 once underflowed to 0 (found by the expected information's decayed
    /// realisations of a prior's param).
    #[test]
    fn a_tiny_or_huge_matrix_triangularises_as_its_unscaled_one() {
        let (rows, cols, p) = (6, 5, 4);
        let a: Vec<f64> = (0..rows * cols)
            .map(|k| ((k * 29 % 17) as f64 - 8.0) / 5.0)
            .collect();
        let mut unit = a.clone();
        triangularise(&mut unit, rows, cols, p);
        for scale in [1e-200, 1e200] {
            let mut t: Vec<f64> = a.iter().map(|x| x * scale).collect();
            triangularise(&mut t, rows, cols, p);
            for (k, (x, y)) in t.iter().zip(&unit).enumerate() {
                let want = y * scale;
                assert!(
                    (x - want).abs() <= 1e-13 * scale * (1.0 + y.abs()),
                    "scale {scale:e}, entry {k}: {x:e} against {want:e}"
                );
            }
        }
    }

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

    /// ∂B against central differences of B(θ) for A(θ) = A0 + θ A1 + θ² A2 (the
    /// triangularisation's signs do not flip near θ, so B is smooth there).
    #[test]
    fn derivatives_match_central_differences() {
        let (rows, cols, p) = (6, 4, 3);
        let base = |k: usize, s: usize| ((k * s % 29) as f64 - 14.0) / 7.0;
        let at = |th: f64| -> Vec<f64> {
            (0..rows * cols)
                .map(|k| {
                    base(k, 7)
                        + 3.0 * ((k % 5 == 0) as u8 as f64)
                        + th * base(k, 11)
                        + th * th * base(k, 13)
                })
                .collect()
        };
        let th = 0.3;
        let mut aug = vec![0.0; rows * cols * 2];
        let (a0, da) = (
            at(th),
            (0..rows * cols)
                .map(|k| base(k, 11) + 2.0 * th * base(k, 13))
                .collect::<Vec<_>>(),
        );
        for r in 0..rows {
            aug[r * 2 * cols..r * 2 * cols + cols].copy_from_slice(&a0[r * cols..r * cols + cols]);
            aug[r * 2 * cols + cols..r * 2 * cols + 2 * cols]
                .copy_from_slice(&da[r * cols..r * cols + cols]);
        }
        triangularise(&mut aug, rows, 2 * cols, p);
        let (mut y, mut om) = (vec![0.0; rows * p], vec![0.0; rows * rows]);
        differentiate(&mut aug, rows, cols, p, 1, &mut y, &mut om);
        let h = 1e-6;
        let (mut plus, mut minus) = (at(th + h), at(th - h));
        triangularise(&mut plus, rows, cols, p);
        triangularise(&mut minus, rows, cols, p);
        // The rows under R are defined up to a rotation: compare R, B12 (the first p
        // rows) exactly, and of B22 only what is invariant, its columns' Gram matrix.
        for r in 0..p {
            for c in 0..cols {
                let fd = (plus[r * cols + c] - minus[r * cols + c]) / (2.0 * h);
                let got = aug[r * 2 * cols + cols + c];
                assert!(
                    (got - fd).abs() <= 1e-6 * (1.0 + fd.abs()),
                    "row {r} col {c}: {got} {fd}"
                );
            }
        }
        for c1 in p..cols {
            for c2 in p..cols {
                let gram = |m: &[f64], w: usize, o: usize| {
                    (p..rows)
                        .map(|r| m[r * w + o + c1] * m[r * w + o + c2])
                        .sum::<f64>()
                };
                let fd = (gram(&plus, cols, 0) - gram(&minus, cols, 0)) / (2.0 * h);
                let got: f64 = (p..rows)
                    .map(|r| {
                        aug[r * 2 * cols + cols + c1] * aug[r * 2 * cols + c2]
                            + aug[r * 2 * cols + c1] * aug[r * 2 * cols + cols + c2]
                    })
                    .sum();
                assert!(
                    (got - fd).abs() <= 1e-6 * (1.0 + fd.abs()),
                    "gram {c1},{c2}: {got} {fd}"
                );
            }
        }
    }
}
