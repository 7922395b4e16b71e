//! The expected Fisher information (METHOD §3 (2.3.2)): the expectation of
//! M_ij = Σ_k [∂_iνᵀS⁻¹∂_jν + ½ tr(S⁻¹∂_iS S⁻¹∂_jS)] over data drawn from the model at
//! θ on the data's steps, with their missing measurements. Its inverse is the
//! Cramér–Rao bound of the estimates.
//!
//! The second term does not depend on the data: the SRIF gives it from its arrays
//! ([`Srif`], without the data term). The first is a second moment: ∂_iν_k =
//! −∂_iH x̂_k − H ∂_ix̂_k, with x̂_k and ∂_ix̂_k (the data held fixed) functions of the
//! innovations before step k, which are independent, ν_k ~ N(0, S_k). So the vector
//! [x̂; ∂_1x̂; …; ∂_px̂] is propagated as its mean and a square root of its covariance
//! (realisation rows, one per independent normal variable): at a measurement,
//! x̂⁺ = x̂ + Kν, ∂_ix̂⁺ = (I − KH)∂_ix̂ − K∂_iH x̂ + ∂_iK ν, where ν = Y ξ_x + L_R ξ_v
//! (Y = H R̃⁻¹, R = L_R L_Rᵀ) brings N + m fresh rows; then x̂ ← Φx̂ + u, ∂_ix̂ ←
//! ∂_iΦ x̂ + Φ∂_ix̂ + ∂_iu. The rows are compressed to N(1 + p) by an orthogonal
//! transformation after each step (only their second moment counts).
//!
//! The filter's matrices come from the SRIF's arrays, never from a covariance
//! recursion: P̃ = R̃⁻¹R̃⁻ᵀ, P̂ = R̂⁻¹R̂⁻ᵀ, I − KH = P̂P̃⁻¹ = P̂R̃ᵀR̃, S = YYᵀ + R,
//! K = P̃HᵀS⁻¹, ∂_iK = (∂_iP̃Hᵀ + P̃∂_iHᵀ − K∂_iS)S⁻¹ with ∂_iP̃ from ∂_iR̃ — so the
//! expected information stays accurate where a covariance recursion does not (a
//! vague prior with a nearly exact sensor).

use super::model::{Data, Discrete, Partial, Prior, PriorAt};
use super::srif::{Likelihood, Srif};
use crate::error::Error;
use crate::numerics::householder::triangularise;
use crate::numerics::linalg::{cholesky, cholesky_solve, mul, mul_abt_sym, solve_lower};

/// The expected information over the parameters whose `partials` are given (np × np,
/// row-major), on `data`'s steps with its missing measurements (its values are not
/// read).
pub fn expected_information(
    model: &Discrete,
    partials: &[Partial],
    prior: &Prior,
    data: &Data,
) -> Result<Vec<f64>, Error> {
    let (n, m, np) = (model.n, model.m, partials.len());
    if np == 0 {
        return Ok(Vec::new());
    }
    let mut srif = Srif::new(model, partials, true)?;
    srif.data_term = false;
    let mut out = Likelihood {
        j: 0.0,
        data_part: 0.0,
        model_part: 0.0,
        measurements: 0,
        gradient: vec![0.0; np],
        fisher_sample: vec![0.0; np * np],
        innovations: Vec::new(),
        nis: Vec::new(),
    };
    let mut e = Estimates::new(n, m, np);
    e.mean[..n].copy_from_slice(&prior.x0);
    for (i, p) in partials.iter().enumerate() {
        e.mean[n * (1 + i)..n * (2 + i)].copy_from_slice(&p.x0);
    }
    srif.set_prior(prior, partials)?;
    srif.r_mask.clear();
    let mut first = vec![0.0; np * np];
    let mut z = vec![0.0; m];
    for k in 0..data.rows() {
        if k > 0 || prior.at == PriorAt::T0 {
            srif.time_update();
            e.time_update(model, partials);
        }
        let row = &data.z[k * m..k * m + m];
        srif.avail.clear();
        srif.avail.extend((0..m).filter(|&j| !row[j].is_nan()));
        if srif.avail.is_empty() {
            continue;
        }
        for j in 0..m {
            z[j] = if row[j].is_nan() { f64::NAN } else { 0.0 };
        }
        e.prior_arrays(&srif);
        srif.measurement_update(model, partials, &z, data.t[k], k, &mut out)?;
        e.measurement(&srif, model, partials, (k, data.t[k]), &mut first)?;
    }
    Ok(first
        .iter()
        .zip(&out.fisher_sample)
        .map(|(a, b)| a + b)
        .collect())
}

