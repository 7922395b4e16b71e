//! The budget's step loop: the filter's own step ([`SequentialJoseph`]) for the gains,
//! then every source's recursion with them.
//!
//! ```text
//! M_k = h_k A_{k−1}                                  once a step (h + h E: O(nnz(E)·N))
//! R^s_k = M_k R^s_{k−1} M_kᵀ + h_k B^s hᵀ + p_k Rv^s p_kᵀ     (2.1), (2.7) per source
//! P^s_k = A P^s_{k−1} Aᵀ + B^s                          (§1.5) per source
//! ```
//!
//! h(A R Aᵀ + B)hᵀ = (hA) R (hA)ᵀ + h B hᵀ; B^s and Rv^s have the rank of their group,
//! so h B^s hᵀ = X W_GG Xᵀ with X = h bΔt_G, and p Rv^s pᵀ = X V_GG Xᵀ with X = p Γ_G.
//! M R Mᵀ is two products of whole rows (2N³ multiply-adds, vectorised), `N` a
//! compile-time constant where the analysis has one (1..=12, else 0: runtime-sized).

use super::{Level, Part};
use crate::analysis::Checkpoints;
use crate::analysis::gains::{Available, Filter};
use crate::analysis::inputs::Inputs;
use crate::error::Error;
use crate::model::compile::CompiledModel;
use crate::numerics::lanes::Lanes;
use crate::numerics::linalg::{mat, mat_mut, mirror, predict_in_place, predict_work};
use crate::progress::Progress;

/// Runs the parts' recursions over `steps` steps (see [`super::run`]); inlined into
/// its build's caller, so that it is compiled with that build's features.
#[inline(always)]
pub(super) fn run<const N: usize, L: Lanes>(
    m: &CompiledModel,
    steps: u64,
    frozen_at: Option<u64>,
    parts: &mut [Part],
    progress: &mut dyn Progress,
) -> Result<(), Error> {
    let n = if N > 0 { N } else { m.n_states() };
    let nm = m.n_measurements();
    let dt = (m.t_end - m.t0) / steps as f64;
    let (nl, ms) = (m.b.cols, m.noise.sources());
    let mut inp = Inputs::new(m, n, dt);
    let mut filter = Filter::new(m);
    let mut avail = Available::new(m);
    // Mᵀ, M R, a source's X W Xᵀ (or X V Xᵀ), its X and X S; the prediction's buffer.
    let mut mt = vec![0.0; n * n];
    let mut t = vec![0.0; n * n];
    let mut q = vec![0.0; n * n];
    let width = nl.max(ms);
    let mut x = vec![0.0; n * width];
    let mut xs = vec![0.0; n * width];
    let mut u = predict_work(n);
    let mut checkpoints = Checkpoints::new(super::step_units(n, nm, parts.len()));

    for k in 1..=steps {
        let t_k = m.t0 + k as f64 * dt;
        inp.at(m, k, k == 1).map_err(crate::request::locate)?;
        if frozen_at.is_none_or(|f| k <= f) {
            avail.at(k, t_k)?;
            if !filter.step::<N, L>(m, &inp, &avail) {
                return Err(super::lost(k, t_k));
            }
        }
        let joseph = &filter.joseph;
        // Mᵀ = Aᵀ hᵀ = hᵀ + Eᵀ hᵀ: row c of Mᵀ gains E_bc · row b of hᵀ.
        let ht = &joseph.ht;
        mt.copy_from_slice(ht);
        for &(b, c, v) in inp.e.nonzeros() {
            let (hb, mc) = (&ht[b * n..b * n + n], &mut mt[c * n..c * n + n]);
            for j in 0..n {
                mc[j] += v * hb[j];
            }
        }
        if k == 1 || !inp.b_fn.is_constant() {
            for part in parts.iter_mut() {
                if let Level::Model(g) = &part.level {
                    // B^s = bΔt_G W_GG bΔt_Gᵀ (1.15), for the open loop.
                    gather(&mut x, &inp.bd, nl, g, n);
                    add_xsxt(&mut part.big_b, &x, &mut xs, &m.w, nl, g, n, true);
                }
            }
        }
        for part in parts.iter_mut() {
            q.fill(0.0);
            match &part.level {
                Level::Initial(_) => {}
                Level::Model(g) => {
                    // X = h bΔt_G: X_ix = Σ_b h_ib bΔt_b,G_x (h_ib = hᵀ_bi)
                    let w = g.len();
                    x[..n * w].fill(0.0);
                    for b in 0..n {
                        for i in 0..n {
                            let h = ht[b * n + i];
                            for (y, &c) in g.iter().enumerate() {
                                x[i * w + y] += h * inp.bd[b * nl + c];
                            }
                        }
                    }
                    add_xsxt(&mut q, &x, &mut xs, &m.w, nl, g, n, false);
                }
                Level::Measurement(g) => {
                    // X = p Γ_G: X_ix = Σ_j p_ij Γ_j,G_x (p_ij = pᵀ_ji)
                    let w = g.len();
                    x[..n * w].fill(0.0);
                    for j in 0..nm {
                        let pj = &joseph.gain_t[j * n..j * n + n];
                        for (y, &c) in g.iter().enumerate() {
                            let gamma = inp.gamma[j * ms + c];
                            for i in 0..n {
                                x[i * w + y] += pj[i] * gamma;
                            }
                        }
                    }
                    add_xsxt(&mut q, &x, &mut xs, &m.v, ms, g, n, false);
                }
            }
            sandwich::<N>(&mut part.r, &mt, &q, &mut t, n);
            for i in 0..n {
                part.sum_r[i] += part.r[i * n + i];
            }
            if let Some(p_y) = &mut part.p_y {
                predict_in_place::<N, L>(p_y, &inp.e, &part.big_b, &mut u, n);
                for i in 0..n {
                    part.sum_p[i] += p_y[i * n + i];
                }
            }
        }
        checkpoints.at(progress, k, || k as f64 / steps as f64)?;
    }
    Ok(())
}

