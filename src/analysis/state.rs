//! The analysis's step-loop state ([`LoopState`]), kept so that an interrupted run
//! goes on from it ([`crate::resume`]), and the memo keys of an analysis.

use crate::numerics::decimate::DecimatorState;
use crate::resume::F;
use serde::{Deserialize, Serialize};

/// The [`crate::exec::Memo`] key of an analysis's state.
pub const STATE_KEY: &str = "analysis-state";

/// The [`crate::exec::Memo`] key of a `"steps": "auto"` selection (kept once made:
/// `steps::Selected`, as JSON).
pub const SELECTION_KEY: &str = "steps-selection";

/// The format of [`LoopState`]; a state of another is ignored.
const FORMAT: u32 = 1;

/// The step loop's state after step `k` (see `analysis::Engine::run_body` for what
/// each member is).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub(crate) struct LoopState {
    pub format: u32,
    pub steps: u64,
    pub n: usize,
    pub nm: usize,
    /// The steps done.
    pub k: u64,
    pub y: Vec<F>,
    pub y_max: Vec<F>,
    pub ydot_max: Vec<F>,
    pub big_r: Vec<F>,
    pub p_y: Vec<F>,
    pub py_diag: Vec<F>,
    pub eta: Vec<F>,
    pub chi: Vec<F>,
    pub r_pred: Vec<F>,
    pub gain_t: Vec<F>,
    pub ht: Vec<F>,
    pub exact: bool,
    pub avail: Vec<bool>,
    pub avail_prev: Vec<bool>,
    pub abs_ht: Vec<F>,
    pub pz: Vec<F>,
    pub pot: Vec<F>,
    pub inv_pot: Vec<F>,
    pub sum: Vec<F>,
    pub count: Vec<u64>,
    pub excluded: Vec<u64>,
    pub row: Vec<F>,
    pub part: Vec<u64>,
    pub part_for: Option<(bool, bool)>,
    pub zeta_s: Vec<F>,
    pub meas_s: Vec<F>,
    pub inv_zeta_s: Vec<F>,
    pub inv_meas_s: Vec<F>,
    pub has_meas: Vec<bool>,
    pub dec: DecimatorState,
    pub constant_rows: bool,
    /// (k, t, bound_ok, open_ok, constants) of the row not yet summed.
    pub written: Option<(u64, F, bool, bool, bool)>,
    pub frozen_at: Option<u64>,
    pub bound_diverged: Option<(u64, F, bool)>,
    pub open_diverged: Option<(u64, F)>,
    pub steady_at: Option<u64>,
    pub steady_cov: Option<(Vec<F>, Vec<F>)>,
    pub cancelled: Option<(u64, F, usize)>,
    pub cancelled_steps: u64,
    pub ill_conditioned: Option<(u64, F, F)>,
}

impl LoopState {
    /// Stamp the state with the format and the run it belongs to.
    pub(crate) fn stamped(mut self, steps: u64, n: usize, nm: usize) -> LoopState {
        (self.format, self.steps, self.n, self.nm) = (FORMAT, steps, n, nm);
        self
    }

    pub(crate) fn to_text(&self) -> String {
        serde_json::to_string(self).expect("a state of numbers and bits serialises")
    }

    /// The state in `text`, if it is one of this format for a run of `steps` steps of
    /// an N × n model (`py_diag`: the length of the loop's gathered diagonal, N or 0)
    /// whose traces `dec` decimates; None otherwise (the run starts over).
    pub(crate) fn from_text(
        text: &str,
        steps: u64,
        (n, nm, py_diag): (usize, usize, usize),
        dec: &crate::numerics::decimate::Decimator,
    ) -> Option<LoopState> {
        let s: LoopState = serde_json::from_str(text).ok()?;
        let lengths = [
            (s.y.len(), n),
            (s.y_max.len(), n),
            (s.ydot_max.len(), n),
            (s.big_r.len(), n * n),
            (s.p_y.len(), n * n),
            (s.py_diag.len(), py_diag),
            (s.eta.len(), n),
            (s.chi.len(), n),
            (s.r_pred.len(), n * n),
            (s.gain_t.len(), nm * n),
            (s.ht.len(), n * n),
            (s.avail.len(), nm),
            (s.avail_prev.len(), nm),
            (s.abs_ht.len(), n * n),
            (s.pz.len(), n),
            (s.pot.len(), n),
            (s.inv_pot.len(), n),
            (s.sum.len(), 6 * n),
            (s.count.len(), 6 * n),
            (s.excluded.len(), 6 * n),
            (s.row.len(), (crate::analysis::SERIES + 3) * n),
            (s.part.len(), 6 * n),
            (s.zeta_s.len(), n),
            (s.meas_s.len(), n),
            (s.inv_zeta_s.len(), n),
            (s.inv_meas_s.len(), n),
            (s.has_meas.len(), n),
        ];
        let steady_fits = s
            .steady_cov
            .as_ref()
            .is_none_or(|(r, g)| r.len() == n * n && g.len() == n * nm);
        let fits = lengths.iter().all(|(got, want)| got == want) && steady_fits && dec.fits(&s.dec);
        (s.format == FORMAT && s.steps == steps && s.n == n && s.nm == nm && s.k <= steps && fits)
            .then_some(s)
    }
}
