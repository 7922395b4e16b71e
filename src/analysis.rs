//! The analysis engine (METHOD §1.2–§1.6): Euler discretisation, the Joseph-form
//! Riccati recursion, means, the bound ("modulus") propagation, the exact-covariance
//! propagation, and the criteria accumulated on the fly. Memory does not grow with D.
//!
//! The per-step kernel is generic over a compile-time state dimension `N` (1..=12) so
//! the compiler unrolls and vectorises it; `N = 0` is the runtime-sized fallback.

use crate::decimate::Decimator;
use crate::error::Error;
use crate::linalg::{cov_rel_diff, mul, mul_abt_sym, mul_vec, predict_cov, sparse_mul_vec};
use crate::result::*;
use crate::riccati::JosephStep;
use crate::steps::select_steps;
use crate::validate::{CompiledModel, MeasurementNoise, StepPlan};
use crate::{Progress, riccati};
use std::collections::BTreeMap;
use std::ops::ControlFlow;

/// Steps between progress reports / cancellation checks.
pub const PROGRESS_EVERY: u64 = 1 << 14;
/// The shortcut freezes the Riccati recursion once r_k is this close (relative) to
/// the stationary solution r∞ of the DARE (rounding keeps a slowly contracting
/// recursion from getting much closer).
const STEADY_TOL: f64 = 1e-13;

/// Run the analysis of a compiled model.
pub fn run(model: &CompiledModel, progress: &mut dyn Progress) -> Result<AnalysisResult, Error> {
    let (steps, selection) = match model.steps {
        StepPlan::Fixed(d) => (d, None),
        StepPlan::Auto {
            tolerance,
            initial_steps,
            max_steps,
        } => {
            let s = select_steps(model, tolerance, initial_steps, max_steps, progress)?;
            (s.chosen, Some(s.selection))
        }
    };
    let mut result = match model.n_states() {
        1 => Engine::<1>::new(model, steps).run(progress),
        2 => Engine::<2>::new(model, steps).run(progress),
        3 => Engine::<3>::new(model, steps).run(progress),
        4 => Engine::<4>::new(model, steps).run(progress),
        5 => Engine::<5>::new(model, steps).run(progress),
        6 => Engine::<6>::new(model, steps).run(progress),
        7 => Engine::<7>::new(model, steps).run(progress),
        8 => Engine::<8>::new(model, steps).run(progress),
        9 => Engine::<9>::new(model, steps).run(progress),
        10 => Engine::<10>::new(model, steps).run(progress),
        11 => Engine::<11>::new(model, steps).run(progress),
        12 => Engine::<12>::new(model, steps).run(progress),
        _ => Engine::<0>::new(model, steps).run(progress),
    }?;
    result.step_selection = selection;
    Ok(result)
}

/// Running sums of one criterion of one state (3.24).
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Avg {
    pub(crate) sum: f64,
    pub(crate) count: u64,
    pub(crate) excluded: u64,
}

impl Avg {
    #[inline(always)]
    pub(crate) fn add(&mut self, num: f64, den: f64) {
        let f = num / den;
        if den > 0.0 && f.is_finite() {
            self.sum += f;
            self.count += 1;
        } else {
            self.excluded += 1;
        }
    }
    pub(crate) fn mean(&self) -> Option<f64> {
        (self.count > 0).then(|| self.sum / self.count as f64)
    }
}

/// Accumulated criteria of one set (bound or covariance): ratios η/ζ, ζ/χ, η/χ per
/// state; the constant factors z_B/y_B are applied at the end (y_B is a sup over k).
#[derive(Clone, Debug)]
pub(crate) struct SetSums {
    pub(crate) yz: Vec<Avg>,
    pub(crate) zx: Vec<Avg>,
    pub(crate) yx: Vec<Avg>,
}

impl SetSums {
    fn new(n: usize) -> Self {
        SetSums {
            yz: vec![Avg::default(); n],
            zx: vec![Avg::default(); n],
            yx: vec![Avg::default(); n],
        }
    }
}

/// Series kept in the traces, per state (in this order).
const SERIES: usize = 10;
const S_Y: usize = 0;
const S_ETA: usize = 1;
const S_ZETA: usize = 2;
const S_CHI: usize = 3;
const S_POT: usize = 4;
const S_OPEN: usize = 5;
const S_MEAS: usize = 6;
const S_RYZ: usize = 7;
const S_RZX: usize = 8;
const S_RYX: usize = 9;

