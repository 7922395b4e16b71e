//! A long computation's state, kept so that a run interrupted there (a server restart)
//! goes on from that point instead of from the start, and ends with the result an
//! uninterrupted run gives, bit for bit: an analysis's between two steps
//! ([`LoopState`]), a Monte Carlo's between two chunks of steps ([`SimulationState`]).
//!
//! A state is text (a [`crate::exec::Memo`] value: the core has no storage): JSON in
//! which every f64 is its bit pattern (a u64), so that NaN, ±∞ and −0 read back as
//! they were. It is what the loop carries from one step to the next; what a step
//! recomputes from the model and k (the inputs at t_k, the factorisation of Rv, the
//! stationary solution, the Monte Carlo's gains) is not in it. A state of another
//! format, another model size or another run is not taken: the run starts over.

use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// The [`crate::exec::Memo`] key of an analysis's state.
pub const STATE_KEY: &str = "analysis-state";

/// The format of [`LoopState`]; a state of another is ignored.
const FORMAT: u32 = 1;

/// An f64 as its bits.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct F(pub f64);

impl Serialize for F {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_u64(self.0.to_bits())
    }
}

impl<'de> Deserialize<'de> for F {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<F, D::Error> {
        u64::deserialize(d).map(|b| F(f64::from_bits(b)))
    }
}

/// Values as their bits.
pub(crate) fn bits(v: &[f64]) -> Vec<F> {
    v.iter().map(|&x| F(x)).collect()
}

/// `dst` set to the values of `src`'s bits (of its length).
pub(crate) fn put(dst: &mut [f64], src: &[F]) {
    for (d, s) in dst.iter_mut().zip(src) {
        *d = s.0;
    }
}

/// Bits as values.
pub(crate) fn values(v: &[F]) -> Vec<f64> {
    v.iter().map(|x| x.0).collect()
}

/// The trace decimator's state ([`crate::decimate::Decimator`]).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub(crate) struct DecimatorState {
    pub min: Vec<F>,
    pub min_at: Vec<u32>,
    pub max: Vec<F>,
    pub max_at: Vec<u32>,
    pub in_bucket: u64,
    pub first_t: F,
    pub last_t: F,
    pub t: Vec<F>,
    pub columns: Vec<Vec<Option<F>>>,
}

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
        dec: &crate::decimate::Decimator,
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

/// The [`crate::exec::Memo`] key of a `"steps": "auto"` selection (kept once made:
/// `steps::Selected`, as JSON).
pub const SELECTION_KEY: &str = "steps-selection";

/// The [`crate::exec::Memo`] key of a Monte Carlo's state.
pub const SIMULATION_KEY: &str = "simulation-state";

/// The format of [`SimulationState`]; a state of another is ignored.
const SIMULATION_FORMAT: u32 = 1;

/// What makes a Monte Carlo's state belong to a run: the model's size, the steps, the
/// runs and their seed, and the chunk length (a state is kept between chunks).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub(crate) struct SimulationStamp {
    pub format: u32,
    pub steps: u64,
    pub n: usize,
    pub nm: usize,
    pub runs: u64,
    pub seed: u64,
    pub chunk: usize,
}

impl SimulationStamp {
    pub(crate) fn new(
        steps: u64,
        (n, nm): (usize, usize),
        runs: u64,
        seed: u64,
        chunk: usize,
    ) -> Self {
        SimulationStamp {
            format: SIMULATION_FORMAT,
            steps,
            n,
            nm,
            runs,
            seed,
            chunk,
        }
    }
}

/// A block of runs' state: their imitated states Y and estimates X (runs × N each),
/// and where each run's random stream is (in 32-bit words from its start). A constant
/// model error is not in it: it is drawn again, from the start of the run's stream,
/// as it was the first time.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub(crate) struct BlockState {
    pub y: Vec<F>,
    pub x: Vec<F>,
    pub word_pos: Vec<u64>,
}

/// A trace row buffer's state (`simulation::Rows`).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub(crate) struct RowsState {
    pub sum: Vec<F>,
    pub count: Vec<u64>,
    pub in_bucket: u64,
    pub t: Vec<F>,
    pub cols: Vec<Vec<Option<F>>>,
}

/// A Monte Carlo's state after step `k`, the end of a chunk (see
/// `simulation::run_n` for what each member is).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub(crate) struct SimulationState {
    pub stamp: SimulationStamp,
    /// The steps done.
    pub k: u64,
    /// The plan: the mean, R, P^Y and the bound χ.
    pub y: Vec<F>,
    pub big_r: Vec<F>,
    pub p_y: Vec<F>,
    pub chi: Vec<F>,
    pub blocks: Vec<BlockState>,
    pub rows: RowsState,
    /// The Monte Carlo criteria's sums (YZ, ZX, YX; per state: sum, count, excluded).
    pub mc: [Vec<(F, u64, u64)>; 3],
    /// NEES: sum, steps, steps in band; NIS: sum, dof sum, steps, steps in band.
    pub nees: (F, u64, u64),
    pub nis: (F, F, u64, u64),
    pub ratio_sum: Vec<F>,
    pub ratio_count: Vec<u64>,
    pub ratio_in: Vec<u64>,
    pub bias_sum: Vec<F>,
}

impl SimulationState {
    pub(crate) fn to_text(&self) -> String {
        serde_json::to_string(self).expect("a state of numbers and bits serialises")
    }

    /// The state in `text` if it was kept by the run `stamp` describes, with `blocks`
    /// blocks of the given runs each and trace rows of `series` series; None
    /// otherwise (the run starts over).
    pub(crate) fn from_text(
        text: &str,
        stamp: SimulationStamp,
        blocks: &[usize],
        series: usize,
    ) -> Option<SimulationState> {
        let s: SimulationState = serde_json::from_str(text).ok()?;
        let n = stamp.n;
        let block_fits = |b: &BlockState, runs: usize| {
            b.y.len() == runs * n && b.x.len() == runs * n && b.word_pos.len() == runs
        };
        let rows = &s.rows;
        let rows_fit = rows.sum.len() == series
            && rows.count.len() == series
            && rows.cols.len() == series
            && rows.cols.iter().all(|c| c.len() == rows.t.len());
        let lengths = [
            (s.y.len(), n),
            (s.big_r.len(), n * n),
            (s.p_y.len(), n * n),
            (s.chi.len(), n),
            (s.mc[0].len(), n),
            (s.mc[1].len(), n),
            (s.mc[2].len(), n),
            (s.ratio_sum.len(), n),
            (s.ratio_count.len(), n),
            (s.ratio_in.len(), n),
            (s.bias_sum.len(), n),
            (s.blocks.len(), blocks.len()),
        ];
        let fits = lengths.iter().all(|(got, want)| got == want)
            && s.blocks.iter().zip(blocks).all(|(b, &r)| block_fits(b, r))
            && rows_fit;
        (s.stamp == stamp && s.k <= stamp.steps && fits).then_some(s)
    }
}
