//! The runs (METHOD §1.8, seed 000 steps 21–22): blocks of runs, each run with its own
//! ChaCha8 stream, advancing the imitated state Y and the filter X through a chunk's
//! records and returning per-step sums.

use super::plan::{Dims, Layout, SumLayout};
use super::request::{ModelError, Truth};
use super::state::BlockState;
use crate::model::compile::CompiledModel;
use crate::resume::{bits, values};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

/// A block of runs: their imitated states and filters, and their random streams.
pub(super) struct Block {
    pub(super) runs: usize,
    /// Y (imitated a-priori state), X (estimate), F (constant model error), each
    /// runs × dim.
    y: Vec<f64>,
    x: Vec<f64>,
    f_const: Vec<f64>,
    rngs: Vec<ChaCha8Rng>,
}

/// Read-only inputs shared by all blocks in a chunk.
pub(super) struct Shared<'a> {
    pub(super) d: Dims,
    pub(super) lay: Layout,
    pub(super) sl: SumLayout,
    pub(super) truth: Truth,
    pub(super) model_error: ModelError,
    /// The filter's C (the model's), and the world's (the truth's, or the same).
    pub(super) c_nz: &'a [(usize, usize, f64)],
    pub(super) wc_nz: &'a [(usize, usize, f64)],
    /// The world's C is the filter's: the innovation is formed as C (truth − H).
    pub(super) same_c: bool,
    /// Entries of the filter's A = I + aΔt, the world's A, bΔt and Γ that can be
    /// non-zero (row, col): the per-run products skip the structural zeros.
    pub(super) a_nz: &'a [(usize, usize)],
    pub(super) wa_nz: &'a [(usize, usize)],
    pub(super) bd_nz: &'a [(usize, usize)],
    pub(super) g_nz: &'a [(usize, usize)],
    /// Lower-triangular square roots of the world's W (L×L) and V (M×M).
    pub(super) w_sqrt: &'a [f64],
    pub(super) v_sqrt: &'a [f64],
}

#[inline(always)]
fn normal(rng: &mut ChaCha8Rng) -> f64 {
    StandardNormal.sample(rng)
}

/// z = S ξ with S lower-triangular (dim×dim), ξ standard normal.
#[inline(always)]
fn draw(rng: &mut ChaCha8Rng, s: &[f64], dim: usize, xi: &mut [f64], z: &mut [f64]) {
    for v in xi[..dim].iter_mut() {
        *v = normal(rng);
    }
    for i in 0..dim {
        let mut acc = 0.0;
        for j in 0..=i {
            acc += s[i * dim + j] * xi[j];
        }
        z[i] = acc;
    }
}

impl Block {
    /// Runs `first_run`… of the world `m` (Y_0 ~ (y0, diag η0²), the model error
    /// from its W), each filter starting from `x0` (the model's y0).
    pub(super) fn new(
        first_run: u64,
        runs: usize,
        seed: u64,
        (m, x0): (&CompiledModel, &[f64]),
        sh: &Shared,
    ) -> Self {
        let Dims { n, nl, .. } = sh.d;
        let mut y = vec![0.0; runs * n];
        let x: Vec<f64> = (0..runs).flat_map(|_| x0.iter().copied()).collect();
        let mut f_const = vec![0.0; runs * nl];
        let mut xi = vec![0.0; nl.max(n)];
        let mut rngs = Vec::with_capacity(runs);
        for r in 0..runs {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            rng.set_stream(first_run + r as u64);
            // Y_0 ~ (y0, diag η0²) (step 7), then the constant model error if any.
            for i in 0..n {
                y[r * n + i] = m.y0[i] + m.eta0[i] * normal(&mut rng);
            }
            if sh.model_error == ModelError::Constant {
                let mut f = vec![0.0; nl];
                draw(&mut rng, sh.w_sqrt, nl, &mut xi, &mut f);
                f_const[r * nl..r * nl + nl].copy_from_slice(&f);
            }
            rngs.push(rng);
        }
        Block {
            runs,
            y,
            x,
            f_const,
            rngs,
        }
    }

    /// The block's state ([`crate::resume`]).
    pub(super) fn state(&self) -> BlockState {
        BlockState {
            y: bits(&self.y),
            x: bits(&self.x),
            // (2⁶⁴ words of one stream are beyond any run: a position is a u64.)
            word_pos: self.rngs.iter().map(|r| r.get_word_pos() as u64).collect(),
        }
    }

    /// The block as `kept`: a new block of the same runs (its constant model errors
    /// drawn as they were), where the kept one had gone.
    pub(super) fn restore(&mut self, kept: &BlockState) {
        self.y = values(&kept.y);
        self.x = values(&kept.x);
        for (r, &pos) in self.rngs.iter_mut().zip(&kept.word_pos) {
            r.set_word_pos(u128::from(pos));
        }
    }