struct Engine<'m, const N: usize> {
    m: &'m CompiledModel,
    steps: u64,
    /// N and n (measurements), L, M.
    nn: usize,
    nm: usize,
    nl: usize,
    ms: usize,
    dt: f64,
}

impl<'m, const N: usize> Engine<'m, N> {
    fn new(m: &'m CompiledModel, steps: u64) -> Self {
        let nn = if N == 0 { m.n_states() } else { N };
        debug_assert_eq!(nn, m.n_states());
        Engine {
            m,
            steps,
            nn,
            nm: m.n_measurements(),
            nl: m.b.cols,
            ms: m.noise.sources(),
            dt: (m.t_end - m.t0) / steps as f64,
        }
    }

    #[inline(always)]
    fn n(&self) -> usize {
        if N == 0 { self.nn } else { N }
    }

    fn run(&self, progress: &mut dyn Progress) -> Result<AnalysisResult, Error> {
        let n = self.n();
        let (nm, nl, ms, dt) = (self.nm, self.nl, self.ms, self.dt);
        let m = self.m;
        let t0 = m.t0;
        let mut a_fn = m.a.clone();
        let mut u_fn = m.u.clone();
        let mut b_fn = m.b.clone();
        let mut noise_fn = m.noise.clone();

        // C as its non-zero entries (row, col, value): selection matrices cost O(n).
        let c_nz: Vec<(usize, usize, f64)> = (0..nm)
            .flat_map(|j| (0..n).map(move |i| (j, i)))
            .filter_map(|(j, i)| {
                let v = m.c[j * n + i];
                (v != 0.0).then_some((j, i, v))
            })
            .collect();

        // --- per-step inputs (recomputed only if time-varying)
        // A = I + aΔt (1.11), dense, only for the stationary solution of invariant models
        let mut big_a = if m.a.is_constant() {
            vec![0.0; n * n]
        } else {
            Vec::new()
        };
        let mut bd = vec![0.0; n * nl]; // b Δt
        let mut bw = vec![0.0; n * nl]; // (b Δt) W
        let mut big_b = vec![0.0; n * n]; // B = bΔt W (bΔt)ᵀ (1.15)
        let mut b_phi = vec![0.0; n]; // |bΔt| φ (3.16)
        let mut gamma = vec![0.0; nm * ms]; // Γ_k
        let mut gv = vec![0.0; nm * ms];
        let mut rv = vec![0.0; nm * nm]; // Rv = Γ V Γᵀ
        let mut zeta = vec![0.0; nm]; // ζ = |Γ| ψ (3.17)
        let mut meas_sko = vec![0.0; nm]; // sqrt(diag Rv)
        let mut u_dt = vec![0.0; n];

        // The structure of a: entries that vary or are non-zero; A = I + E, E = aΔt.
        let a_pattern: Vec<(usize, usize)> = (0..n)
            .flat_map(|i| (0..n).map(move |j| (i, j)))
            .filter(|&(i, j)| m.a.values[i * n + j] != 0.0 || m.a.varies(i * n + j))
            .collect();
        // |A| keeps the diagonal even where a_ii = 0 (A_ii = 1).
        let abs_pattern: Vec<(usize, usize)> = (0..n)
            .flat_map(|i| (0..n).map(move |j| (i, j)))
            .filter(|&(i, j)| i == j || m.a.values[i * n + j] != 0.0 || m.a.varies(i * n + j))
            .collect();
        let mut e_nz: Vec<(usize, usize, f64)> =
            a_pattern.iter().map(|&(i, j)| (i, j, 0.0)).collect();
        let mut abs_nz: Vec<(usize, usize, f64)> =
            abs_pattern.iter().map(|&(i, j)| (i, j, 0.0)).collect();
        let update_a = |a_fn: &crate::expr::TimeMatrix,
                        big_a: &mut [f64],
                        e_nz: &mut [(usize, usize, f64)],
                        abs_nz: &mut [(usize, usize, f64)]| {
            for e in e_nz.iter_mut() {
                e.2 = a_fn.values[e.0 * n + e.1] * dt;
            }
            for e in abs_nz.iter_mut() {
                let v = a_fn.values[e.0 * n + e.1] * dt + if e.0 == e.1 { 1.0 } else { 0.0 };
                e.2 = v.abs();
            }
            if !big_a.is_empty() {
                for i in 0..n {
                    for j in 0..n {
                        big_a[i * n + j] =
                            a_fn.values[i * n + j] * dt + if i == j { 1.0 } else { 0.0 };
                    }
                }
            }
        };
        let w = &m.w;
        let update_b = |b_fn: &crate::expr::TimeMatrix,
                        bd: &mut [f64],
                        bw: &mut [f64],
                        big_b: &mut [f64],
                        b_phi: &mut [f64]| {
            for (d, s) in bd.iter_mut().zip(&b_fn.values) {
                *d = s * dt;
            }
            mul(bw, bd, w, n, nl, nl);
            mul_abt_sym(big_b, bw, bd, None, n, nl);
            for i in 0..n {
                b_phi[i] = (0..nl).map(|l| bd[i * nl + l].abs() * m.phi[l]).sum();
            }
        };
        let v = &m.v;
        let update_gamma = |noise_fn: &MeasurementNoise,
                            gamma: &mut [f64],
                            gv: &mut [f64],
                            rv: &mut [f64],
                            zeta: &mut [f64],
                            meas_sko: &mut [f64]| {
            match noise_fn {
                MeasurementNoise::Gamma(g) => gamma.copy_from_slice(&g.values),
                // Γ = C g (the seed's form Z = c (y + gΦ))
                MeasurementNoise::SeedG(g) => mul(gamma, &m.c, &g.values, nm, n, ms),
            }
            mul(gv, gamma, v, nm, ms, ms);
            mul_abt_sym(rv, gv, gamma, None, nm, ms);
            for j in 0..nm {
                zeta[j] = (0..ms).map(|l| gamma[j * ms + l].abs() * m.psi[l]).sum();
                meas_sko[j] = rv[j * nm + j].max(0.0).sqrt();
            }
        };
        let time_err = |path: &str, k: u64, t: f64| Error::Numerical {
            step: k,
            t,
            path: path.to_string(),
            message: "the expression is not finite here".to_string(),
        };

        // Constant inputs once.
        a_fn.update(t0).map_err(|p| time_err(p, 0, t0))?;
        b_fn.update(t0).map_err(|p| time_err(p, 0, t0))?;
        update_a(&a_fn, &mut big_a, &mut e_nz, &mut abs_nz);
        update_b(&b_fn, &mut bd, &mut bw, &mut big_b, &mut b_phi);
        let t1 = t0 + dt;
        update_noise(&mut noise_fn, t1).map_err(|p| time_err(&p, 1, t1))?;
        update_gamma(
            &noise_fn,
            &mut gamma,
            &mut gv,
            &mut rv,
            &mut zeta,
            &mut meas_sko,
        );
        let a_const = a_fn.is_constant();
        let b_const = b_fn.is_constant();
        let g_const = noise_fn.matrix().is_constant();
        let u_const = u_fn.is_constant();
        u_fn.update(t0).map_err(|p| time_err(p, 0, t0))?;
        for i in 0..n {
            u_dt[i] = u_fn.values[i] * dt;
        }
        let invariant = a_const && b_const && g_const;

        // The stationary predicted covariance r∞ (doubling), for the shortcut.
        let r_inf = if invariant {
            riccati::dare_doubling(&big_a, &c_nz, &big_b, &rv, n, nm)
        } else {
            None
        };
        let mut warnings = Vec::new();
        if invariant && r_inf.is_none() {
            warnings.push(
                "the stationary Riccati solution could not be computed (no stabilising solution?): the full recursion was run and no steady state is reported".to_string(),
            );
        }

        // --- state
        let mut y = m.y0.clone();
        let mut y_next = vec![0.0; n];
        let mut ydot = vec![0.0; n];
        let mut y_max: Vec<f64> = y.iter().map(|v| v.abs()).collect();
        let mut ydot_max = vec![0.0f64; n];
        let mut big_r = vec![0.0; n * n]; // R_k
        for i in 0..n {
            big_r[i * n + i] = m.eta0[i] * m.eta0[i];
        }
        let mut p_y = big_r.clone(); // open-loop covariance P^Y
        let mut eta = m.eta0.clone();
        let mut chi = vec![0.0; n]; // χ(t0) = 0 (3.18)
        let mut xi = vec![0.0; n];
        let mut tmp_nn = vec![0.0; n * n];
        let mut tmp_p = vec![0.0; n * n];
        let mut joseph = JosephStep::new(n, nm);
        let mut schedule = m.schedule.clone();
        let mut avail = vec![true; nm];
        let mut c_nz_k: Vec<(usize, usize, f64)> = Vec::with_capacity(c_nz.len());
        let mut rv_k = vec![0.0; nm * nm];
        let mut gain_k = vec![0.0; n * nm];
        let mut abs_h = vec![0.0; n * n]; // |I − pC|
        let mut abs_p = vec![0.0; n * nm];
        let mut tmp_n = vec![0.0; n];

        let mut bound = SetSums::new(n);
        let mut cov = SetSums::new(n);
        let pair = &m.pair_of_state;
        let mut dec = Decimator::new(self.steps, n * SERIES, m.trace_points);

        let mut frozen_at: Option<u64> = None;
        // The bound (|A| element-wise) or the open-loop covariance can overflow while
        // the filter itself is fine; the affected criteria then become null.
        let mut bound_diverged: Option<(u64, f64)> = None;
        let mut open_diverged: Option<(u64, f64)> = None;
        let mut steady_at: Option<u64> = None;
        let mut steady_cov: Option<(Vec<f64>, Vec<f64>)> = None;

        for k in 1..=self.steps {
            let t_prev = t0 + (k - 1) as f64 * dt;
            let t_k = t0 + k as f64 * dt;

            // (1.11)–(1.15) inputs at t_{k−1}; Γ at t_k.
            if !a_const && k > 1 {
                a_fn.update(t_prev).map_err(|p| time_err(p, k, t_prev))?;
                update_a(&a_fn, &mut big_a, &mut e_nz, &mut abs_nz);
            }
            if !b_const && k > 1 {
                b_fn.update(t_prev).map_err(|p| time_err(p, k, t_prev))?;
                update_b(&b_fn, &mut bd, &mut bw, &mut big_b, &mut b_phi);
            }
            if !u_const && k > 1 {
                u_fn.update(t_prev).map_err(|p| time_err(p, k, t_prev))?;
                for i in 0..n {
                    u_dt[i] = u_fn.values[i] * dt;
                }
            }
            if !g_const && k > 1 {
                update_noise(&mut noise_fn, t_k).map_err(|p| time_err(&p, k, t_k))?;
                update_gamma(
                    &noise_fn,
                    &mut gamma,
                    &mut gv,
                    &mut rv,
                    &mut zeta,
                    &mut meas_sko,
                );
            }

            // ẏ(t_{k−1}) = a y + u (1.4); y_k = A y_{k−1} + uΔt (3.3)
            mul_vec(&mut ydot, &a_fn.values, &y, n, n);
            sparse_mul_vec(&mut y_next, &e_nz, &y, n);
            for i in 0..n {
                let d = (ydot[i] + u_fn.values[i]).abs();
                if d > ydot_max[i] {
                    ydot_max[i] = d;
                }
                y[i] += y_next[i] + u_dt[i];
                let ya = y[i].abs();
                if ya > y_max[i] {
                    y_max[i] = ya;
                }
            }
            if !y[0].is_finite() || y.iter().any(|v| !v.is_finite()) {
                return Err(Error::Numerical {
                    step: k,
                    t: t_k,
                    path: "system.a".into(),
                    message: "the mean state overflowed: the model diverges faster than f64 can follow on this interval".into(),
                });
            }

            if frozen_at.is_none() {
                // Measurements available at this step (all, unless scheduled).
                let all = match schedule.as_mut() {
                    None => true,
                    Some(sc) => sc
                        .mask(k, t_k, &mut avail)
                        .map_err(|p| time_err(&p, k, t_k))?,
                };
                let ok = if all {
                    joseph.step(n, &mut big_r, &e_nz, &big_b, &c_nz, &rv, nm)
                } else {
                    // Compact C and Rv to the available rows.
                    let mut idx = Vec::with_capacity(nm);
                    for (j, a) in avail.iter().enumerate() {
                        if *a {
                            idx.push(j);
                        }
                    }
                    let nk = idx.len();
                    c_nz_k.clear();
                    for &(j, i, c) in &c_nz {
                        if let Some(jj) = idx.iter().position(|x| *x == j) {
                            c_nz_k.push((jj, i, c));
                        }
                    }
                    for (a, &ja) in idx.iter().enumerate() {
                        for (b, &jb) in idx.iter().enumerate() {
                            rv_k[a * nk + b] = rv[ja * nm + jb];
                        }
                    }
                    let ok = joseph.step(n, &mut big_r, &e_nz, &big_b, &c_nz_k, &rv_k, nk);
                    gain_k[..n * nk].copy_from_slice(&joseph.gain[..n * nk]);
                    joseph.gain[..n * nm].fill(0.0);
                    for i in 0..n {
                        for (a, &j) in idx.iter().enumerate() {
                            joseph.gain[i * nm + j] = gain_k[i * nk + a];
                        }
                    }
                    ok
                };
                if !ok {
                    return Err(Error::Numerical {
                        step: k,
                        t: t_k,
                        path: "measurement".into(),
                        message: "the innovation covariance q = C r Cᵀ + Γ V Γᵀ is singular (not positive definite): a measurement has no error and its direction of the state is already known exactly; give non-zero psi/V or eta0".into(),
                    });
                }
                // |I − pC| and |p| for the bound (3.19)
                for (h, x) in abs_h.iter_mut().zip(&joseph.h) {
                    *h = x.abs();
                }
                for (ap, g) in abs_p.iter_mut().zip(&joseph.gain[..n * nm]) {
                    *ap = g.abs();
                }
                for i in 0..n {
                    let d = big_r[i * n + i];
                    if !d.is_finite() {
                        return Err(Error::Numerical {
                            step: k,
                            t: t_k,
                            path: "system".into(),
                            message: "the filtered covariance overflowed: the model diverges faster than f64 can follow on this interval".into(),
                        });
                    }
                }
                // Steady state: r_k within STEADY_TOL of r∞ (then R, p are stationary too).
                if let Some(r_inf) = &r_inf {
                    if steady_at.is_none()
                        && diag_close(&joseph.r_pred, r_inf, n, STEADY_TOL)
                        && cov_rel_diff(&joseph.r_pred, r_inf, n) <= STEADY_TOL
                    {
                        steady_at = Some(k);
                        steady_cov = Some((big_r.clone(), joseph.gain[..n * nm].to_vec()));
                        if m.steady_state_shortcut {
                            frozen_at = Some(k);
                        }
                    }
                }
            }

            // Open-loop covariance P^Y = A P Aᵀ + B (§1.5, exact second moments)
            if open_diverged.is_none() {
                tmp_p.copy_from_slice(&p_y);
                predict_cov(&mut p_y, &tmp_p, &e_nz, &big_b, &mut tmp_nn, n);
                if !(0..n).all(|i| p_y[i * n + i].is_finite()) {
                    open_diverged = Some((k, t_k));
                }
            }

            // Bound propagation (3.16)–(3.19)
            if bound_diverged.is_none() {
                sparse_mul_vec(&mut tmp_n, &abs_nz, &eta, n);
                for i in 0..n {
                    eta[i] = tmp_n[i] + b_phi[i];
                }
                sparse_mul_vec(&mut xi, &abs_nz, &chi, n);
                mul_vec(&mut chi, &abs_h, &xi, n, n);
                for i in 0..n {
                    let mut s = 0.0;
                    for j in 0..nm {
                        s += abs_p[i * nm + j] * zeta[j];
                    }
                    chi[i] += s;
                }
                if !eta.iter().chain(chi.iter()).all(|v| v.is_finite()) {
                    bound_diverged = Some((k, t_k));
                }
            }
            let bound_ok = bound_diverged.is_none();
            let open_ok = open_diverged.is_none();

            // Criteria (3.23)–(3.24) as ratios; traces.
            dec.begin(t_k);
            for i in 0..n {
                let pot = big_r[i * n + i].max(0.0).sqrt();
                let open = p_y[i * n + i].max(0.0).sqrt();
                let base = i * SERIES;
                dec.put(base + S_Y, k, y[i]);
                dec.put(base + S_POT, k, pot);
                if bound_ok {
                    bound.yx[i].add(eta[i], chi[i]);
                    dec.put(base + S_ETA, k, eta[i]);
                    dec.put(base + S_CHI, k, chi[i]);
                    if chi[i] > 0.0 {
                        dec.put(base + S_RYX, k, eta[i] / chi[i]);
                    }
                }
                if open_ok {
                    cov.yx[i].add(open, pot);
                    dec.put(base + S_OPEN, k, open);
                }
                if let Some(j) = pair[i] {
                    if !avail[j] {
                        // No measured information at this step: excluded from YZ/ZX.
                        bound.yz[i].excluded += 1;
                        bound.zx[i].excluded += 1;
                        cov.yz[i].excluded += 1;
                        cov.zx[i].excluded += 1;
                        continue;
                    }
                    let (zb, zc) = (zeta[j], meas_sko[j]);
                    dec.put(base + S_ZETA, k, zb);
                    dec.put(base + S_MEAS, k, zc);
                    cov.zx[i].add(zc, pot);
                    if bound_ok {
                        bound.yz[i].add(eta[i], zb);
                        bound.zx[i].add(zb, chi[i]);
                        if zb > 0.0 {
                            dec.put(base + S_RYZ, k, eta[i] / zb);
                        }
                        if chi[i] > 0.0 {
                            dec.put(base + S_RZX, k, zb / chi[i]);
                        }
                    }
                    if open_ok {
                        cov.yz[i].add(open, zc);
                    }
                }
            }
            dec.end(k);

            if k % PROGRESS_EVERY == 0
                && let ControlFlow::Break(()) = progress.report(k as f64 / self.steps as f64)
            {
                return Err(Error::Cancelled);
            }
        }
        let _ = progress.report(1.0);

        // --- assemble (3.20)–(3.26)
        let z_max: Vec<f64> = (0..nm)
            .map(|j| (0..n).map(|i| m.c[j * n + i].abs() * y_max[i]).sum())
            .collect();
        let lambda = laplace_lambda(m.confidence);
        let bound_why = bound_diverged.map(|(k, t)| format!(
            "the bound (modulus procedure) overflowed at step {k} (t = {t}): |A| taken element-wise grows where A does not (oscillatory or feedback dynamics), so the bound is not informative here; see the covariance set"
        ));
        let open_why = open_diverged.map(|(k, t)| {
            format!("the open-loop (a-priori) covariance overflowed at step {k} (t = {t})")
        });
        if let Some(w) = &bound_why {
            warnings.push(w.clone());
        }
        if let Some(w) = &open_why {
            warnings.push(w.clone());
        }
        let bound_set = criteria_set(
            m,
            &bound,
            &y_max,
            &z_max,
            "bound",
            [
                bound_why.as_deref(),
                bound_why.as_deref(),
                bound_why.as_deref(),
            ],
        );
        let cov_set = criteria_set(
            m,
            &cov,
            &y_max,
            &z_max,
            "covariance",
            [open_why.as_deref(), None, open_why.as_deref()],
        );
        let traces = build_traces(m, dec, &y_max, &z_max);
        let to_rows = |v: &[f64], cols: usize| -> Vec<Vec<f64>> {
            v.chunks_exact(cols.max(1)).map(|r| r.to_vec()).collect()
        };
        let pairs = (0..n)
            .filter_map(|i| {
                pair[i].map(|j| PairOut {
                    state: m.states[i].clone(),
                    measurement: m.measurements[j].clone(),
                })
            })
            .collect();
        let zeta_state: Vec<f64> = zeta.clone();
        let final_ = Final {
            covariance: to_rows(&big_r, n),
            gain: to_rows(&joseph.gain[..n * nm], nm),
            predicted_covariance: to_rows(&joseph.r_pred, n),
            eta: eta.clone(),
            zeta: zeta_state.clone(),
            chi: chi.clone(),
            potential_sko: (0..n).map(|i| big_r[i * n + i].max(0.0).sqrt()).collect(),
            open_loop_sko: (0..n).map(|i| p_y[i * n + i].max(0.0).sqrt()).collect(),
            measured_sko: meas_sko.clone(),
            delta_y: eta.iter().map(|x| lambda * x).collect(),
            delta_z: zeta_state.iter().map(|x| lambda * x).collect(),
            delta_x: chi.iter().map(|x| lambda * x).collect(),
        };
        let steady_state = steady_at.map(|k| {
            let (r, g) = steady_cov.clone().unwrap_or_default();
            SteadyState {
                reached_at_step: k,
                t: t0 + k as f64 * dt,
                covariance: to_rows(&r, n),
                gain: to_rows(&g, nm),
                shortcut_used: frozen_at.is_some(),
            }
        });
        if !invariant && m.steady_state_shortcut {
            // Nothing to say: the shortcut applies to time-invariant models only.
        }
        Ok(AnalysisResult {
            steps: self.steps,
            dt,
            t0,
            t_end: m.t_end,
            step_selection: None,
            states: m.states.clone(),
            measurements: m.measurements.clone(),
            pairs,
            y_max,
            ydot_max,
            z_max,
            confidence: m.confidence,
            lambda,
            criteria: CriteriaSets {
                bound: bound_set,
                covariance: cov_set,
                monte_carlo: None,
            },
            final_,
            steady_state,
            traces,
            timing: Timing::default(),
            warnings,
        })
    }
}