/// The estimates' mean and realisations, and the buffers of a step.
struct Estimates {
    n: usize,
    m: usize,
    np: usize,
    /// N(1 + p): [x̂; ∂_1x̂; …; ∂_px̂].
    keep: usize,
    mean: Vec<f64>,
    /// Realisation rows (at most keep + N + m of `keep` values); `rows` in use.
    real: Vec<f64>,
    rows: usize,
    /// R̃ and its derivatives before the update (N × N each).
    r_prior: Vec<f64>,
    d_r_prior: Vec<f64>,
    /// R̃⁻¹, once a step.
    r_prior_inv: Vec<f64>,
    /// P̃, P̂, I − KH, K, Y = H_a R̃⁻¹, the factors of S and R, and per param ∂P̃, ∂K.
    p_prior: Vec<f64>,
    p_post: Vec<f64>,
    a: Vec<f64>,
    k: Vec<f64>,
    y: Vec<f64>,
    s_chol: Vec<f64>,
    r_chol: Vec<f64>,
    d_p: Vec<f64>,
    d_k: Vec<f64>,
    /// Work: N × N, N × m, N × max(N, m), m × m, the per-param ∂ν (np × m), a row.
    nn: Vec<f64>,
    nm: Vec<f64>,
    x: Vec<f64>,
    ds: Vec<f64>,
    d_nu: Vec<f64>,
    row: Vec<f64>,
}

impl Estimates {
    fn new(n: usize, m: usize, np: usize) -> Estimates {
        let keep = n * (1 + np);
        Estimates {
            n,
            m,
            np,
            keep,
            mean: vec![0.0; keep],
            real: vec![0.0; (keep + n + m) * keep],
            rows: 0,
            r_prior: vec![0.0; n * n],
            r_prior_inv: vec![0.0; n * n],
            d_r_prior: vec![0.0; np * n * n],
            p_prior: vec![0.0; n * n],
            p_post: vec![0.0; n * n],
            a: vec![0.0; n * n],
            k: vec![0.0; n * m],
            y: vec![0.0; m * n],
            s_chol: vec![0.0; m * m],
            r_chol: vec![0.0; m * m],
            d_p: vec![0.0; np * n * n],
            d_k: vec![0.0; np * n * m],
            nn: vec![0.0; n * n],
            nm: vec![0.0; n * m],
            x: vec![0.0; n * n.max(m)],
            ds: vec![0.0; m * m],
            d_nu: vec![0.0; np * m],
            row: vec![0.0; keep],
        }
    }

    /// x̂ ← Φx̂ + u, ∂_ix̂ ← ∂_iΦ x̂ + Φ∂_ix̂ + ∂_iu (u and ∂u for the mean only).
    fn time_update(&mut self, model: &Discrete, partials: &[Partial]) {
        let (n, keep) = (self.n, self.keep);
        for r in 0..=self.rows {
            let v = if r < self.rows {
                &mut self.real[r * keep..(r + 1) * keep]
            } else {
                &mut self.mean[..]
            };
            let is_mean = r == self.rows;
            self.row.fill(0.0);
            for (d, p) in partials.iter().enumerate() {
                let out = &mut self.row[n * (1 + d)..n * (2 + d)];
                for i in 0..n {
                    let mut s = if is_mean { p.u[i] } else { 0.0 };
                    for j in 0..n {
                        s += p.phi[i * n + j] * v[j] + model.phi[i * n + j] * v[n * (1 + d) + j];
                    }
                    out[i] = s;
                }
            }
            for i in 0..n {
                let mut s = if is_mean { model.u[i] } else { 0.0 };
                for j in 0..n {
                    s += model.phi[i * n + j] * v[j];
                }
                self.row[i] = s;
            }
            v.copy_from_slice(&self.row);
        }
    }

    /// R̃ and ∂R̃ before the SRIF's measurement update.
    fn prior_arrays(&mut self, srif: &Srif) {
        let n = self.n;
        let ic = n + 1;
        let w = ic * (1 + self.np);
        for i in 0..n {
            self.r_prior[i * n..i * n + n].copy_from_slice(&srif.info[i * w..i * w + n]);
            for d in 0..self.np {
                let off = ic * (1 + d);
                self.d_r_prior[d * n * n + i * n..d * n * n + i * n + n]
                    .copy_from_slice(&srif.info[i * w + off..i * w + off + n]);
            }
        }
    }

