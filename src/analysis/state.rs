//! The analysis's step-loop state ([`LoopState`]): what the loop carries from one
//! step to the next, which is also what an interrupted run keeps to go on from
//! ([`crate::resume`]), and the memo keys of an analysis.

use super::criteria::Running;
use super::traces::{SERIES, Written};
use crate::model::compile::CompiledModel;
use crate::numerics::decimate::Decimator;
use crate::numerics::riccati::SequentialJoseph;
use crate::resume::{F, f64s};
use serde::{Deserialize, Serialize};

/// The [`crate::exec::Memo`] key of an analysis's state.
pub const STATE_KEY: &str = "analysis-state";

/// The [`crate::exec::Memo`] key of a `"steps": "auto"` selection (kept once made:
/// `steps::Selected`, as JSON).
pub const SELECTION_KEY: &str = "steps-selection";

/// The format of a kept state; a state of another is ignored (the run starts over).
const FORMAT: u32 = 2;

/// The step loop's state after step `k` (`analysis::engine`'s loop reads and writes
/// it; nothing else carries from one step to the next but what a step recomputes
/// from the model and k: the inputs at t_k, the factorisation of Rv, scratch).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub(super) struct LoopState {
    /// The steps done (kept beside the state, with the run it is of).
    #[serde(skip)]
    pub k: u64,
    /// The mean y_k (3.3), and the largest |y| and |ẏ| so far (for z_max and the
    /// overflow check).
    #[serde(with = "f64s")]
    pub y: Vec<f64>,
    #[serde(with = "f64s")]
    pub y_max: Vec<f64>,
    #[serde(with = "f64s")]
    pub ydot_max: Vec<f64>,
    /// R_k, the filtered covariance (2.7).
    #[serde(with = "f64s")]
    pub big_r: Vec<f64>,
    /// P^Y, the open-loop (a-priori) covariance (§1.5).
    #[serde(with = "f64s")]
    pub p_y: Vec<f64>,
    /// The bound's η (a-priori, 3.16) and χ (filtered, 3.18–3.19; χ(t0) = 0).
    #[serde(with = "f64s")]
    pub eta: Vec<f64>,
    #[serde(with = "f64s")]
    pub chi: Vec<f64>,
    /// The Riccati step (2.1)–(2.7) with r_k, p_k and h_k.
    pub joseph: SequentialJoseph,
    /// The measurements available at this step, and the mask the factorisation of Rv
    /// was made for.
    pub avail: Vec<bool>,
    pub avail_prev: Vec<bool>,
    /// |I − pC|ᵀ and |p| ζ (3.19).
    #[serde(with = "f64s")]
    pub abs_ht: Vec<f64>,
    #[serde(with = "f64s")]
    pub pz: Vec<f64>,
    /// sqrt(diag R_k), and its reciprocals where positive (NaN otherwise).
    #[serde(with = "f64s")]
    pub pot: Vec<f64>,
    #[serde(with = "f64s")]
    pub inv_pot: Vec<f64>,
    /// The criteria's running sums (3.24).
    pub running: Running,
    /// A step's trace values (NaN: no value), followed by its covariance-set ratios
    /// (NaN: excluded), so that the six criteria's ratios are contiguous (the bound
    /// set's are the last three trace series).
    #[serde(with = "f64s")]
    pub row: Vec<f64>,
    /// Which criteria take part, per criterion and state, and the (bound_ok,
    /// open_ok) it was set for.
    pub part: Vec<u64>,
    pub part_for: Option<(bool, bool)>,
    /// Per state: ζ, σ_Z while its measurement is available (NaN when unpaired or
    /// unavailable, which makes every measured ratio NaN), and their reciprocals
    /// where positive (NaN otherwise: a ratio over them is then NaN, excluded).
    #[serde(with = "f64s")]
    pub zeta_s: Vec<f64>,
    #[serde(with = "f64s")]
    pub meas_s: Vec<f64>,
    #[serde(with = "f64s")]
    pub inv_zeta_s: Vec<f64>,
    #[serde(with = "f64s")]
    pub inv_meas_s: Vec<f64>,
    /// Per state: its paired measurement is available at this step.
    pub has_meas: Vec<bool>,
    /// Whether the row's constant series (before S_Y) and covariance ZX ratios are
    /// those of the previous step.
    pub constant_rows: bool,
    /// The row written at the end of the previous step, not yet summed.
    pub written: Option<Written>,
    /// The step the steady-state shortcut froze the recursion at.
    pub frozen_at: Option<u64>,
    /// The bound (|A| element-wise) or the open-loop covariance can overflow while
    /// the filter itself is fine; the affected criteria then become null.
    /// (step, t, whether η — the a-priori bound — overflowed, not only χ)
    pub bound_diverged: Option<(u64, F, bool)>,
    pub open_diverged: Option<(u64, F)>,
    /// The step r_k reached r∞, and R and p there.
    pub steady_at: Option<u64>,
    pub steady_cov: Option<(Vec<F>, Vec<F>)>,
    /// The first step (k, t_k, state) whose filtered variance is at rounding level,
    /// and how many steps had one.
    pub cancelled: Option<(u64, F, usize)>,
    pub cancelled_steps: u64,
    /// The first step whose Rv is ill-conditioned, and the worst spread of its pivots.
    pub ill_conditioned: Option<(u64, F, F)>,
}

