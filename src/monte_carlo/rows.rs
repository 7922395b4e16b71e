//! The traces' rows (METHOD §1.8): bucket averages of the per-step series (variances
//! averaged, SKOs derived at the end), and the series' indices per state.

use super::state::RowsState;
use crate::resume::{F, bits, values};

/// Bucket averages of variances for the traces.
pub(super) struct Rows {
    pub(super) bucket: u64,
    steps: u64,
    series: usize,
    sum: Vec<f64>,
    count: Vec<u64>,
    in_bucket: u64,
    pub(super) t: Vec<f64>,
    pub(super) cols: Vec<Vec<Option<f64>>>,
}

impl Rows {
    pub(super) fn new(steps: u64, series: usize, max_rows: usize) -> Self {
        let bucket = steps.div_ceil(max_rows.max(1) as u64).max(1);
        Rows {
            bucket,
            steps,
            series,
            sum: vec![0.0; series],
            count: vec![0; series],
            in_bucket: 0,
            t: Vec::new(),
            cols: vec![Vec::new(); series],
        }
    }
    pub(super) fn put(&mut self, s: usize, v: f64) {
        self.sum[s] += v;
        self.count[s] += 1;
    }
    /// The rows' state ([`crate::resume`]).
    pub(super) fn state(&self) -> RowsState {
        RowsState {
            sum: bits(&self.sum),
            count: self.count.clone(),
            in_bucket: self.in_bucket,
            t: bits(&self.t),
            cols: self
                .cols
                .iter()
                .map(|c| c.iter().map(|v| v.map(F)).collect())
                .collect(),
        }
    }
    /// The rows as `kept` (of as many series).
    pub(super) fn restore(&mut self, kept: RowsState) {
        self.sum = values(&kept.sum);
        self.count = kept.count;
        self.in_bucket = kept.in_bucket;
        self.t = values(&kept.t);
        self.cols = kept
            .cols
            .into_iter()
            .map(|c| c.into_iter().map(|v| v.map(|v| v.0)).collect())
            .collect();
    }
    pub(super) fn end(&mut self, k: u64, t: f64) {
        self.in_bucket += 1;
        if self.in_bucket == self.bucket || k == self.steps {
            self.t.push(t);
            for s in 0..self.series {
                self.cols[s].push((self.count[s] > 0).then(|| self.sum[s] / self.count[s] as f64));
                self.sum[s] = 0.0;
                self.count[s] = 0;
            }
            self.in_bucket = 0;
        }
    }
}

// Trace series per state (variances are averaged, SKOs derived at the end).
pub(super) const T_APRIORI: usize = 0;
pub(super) const T_OPEN: usize = 1;
pub(super) const T_MEAS: usize = 2;
pub(super) const T_FILT: usize = 3;
pub(super) const T_MEAN: usize = 4;
pub(super) const T_POT: usize = 5;
pub(super) const T_CHI: usize = 6;
pub(super) const T_SERIES: usize = 7;