    /// Advance every run through a chunk of `steps` records; return the per-step sums
    /// (steps × `SumLayout::size`).
    ///
    /// Run-minor ("structure of arrays"): every quantity is stored as dim × runs, so
    /// each product is a loop over the block's runs that the compiler vectorises. Each
    /// run still draws from its own stream in the same order (F, then Φ, per step), and
    /// the per-step sums run over the runs in order: results do not depend on threads.
    pub(super) fn advance<const N: usize>(
        &mut self,
        sh: &Shared,
        chunk: &[f64],
        steps: usize,
    ) -> Vec<f64> {
        let d = sh.d;
        let n = if N == 0 { d.n } else { N };
        let (nm, nl, ms) = (d.nm, d.nl, d.ms);
        let nr = self.runs;
        let lay = sh.lay;
        let sl = sh.sl;
        let mut sums = vec![0.0; steps * sl.size];
        // dim × runs buffers
        let soa = |aos: &[f64], dim: usize| -> Vec<f64> {
            let mut v = vec![0.0; dim * nr];
            for r in 0..nr {
                for i in 0..dim {
                    v[i * nr + r] = aos[r * dim + i];
                }
            }
            v
        };
        let mut ys = soa(&self.y, n);
        let mut xs = soa(&self.x, n);
        let mut f = soa(&self.f_const, nl);
        let mut y_new = vec![0.0; n * nr];
        let mut phi = vec![0.0; ms * nr];
        let mut noise = vec![0.0; nm * nr];
        let mut h = vec![0.0; n * nr];
        let mut nu = vec![0.0; nm * nr];
        let mut e = vec![0.0; n * nr];
        let mut mean = vec![0.0; if sh.truth == Truth::Mean { n * nr } else { 0 }];
        let mut w = vec![0.0; n.max(nm) * nr];
        let mut norm2 = vec![0.0; nr];
        let mut xi = vec![0.0; nl.max(ms)];
        let mut one = vec![0.0; nl.max(ms)];
        for s in 0..steps {
            let rec = &chunk[s * lay.size..(s + 1) * lay.size];
            let out = &mut sums[s * sl.size..(s + 1) * sl.size];
            let a = &rec[lay.a..lay.a + n * n];
            let u = &rec[lay.u..lay.u + n];
            let wa = &rec[lay.wa..lay.wa + n * n];
            let wu = &rec[lay.wu..lay.wu + n];
            let bd = &rec[lay.bd..lay.bd + n * nl];
            let ym = &rec[lay.y..lay.y + n];
            let gamma = &rec[lay.gamma..lay.gamma + nm * ms];
            let gain = &rec[lay.gain..lay.gain + n * nm];
            // Draws, run by run: F (white model error), then Φ.
            for (r, rng) in self.rngs.iter_mut().enumerate() {
                if sh.model_error == ModelError::White {
                    draw(rng, sh.w_sqrt, nl, &mut xi, &mut one);
                    for l in 0..nl {
                        f[l * nr + r] = one[l];
                    }
                }
                draw(rng, sh.v_sqrt, ms, &mut xi, &mut one);
                for l in 0..ms {
                    phi[l * nr + r] = one[l];
                }
            }
            // Step 21: Y_k = A Y + uΔt + bΔt F (the world's A, u, b).
            for i in 0..n {
                y_new[i * nr..(i + 1) * nr].fill(wu[i]);
            }
            for &(i, j) in sh.wa_nz {
                axpy(&mut y_new, i, &ys, j, wa[i * n + j], nr);
            }
            for &(i, l) in sh.bd_nz {
                axpy(&mut y_new, i, &f, l, bd[i * nl + l], nr);
            }
            std::mem::swap(&mut ys, &mut y_new);
            let truth: &[f64] = match sh.truth {
                Truth::Process => &ys,
                Truth::Mean => {
                    for i in 0..n {
                        mean[i * nr..(i + 1) * nr].fill(ym[i]);
                    }
                    &mean
                }
            };
            // Step 22: Z_k = C·truth + Γ_k Φ (Φ drawn every step, used where available).
            noise.fill(0.0);
            for &(j, l) in sh.g_nz {
                axpy(&mut noise, j, &phi, l, gamma[j * ms + l], nr);
            }
            // (2.8) H = A X + uΔt; (2.10) X = H + p (Z − C H)
            for i in 0..n {
                h[i * nr..(i + 1) * nr].fill(u[i]);
            }
            for &(i, j) in sh.a_nz {
                axpy(&mut h, i, &xs, j, a[i * n + j], nr);
            }
            // ν = Z − C H, Z = C^w·truth + ΓΦ
            nu.copy_from_slice(&noise);
            if sh.same_c {
                for &(j, i, c) in sh.c_nz {
                    let (t, hh) = (&truth[i * nr..(i + 1) * nr], &h[i * nr..(i + 1) * nr]);
                    for ((v, t), hh) in nu[j * nr..(j + 1) * nr].iter_mut().zip(t).zip(hh) {
                        *v += c * (t - hh);
                    }
                }
            } else {
                for &(j, i, c) in sh.wc_nz {
                    axpy(&mut nu, j, truth, i, c, nr);
                }
                for &(j, i, c) in sh.c_nz {
                    axpy(&mut nu, j, &h, i, -c, nr);
                }
            }
            for j in 0..nm {
                if rec[lay.avail + j] == 0.0 {
                    nu[j * nr..(j + 1) * nr].fill(0.0);
                }
            }
            xs.copy_from_slice(&h);
            for i in 0..n {
                for j in 0..nm {
                    let g = gain[i * nm + j];
                    if g != 0.0 {
                        axpy(&mut xs, i, &nu, j, g, nr);
                    }
                }
            }
            // Errors and their sums (over the runs, in order).
            for i in 0..n {
                let (yi, xi_, ti) = (
                    &ys[i * nr..(i + 1) * nr],
                    &xs[i * nr..(i + 1) * nr],
                    &truth[i * nr..(i + 1) * nr],
                );
                let ei = &mut e[i * nr..(i + 1) * nr];
                for r in 0..nr {
                    let ea = yi[r] - ym[i];
                    out[sl.apriori + i] += ea * ea;
                    let er = xi_[r] - ti[r];
                    ei[r] = er;
                    out[sl.filt2 + i] += er * er;
                    out[sl.filt1 + i] += er;
                }
            }
            for j in 0..nm {
                for v in &noise[j * nr..(j + 1) * nr] {
                    out[sl.meas2 + j] += v * v;
                }
            }
            // NEES = ‖L⁻¹ e‖² with R_k = L Lᵀ.
            if rec[lay.flags] != 0.0 {
                forward_norm2(&rec[lay.r_chol..], &e, &mut w, &mut norm2, n, nr);
                for v in &norm2 {
                    out[sl.nees] += v;
                }
            }
            // NIS = ‖Lq⁻¹ ν‖² (ν = 0 for unavailable measurements, q masked).
            if rec[lay.flags + 1] != 0.0 {
                forward_norm2(&rec[lay.q_chol..], &nu, &mut w, &mut norm2, nm, nr);
                for v in &norm2 {
                    out[sl.nis] += v;
                }
            }
        }
        // back to runs × dim
        for r in 0..nr {
            for i in 0..n {
                self.y[r * n + i] = ys[i * nr + r];
                self.x[r * n + i] = xs[i * nr + r];
            }
        }
        sums
    }
}