/// R ← M R Mᵀ + Q for symmetric R and Q, given Mᵀ (`mt`); `t` holds M R. Each a sum
/// of whole rows: (M R)_i· = Σ_b M_ib R_b·, (M R Mᵀ)_i· = Σ_b (M R)_ib (Mᵀ)_b·; the
/// upper triangle is then mirrored, so R stays exactly symmetric.
#[inline(always)]
fn sandwich<const N: usize>(r: &mut [f64], mt: &[f64], q: &[f64], t: &mut [f64], n: usize) {
    if N > 0 {
        // The same sums on arrays: each row's accumulator held in registers.
        let (m, q) = (mat::<N>(mt), mat::<N>(q));
        let rr = mat_mut::<N>(r);
        let mut mr = [[0.0f64; N]; N];
        for i in 0..N {
            let mut acc = [0.0f64; N];
            for b in 0..N {
                let x = m[b][i];
                for j in 0..N {
                    acc[j] += x * rr[b][j];
                }
            }
            mr[i] = acc;
        }
        for i in 0..N {
            let mut acc = q[i];
            for b in 0..N {
                let x = mr[i][b];
                for j in 0..N {
                    acc[j] += x * m[b][j];
                }
            }
            rr[i] = acc;
        }
        mirror::<N>(rr, true);
        return;
    }
    for i in 0..n {
        let ti = &mut t[i * n..i * n + n];
        ti.fill(0.0);
        for b in 0..n {
            let (x, rb) = (mt[b * n + i], &r[b * n..b * n + n]);
            for j in 0..n {
                ti[j] += x * rb[j];
            }
        }
    }
    for i in 0..n {
        let ri = &mut r[i * n..i * n + n];
        ri.copy_from_slice(&q[i * n..i * n + n]);
        for b in 0..n {
            let (x, mb) = (t[i * n + b], &mt[b * n..b * n + n]);
            for j in 0..n {
                ri[j] += x * mb[j];
            }
        }
    }
    for i in 1..n {
        for j in 0..i {
            r[i * n + j] = r[j * n + i];
        }
    }
}

/// x (n × |G|) = the columns G of `from` (n × cols).
fn gather(x: &mut [f64], from: &[f64], cols: usize, g: &[usize], n: usize) {
    let w = g.len();
    for i in 0..n {
        for (y, &c) in g.iter().enumerate() {
            x[i * w + y] = from[i * cols + c];
        }
    }
}

/// out (+)= X S_GG Xᵀ (X: n × |G|, S: k × k with the group's rows and columns G),
/// its upper triangle computed and mirrored; `assign`: out is overwritten.
#[allow(clippy::too_many_arguments)] // the product's operands and their sizes
fn add_xsxt(
    out: &mut [f64],
    x: &[f64],
    xs: &mut [f64],
    s: &[f64],
    k: usize,
    g: &[usize],
    n: usize,
    assign: bool,
) {
    let w = g.len();
    for i in 0..n {
        for (y, &c) in g.iter().enumerate() {
            xs[i * w + y] = g
                .iter()
                .enumerate()
                .map(|(z, &d)| x[i * w + z] * s[d * k + c])
                .sum();
        }
    }
    for i in 0..n {
        for j in i..n {
            let v: f64 = (0..w).map(|y| xs[i * w + y] * x[j * w + y]).sum();
            let v = if assign { v } else { v + out[i * n + j] };
            out[i * n + j] = v;
            out[j * n + i] = v;
        }
    }
}
