//! The Monte Carlo's state between two chunks of steps ([`MonteCarloState`]), kept so
//! that an interrupted run goes on from it ([`crate::resume`]).

use crate::resume::F;
use serde::{Deserialize, Serialize};

/// The [`crate::exec::Memo`] key of a Monte Carlo's state.
pub const STATE_KEY: &str = "monte-carlo-state";

/// The format of [`MonteCarloState`]; a state of another is ignored.
const FORMAT: u32 = 1;

/// What makes a Monte Carlo's state belong to a run: the model's size, the steps, the
/// runs and their seed, and the chunk length (a state is kept between chunks).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub(crate) struct MonteCarloStamp {
    pub format: u32,
    pub steps: u64,
    pub n: usize,
    pub nm: usize,
    pub runs: u64,
    pub seed: u64,
    pub chunk: usize,
}

impl MonteCarloStamp {
    pub(crate) fn new(
        steps: u64,
        (n, nm): (usize, usize),
        runs: u64,
        seed: u64,
        chunk: usize,
    ) -> Self {
        MonteCarloStamp {
            format: FORMAT,
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

/// A trace row buffer's state (`rows::Rows`).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub(crate) struct RowsState {
    pub sum: Vec<F>,
    pub count: Vec<u64>,
    pub in_bucket: u64,
    pub t: Vec<F>,
    pub cols: Vec<Vec<Option<F>>>,
}

/// A Monte Carlo's state after step `k`, the end of a chunk (see
/// `super::run_n` for what each member is).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub(crate) struct MonteCarloState {
    pub stamp: MonteCarloStamp,
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

impl MonteCarloState {
    pub(crate) fn to_text(&self) -> String {
        serde_json::to_string(self).expect("a state of numbers and bits serialises")
    }

    /// The state in `text` if it was kept by the run `stamp` describes, with `blocks`
    /// blocks of the given runs each and trace rows of `series` series; None
    /// otherwise (the run starts over).
    pub(crate) fn from_text(
        text: &str,
        stamp: MonteCarloStamp,
        blocks: &[usize],
        series: usize,
    ) -> Option<MonteCarloState> {
        let s: MonteCarloState = serde_json::from_str(text).ok()?;
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