/// Row i of `dst` += v · row j of `src` (both dim × len).
#[inline(always)]
fn axpy(dst: &mut [f64], i: usize, src: &[f64], j: usize, v: f64, len: usize) {
    for (d, s) in dst[i * len..(i + 1) * len]
        .iter_mut()
        .zip(&src[j * len..(j + 1) * len])
    {
        *d += v * s;
    }
}

/// out[r] = ‖L⁻¹ v_r‖² for every run r (v, w: dim × runs) with L lower-triangular
/// (dim×dim, row-major) stored with 1/L_ii on its diagonal.
#[inline(always)]
fn forward_norm2(l: &[f64], v: &[f64], w: &mut [f64], out: &mut [f64], dim: usize, nr: usize) {
    out.fill(0.0);
    for i in 0..dim {
        let (done, rest) = w.split_at_mut(i * nr);
        let wi = &mut rest[..nr];
        wi.copy_from_slice(&v[i * nr..(i + 1) * nr]);
        for k in 0..i {
            let lik = l[i * dim + k];
            for (x, y) in wi.iter_mut().zip(&done[k * nr..(k + 1) * nr]) {
                *x -= lik * y;
            }
        }
        let d = l[i * dim + i];
        for (x, o) in wi.iter_mut().zip(out.iter_mut()) {
            *x *= d;
            *o += *x * *x;
        }
    }
}

/// Lower-triangular S with S Sᵀ = cov for a positive semi-definite cov (dim×dim):
/// Cholesky, with a zero column where a pivot is zero (a degenerate direction).
pub(super) fn sqrt_psd(cov: &[f64], dim: usize) -> Vec<f64> {
    let mut l = vec![0.0; dim * dim];
    let scale = (0..dim).map(|i| cov[i * dim + i].abs()).fold(0.0, f64::max);
    for j in 0..dim {
        let mut d = cov[j * dim + j];
        for k in 0..j {
            d -= l[j * dim + k] * l[j * dim + k];
        }
        if d <= 1e-14 * scale {
            continue; // column j stays zero
        }
        let d = d.sqrt();
        l[j * dim + j] = d;
        for i in j + 1..dim {
            let mut s = cov[i * dim + j];
            for k in 0..j {
                s -= l[i * dim + k] * l[j * dim + k];
            }
            l[i * dim + j] = s / d;
        }
    }
    l
}
