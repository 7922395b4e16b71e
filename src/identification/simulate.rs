//! Data simulated from a discrete model (seeded): a known truth to try an
//! identification on. The draws follow the references' order (their README): the
//! initial state x ~ N(y0, diag η0²) — at t0, then one transition (kea's convention),
//! or at t_1 — then per step k the measurement noise v_k, z_k = H x_k + Γ v_k, then the
//! process noise w_k, x_{k+1} = Φ x_k + u + G w_k. One ChaCha8 stream from the seed,
//! normal samples as the Monte Carlo draws them (rand_distr over libm: the browser's
//! bits).

use super::data::Grid;
use super::model::{Data, Discrete, Prior, PriorAt};
use crate::error::Error;
use crate::numerics::linalg::cholesky;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

/// D steps of data on `grid` from `model` and `prior` (R = Γ V Γᵀ is drawn as given:
/// `r_factor` is its square-root factor, m × m).
pub fn simulate(model: &Discrete, prior: &Prior, grid: &Grid, seed: u64) -> Result<Data, Error> {
    let (n, l, m) = (model.n, model.l, model.m);
    let q = factor(&model.q, l, "system.phi")?;
    let r = factor(&model.r, m, "measurement.psi")?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut normal = move || -> f64 { StandardNormal.sample(&mut rng) };
    let mut x: Vec<f64> = (0..n)
        .map(|i| prior.x0[i] + prior.p0[i * n + i].sqrt() * normal())
        .collect();
    let mut next = vec![0.0; n];
    let mut xi = vec![0.0; l.max(m)];
    let mut transition = |x: &mut Vec<f64>, normal: &mut dyn FnMut() -> f64| {
        for v in xi[..l].iter_mut() {
            *v = normal();
        }
        for i in 0..n {
            let mut acc = model.u[i];
            for j in 0..n {
                acc += model.phi[i * n + j] * x[j];
            }
            for a in 0..l {
                let w: f64 = (0..=a).map(|b| q[a * l + b] * xi[b]).sum();
                acc += model.g[i * l + a] * w;
            }
            next[i] = acc;
        }
        x.copy_from_slice(&next);
    };
    if prior.at == PriorAt::T0 {
        transition(&mut x, &mut normal);
    }
    let mut z = vec![0.0; grid.steps * m];
    let mut eta = vec![0.0; m];
    for k in 0..grid.steps {
        for v in eta.iter_mut() {
            *v = normal();
        }
        for j in 0..m {
            let hx: f64 = (0..n).map(|i| model.h[j * n + i] * x[i]).sum();
            let v: f64 = (0..=j).map(|b| r[j * m + b] * eta[b]).sum();
            z[k * m + j] = hx + v;
        }
        transition(&mut x, &mut normal);
    }
    Ok(Data {
        m,
        t: (1..=grid.steps).map(|k| grid.t(k)).collect(),
        z,
    })
}

/// The lower Cholesky factor of a covariance (its upper part zeroed); a covariance
/// that is not positive definite is refused at `path` (a noise with zero SKO cannot be
/// identified either: the SRIF needs Q, R > 0).
fn factor(c: &[f64], k: usize, path: &str) -> Result<Vec<f64>, Error> {
    let mut f = c.to_vec();
    if !cholesky(&mut f, k) {
        return Err(Error::invalid(
            path,
            "the covariance is not positive definite: data cannot be simulated with it (every SKO must be > 0)",
        ));
    }
    for i in 0..k {
        for j in i + 1..k {
            f[i * k + j] = 0.0;
        }
    }
    Ok(f)
}