/// A kept state as text: the loop's, the trace decimator's, and what run it is of.
#[derive(Serialize)]
struct Kept<'a> {
    format: u32,
    steps: u64,
    n: usize,
    nm: usize,
    k: u64,
    state: &'a LoopState,
    dec: &'a Decimator,
}

#[derive(Deserialize)]
struct Read {
    format: u32,
    steps: u64,
    n: usize,
    nm: usize,
    k: u64,
    state: LoopState,
    dec: Decimator,
}

impl LoopState {
    /// The state before step 1: y(t0), R_0 = P^Y_0 = diag(η0²), χ = 0.
    pub(super) fn new(m: &CompiledModel, n: usize, nm: usize) -> LoopState {
        let mut big_r = vec![0.0; n * n];
        for i in 0..n {
            big_r[i * n + i] = m.eta0[i] * m.eta0[i];
        }
        let nan = vec![f64::NAN; n];
        LoopState {
            k: 0,
            y: m.y0.clone(),
            y_max: m.y0.iter().map(|v| v.abs()).collect(),
            ydot_max: vec![0.0; n],
            p_y: big_r.clone(),
            big_r,
            eta: m.eta0.clone(),
            chi: vec![0.0; n],
            joseph: SequentialJoseph::new(n, nm),
            avail: vec![true; nm],
            avail_prev: vec![true; nm],
            abs_ht: vec![0.0; n * n],
            pz: vec![0.0; n],
            pot: vec![0.0; n],
            inv_pot: vec![0.0; n],
            running: Running::new(n),
            row: vec![f64::NAN; (SERIES + 3) * n],
            part: vec![0; 6 * n],
            part_for: None,
            zeta_s: nan.clone(),
            meas_s: nan.clone(),
            inv_zeta_s: nan.clone(),
            inv_meas_s: nan,
            has_meas: vec![false; n],
            constant_rows: false,
            written: None,
            frozen_at: None,
            bound_diverged: None,
            open_diverged: None,
            steady_at: None,
            steady_cov: None,
            cancelled: None,
            cancelled_steps: 0,
            ill_conditioned: None,
        }
    }

    /// The state and the decimator's as text, for a run of `steps` steps of an N × n
    /// model.
    pub(super) fn to_text(&self, dec: &Decimator, steps: u64, n: usize, nm: usize) -> String {
        let kept = Kept {
            format: FORMAT,
            steps,
            n,
            nm,
            k: self.k,
            state: self,
            dec,
        };
        serde_json::to_string(&kept).expect("a state of numbers and bits serialises")
    }

    /// The state in `text`, if it is one of this format for a run of `steps` steps of
    /// an N × n model whose traces `dec` decimates (its values then restored into
    /// `dec`); None otherwise (the run starts over).
    pub(super) fn from_text(
        text: &str,
        steps: u64,
        m: &CompiledModel,
        (n, nm): (usize, usize),
        dec: &mut Decimator,
    ) -> Option<LoopState> {
        let kept: serde_json::Value = serde_json::from_str(text).ok()?;
        // Every vector of the length a fresh state's has (the optional members that
        // both have set, too); the steady state's matrices, unset in a fresh one, by hand.
        let fresh = serde_json::to_value(LoopState::new(m, n, nm)).ok()?;
        if !crate::resume::same_shape(&kept["state"], &fresh) {
            return None;
        }
        let mut r: Read = serde_json::from_value(kept).ok()?;
        r.state.k = r.k;
        let s = &r.state;
        let steady_fits = s
            .steady_cov
            .as_ref()
            .is_none_or(|(r, g)| r.len() == n * n && g.len() == n * nm);
        let run = (r.format, r.steps, r.n, r.nm) == (FORMAT, steps, n, nm) && s.k <= steps;
        if !(steady_fits && run && dec.fits(&r.dec)) {
            return None;
        }
        dec.restore(r.dec);
        Some(r.state)
    }
}