    /// A step's first term Σ over the mean and the realisations of ∂_iνᵀS⁻¹∂_jν into
    /// `first`, then the estimates updated with the step's fresh innovations.
    fn measurement(
        &mut self,
        srif: &Srif,
        model: &Discrete,
        partials: &[Partial],
        (k, t): (usize, f64),
        first: &mut [f64],
    ) -> Result<(), Error> {
        let (n, m, np, keep) = (self.n, self.m, self.np, self.keep);
        let avail = &srif.avail;
        let ma = avail.len();
        let ic = n + 1;
        let w = ic * (1 + np);
        let h = |r: usize, c: usize| model.h[avail[r] * n + c];
        // P̃ = R̃⁻¹R̃⁻ᵀ, and Y = H_a R̃⁻¹.
        upper_inverse(&self.r_prior, &mut self.r_prior_inv, n);
        let r_inv = &self.r_prior_inv;
        mul_abt_sym(&mut self.p_prior, r_inv, r_inv, None, n, n);
        for r in 0..ma {
            for c in 0..n {
                self.y[r * n + c] = (0..=c).map(|j| h(r, j) * r_inv[j * n + c]).sum();
            }
        }
        // S = YYᵀ + R_a and R_a, factored.
        for r in 0..ma {
            for c in 0..ma {
                let yy: f64 = (0..n).map(|j| self.y[r * n + j] * self.y[c * n + j]).sum();
                let rr = model.r[avail[r] * m + avail[c]];
                self.s_chol[r * ma + c] = yy + rr;
                self.r_chol[r * ma + c] = rr;
            }
        }
        if !cholesky(&mut self.s_chol[..ma * ma], ma) || !cholesky(&mut self.r_chol[..ma * ma], ma)
        {
            return Err(Error::Numerical {
                step: k as u64 + 1,
                t,
                path: "data".into(),
                message: "the innovation covariance of a step is singular to working precision; its expected information cannot be formed".into(),
            });
        }
        // P̂ = R̂⁻¹R̂⁻ᵀ (R̂ after the update), I − KH = P̂ R̃ᵀR̃.
        for i in 0..n {
            self.x[i * n..i * n + n].copy_from_slice(&srif.info[i * w..i * w + n]);
        }
        upper_inverse(&self.x, &mut self.nn, n);
        mul_abt_sym(&mut self.p_post, &self.nn, &self.nn, None, n, n);
        for i in 0..n {
            for j in 0..n {
                // (R̃ᵀR̃)_ij
                self.nn[i * n + j] = (0..=i.min(j))
                    .map(|q| self.r_prior[q * n + i] * self.r_prior[q * n + j])
                    .sum();
            }
        }
        mul(&mut self.a, &self.p_post, &self.nn, n, n, n);
        // K = P̃ H_aᵀ S⁻¹ (n × ma): rows solved against S.
        for i in 0..n {
            for r in 0..ma {
                self.nm[r * n + i] = (0..n).map(|j| self.p_prior[i * n + j] * h(r, j)).sum();
            }
        }
        cholesky_solve(&self.s_chol[..ma * ma], &mut self.nm[..ma * n], ma, n);
        for i in 0..n {
            for r in 0..ma {
                self.k[i * ma + r] = self.nm[r * n + i];
            }
        }
        // ∂P̃ = −X P̃ − P̃ Xᵀ, X = R̃⁻¹∂R̃; ∂S = H∂P̃Hᵀ + ∂H P̃Hᵀ + H P̃∂Hᵀ + ∂R;
        // ∂K = (∂P̃Hᵀ + P̃∂Hᵀ − K∂S) S⁻¹.
        for (d, p) in partials.iter().enumerate() {
            let dr = &self.d_r_prior[d * n * n..(d + 1) * n * n];
            let dp = &mut self.d_p[d * n * n..(d + 1) * n * n];
            // X = R̃⁻¹∂R̃ into x
            let x = &mut self.x;
            for i in 0..n {
                for j in 0..n {
                    x[i * n + j] = (0..n)
                        .map(|q| self.r_prior_inv[i * n + q] * dr[q * n + j])
                        .sum();
                }
            }
            for i in 0..n {
                for j in 0..n {
                    let xp: f64 = (0..n).map(|q| x[i * n + q] * self.p_prior[q * n + j]).sum();
                    let px: f64 = (0..n).map(|q| self.p_prior[i * n + q] * x[j * n + q]).sum();
                    dp[i * n + j] = -xp - px;
                }
            }
            // ∂S (ma × ma)
            let dh = |r: usize, c: usize| p.h[avail[r] * n + c];
            let ds = &mut self.ds;
            for r in 0..ma {
                for c in 0..ma {
                    let mut s = p.r[avail[r] * m + avail[c]];
                    for i in 0..n {
                        for j in 0..n {
                            s += h(r, i) * dp[i * n + j] * h(c, j)
                                + dh(r, i) * self.p_prior[i * n + j] * h(c, j)
                                + h(r, i) * self.p_prior[i * n + j] * dh(c, j);
                        }
                    }
                    ds[r * ma + c] = s;
                }
            }
            // (∂P̃Hᵀ + P̃∂Hᵀ − K∂S)ᵀ into x (ma × n), then S⁻¹ from the left.
            for r in 0..ma {
                for i in 0..n {
                    let mut s = 0.0;
                    for j in 0..n {
                        s += dp[i * n + j] * h(r, j) + self.p_prior[i * n + j] * dh(r, j);
                    }
                    for c in 0..ma {
                        s -= self.k[i * ma + c] * ds[c * ma + r];
                    }
                    x[r * n + i] = s;
                }
            }
            cholesky_solve(&self.s_chol[..ma * ma], &mut x[..ma * n], ma, n);
            let dk = &mut self.d_k[d * n * m..d * n * m + n * ma];
            for i in 0..n {
                for r in 0..ma {
                    dk[i * ma + r] = x[r * n + i];
                }
            }
        }
        // The first term over the mean and every realisation: w_i = L_S⁻¹∂_iν.
        for r in 0..=self.rows {
            let v = if r < self.rows {
                &self.real[r * keep..(r + 1) * keep]
            } else {
                &self.mean[..]
            };
            for (d, p) in partials.iter().enumerate() {
                let dnu = &mut self.d_nu[d * m..d * m + ma];
                for (q, &j) in avail.iter().enumerate() {
                    dnu[q] = -(0..n)
                        .map(|c| p.h[j * n + c] * v[c] + model.h[j * n + c] * v[n * (1 + d) + c])
                        .sum::<f64>();
                }
                solve_lower(&self.s_chol[..ma * ma], dnu, ma, 1);
            }
            for i in 0..np {
                for j in 0..=i {
                    let s: f64 = (0..ma)
                        .map(|q| self.d_nu[i * m + q] * self.d_nu[j * m + q])
                        .sum();
                    first[i * np + j] += s;
                    if i != j {
                        first[j * np + i] += s;
                    }
                }
            }
        }
        // The update: ν = 0 for what came before (∂x̂ ← (I − KH)∂x̂ − K∂H x̂); then
        // N + ma fresh rows with ν = Y e_j or L_R e_r (x̂ = Kν, ∂x̂ = ∂Kν).
        for r in 0..=self.rows {
            let v = if r < self.rows {
                &mut self.real[r * keep..(r + 1) * keep]
            } else {
                &mut self.mean[..]
            };
            self.row.copy_from_slice(v);
            for (d, p) in partials.iter().enumerate() {
                for i in 0..n {
                    let mut s: f64 = (0..n)
                        .map(|c| self.a[i * n + c] * self.row[n * (1 + d) + c])
                        .sum();
                    for (q, &j) in avail.iter().enumerate() {
                        let dhx: f64 = (0..n).map(|c| p.h[j * n + c] * self.row[c]).sum();
                        s -= self.k[i * ma + q] * dhx;
                    }
                    v[n * (1 + d) + i] = s;
                }
            }
        }
        let fresh = n + ma;
        for f in 0..fresh {
            let at = (self.rows + f) * keep;
            for q in 0..ma {
                // (the factor is the lower triangle only)
                self.d_nu[q] = match f.checked_sub(n) {
                    None => self.y[q * n + f],
                    Some(c) if c <= q => self.r_chol[q * ma + c],
                    Some(_) => 0.0,
                };
            }
            let nu = &self.d_nu[..ma];
            let v = &mut self.real[at..at + keep];
            for i in 0..n {
                v[i] = (0..ma).map(|q| self.k[i * ma + q] * nu[q]).sum();
                for d in 0..np {
                    let dk = &self.d_k[d * n * m..];
                    v[n * (1 + d) + i] = (0..ma).map(|q| dk[i * ma + q] * nu[q]).sum();
                }
            }
        }
        let count = self.rows + fresh;
        triangularise(&mut self.real[..count * keep], count, keep, keep);
        self.rows = count.min(keep);
        Ok(())
    }
}

/// The inverse of the upper triangular `r` (n × n) into `out`.
fn upper_inverse(r: &[f64], out: &mut [f64], n: usize) {
    out[..n * n].fill(0.0);
    for c in 0..n {
        out[c * n + c] = 1.0 / r[c * n + c];
        for i in (0..c).rev() {
            let s: f64 = (i + 1..=c).map(|q| r[i * n + q] * out[q * n + c]).sum();
            out[i * n + c] = -s / r[i * n + i];
        }
    }
}