/// The cheap first test of the steady state: every diagonal entry within `tol`.
#[inline(always)]
fn diag_close(a: &[f64], b: &[f64], n: usize, tol: f64) -> bool {
    (0..n).all(|i| (a[i * n + i] - b[i * n + i]).abs() <= tol * b[i * n + i].abs())
}

fn update_noise(noise: &mut MeasurementNoise, t: f64) -> Result<(), String> {
    match noise {
        MeasurementNoise::Gamma(g) | MeasurementNoise::SeedG(g) => {
            g.update(t).map_err(|p| p.to_string())
        }
    }
}

/// λ = Φ⁻¹((1+P)/2), the two-sided normal quantile (3.14).
pub fn laplace_lambda(p: f64) -> f64 {
    use statrs::distribution::{ContinuousCDF, Normal};
    Normal::standard().inverse_cdf((1.0 + p) / 2.0)
}

/// Averaged (3.24) and weighted (3.25) criteria of one set from its running sums;
/// `invalid[c]` nulls criterion c (yz, zx, yx) for every state with that reason.
pub(crate) fn criteria_set(
    m: &CompiledModel,
    s: &SetSums,
    y_max: &[f64],
    z_max: &[f64],
    set: &str,
    invalid: [Option<&str>; 3],
) -> CriteriaSet {
    let n = m.n_states();
    let mut per_state = Vec::with_capacity(n);
    for i in 0..n {
        let mut undefined = BTreeMap::new();
        let pair = m.pair_of_state[i];
        let yb = y_max[i];
        let mut finish = |name: &str,
                          avg: &Avg,
                          factor: Option<f64>,
                          paired: bool|
         -> Option<f64> {
            if !paired {
                undefined.insert(
                    name.to_string(),
                    format!("state \"{}\" has no paired measurement", m.states[i]),
                );
                return None;
            }
            if yb == 0.0 {
                undefined.insert(
                    name.to_string(),
                    format!("y_B = 0: the mean of \"{}\" is identically zero, so relative errors (3.20) are undefined", m.states[i]),
                );
                return None;
            }
            let Some(factor) = factor else {
                undefined.insert(
                    name.to_string(),
                    "z_B = 0: the mean measurement is identically zero".to_string(),
                );
                return None;
            };
            match avg.mean() {
                Some(v) => Some(v * factor),
                None => {
                    undefined.insert(
                        name.to_string(),
                        format!("every step has a zero denominator in the {set} set"),
                    );
                    None
                }
            }
        };
        // f^YZ = (η/y_B)/(ζ/z_B) = (η/ζ)(z_B/y_B); f^ZX = (ζ/χ)(y_B/z_B); f^YX = η/χ.
        let zb = pair.map(|j| z_max[j]);
        let f_yz = zb.filter(|z| *z > 0.0).map(|z| z / yb);
        let f_zx = zb.filter(|z| *z > 0.0).map(|z| yb / z);
        let mut yz = finish("yz", &s.yz[i], f_yz, pair.is_some());
        let mut zx = finish("zx", &s.zx[i], f_zx, pair.is_some());
        let mut yx = finish("yx", &s.yx[i], Some(1.0), true);
        for ((name, v), why) in [("yz", &mut yz), ("zx", &mut zx), ("yx", &mut yx)]
            .into_iter()
            .zip(invalid)
        {
            if let Some(why) = why {
                *v = None;
                undefined.insert(name.to_string(), why.to_string());
            }
        }
        per_state.push(StateCriteria {
            state: m.states[i].clone(),
            measurement: pair.map(|j| m.measurements[j].clone()),
            yz,
            zx,
            yx,
            undefined,
            excluded_steps: ExcludedSteps {
                yz: s.yz[i].excluded,
                zx: s.zx[i].excluded,
                yx: s.yx[i].excluded,
            },
        });
    }
    let mut undefined = BTreeMap::new();
    let mut weighted = |name: &str, given: Option<&Vec<f64>>, values: Vec<Option<f64>>| {
        let (w, v) = weighted_sum(given, &values);
        match v {
            Ok(v) => (w, Some(v)),
            Err(why) => {
                let why = why.replace("{state}", "");
                let named = why
                    .split_once('#')
                    .map(|(a, i)| format!("{a}\"{}\"", m.states[i.parse::<usize>().unwrap_or(0)]))
                    .unwrap_or(why);
                undefined.insert(name.to_string(), named);
                (w, None)
            }
        }
    };
    let (w_yz, yz) = weighted(
        "yz",
        m.weights_yz.as_ref(),
        per_state.iter().map(|p| p.yz).collect(),
    );
    let (w_zx, zx) = weighted(
        "zx",
        m.weights_zx.as_ref(),
        per_state.iter().map(|p| p.zx).collect(),
    );
    let (w_yx, yx) = weighted(
        "yx",
        m.weights_yx.as_ref(),
        per_state.iter().map(|p| p.yx).collect(),
    );
    CriteriaSet {
        per_state,
        weighted: Weighted {
            yz,
            zx,
            yx,
            weights: WeightsOut {
                yz: w_yz,
                zx: w_zx,
                yx: w_yx,
            },
            undefined,
        },
    }
}

/// (3.25): F = Σ k_i f_i. Default weights: equal over the states where f_i is defined.
/// Err names (as `#i`) a state with positive weight whose criterion is undefined.
fn weighted_sum(
    given: Option<&Vec<f64>>,
    values: &[Option<f64>],
) -> (Vec<f64>, Result<f64, String>) {
    let n = values.len();
    match given {
        Some(w) => {
            for i in 0..n {
                if w[i] > 0.0 && values[i].is_none() {
                    return (
                        w.clone(),
                        Err(format!(
                            "the criterion is undefined for weighted state #{i}"
                        )),
                    );
                }
            }
            let v = (0..n).map(|i| w[i] * values[i].unwrap_or(0.0)).sum();
            (w.clone(), Ok(v))
        }
        None => {
            let defined = values.iter().filter(|v| v.is_some()).count();
            if defined == 0 {
                return (
                    vec![0.0; n],
                    Err("the criterion is undefined for every state".to_string()),
                );
            }
            let k = 1.0 / defined as f64;
            let w: Vec<f64> = values
                .iter()
                .map(|v| if v.is_some() { k } else { 0.0 })
                .collect();
            let v = values.iter().flatten().map(|x| k * x).sum();
            (w, Ok(v))
        }
    }
}

fn build_traces(m: &CompiledModel, dec: Decimator, y_max: &[f64], z_max: &[f64]) -> Traces {
    let n = m.n_states();
    let bucket_steps = dec.bucket_steps();
    let Decimator { t, mut columns, .. } = dec;
    let mut take = |i: usize, s: usize| std::mem::take(&mut columns[i * SERIES + s]);
    let plain = |v: Vec<Option<f64>>| {
        v.into_iter()
            .map(|x| x.unwrap_or(0.0))
            .collect::<Vec<f64>>()
    };
    let scale = |v: &[f64], by: f64| v.iter().map(|x| x / by).collect::<Vec<f64>>();
    let scale_opt = |v: Vec<Option<f64>>, f: Option<f64>| -> Vec<Option<f64>> {
        v.into_iter()
            .map(|x| match (x, f) {
                (Some(x), Some(f)) if (x * f).is_finite() => Some(x * f),
                _ => None,
            })
            .collect()
    };
    let mut states = Vec::with_capacity(n);
    for i in 0..n {
        let yb = y_max[i];
        let pair = m.pair_of_state[i];
        let zb = pair.map(|j| z_max[j]);
        let y = plain(take(i, S_Y));
        let eta = plain(take(i, S_ETA));
        let chi = plain(take(i, S_CHI));
        let zeta = pair.map(|_| plain(take(i, S_ZETA)));
        let measured = pair.map(|_| plain(take(i, S_MEAS)));
        let yb_ok = (yb > 0.0).then_some(yb);
        let zb_ok = zb.filter(|z| *z > 0.0);
        let rel = |v: &[f64], b: Option<f64>| match b {
            Some(b) => scale(v, b),
            None => vec![0.0; v.len()],
        };
        let local_yz =
            pair.map(|_| scale_opt(take(i, S_RYZ), zb_ok.zip(yb_ok).map(|(z, y)| z / y)));
        let local_zx =
            pair.map(|_| scale_opt(take(i, S_RZX), zb_ok.zip(yb_ok).map(|(z, y)| y / z)));
        let local_yx = scale_opt(take(i, S_RYX), yb_ok.map(|_| 1.0));
        states.push(StateTrace {
            state: m.states[i].clone(),
            rel_y: rel(&eta, yb_ok),
            rel_x: rel(&chi, yb_ok),
            rel_z: zeta.as_ref().map(|z| rel(z, zb_ok)),
            y,
            eta,
            zeta,
            chi,
            potential_sko: plain(take(i, S_POT)),
            open_loop_sko: plain(take(i, S_OPEN)),
            measured_sko: measured,
            local_yz,
            local_zx,
            local_yx,
        });
    }
    Traces {
        bucket_steps,
        t,
        states,
    }
}
