//! Trace decimation that keeps extremes: steps are grouped in buckets of `bucket`
//! steps; each bucket emits two rows (its first and last time) and every series puts
//! its minimum and maximum over the bucket on them, in the order they occurred. So a
//! spike that lasts one step survives decimation. Memory is O(rows), not O(steps).

use crate::resume::{columns, f64_bits, f64s};
use serde::{Deserialize, Serialize};

/// Decimates `series` parallel series sampled at steps 1..=steps. It is also its own
/// state for [`crate::resume`] (its f64s kept as their bits).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Decimator {
    bucket: u64,
    steps: u64,
    series: usize,
    /// Each series' extremes in the current bucket and the steps they occurred at
    /// (their places in the bucket: 32 bits, half the width of a value, so that the
    /// selects cost half), as parallel arrays so that [`Decimator::put_row`] is one
    /// vectorisable loop. A series has a value in the bucket exactly when min ≤ max.
    #[serde(with = "f64s")]
    min: Vec<f64>,
    min_at: Vec<u32>,
    #[serde(with = "f64s")]
    max: Vec<f64>,
    max_at: Vec<u32>,
    in_bucket: u64,
    #[serde(with = "f64_bits")]
    first_t: f64,
    #[serde(with = "f64_bits")]
    last_t: f64,
    #[serde(with = "f64s")]
    pub t: Vec<f64>,
    /// One column per series; `None` where a series had no defined value.
    #[serde(with = "columns")]
    pub columns: Vec<Vec<Option<f64>>>,
    /// `max_rows == 0`: record nothing (results without traces).
    enabled: bool,
}

impl Decimator {
    /// Choose the bucket size so that at most `max_rows` rows are produced.
    pub fn new(steps: u64, series: usize, max_rows: usize) -> Self {
        let enabled = max_rows > 0;
        let max_rows = max_rows.max(2) as u64;
        let bucket = if steps <= max_rows {
            1
        } else {
            steps.div_ceil(max_rows / 2)
        };
        let rows = if enabled {
            (steps.div_ceil(bucket) * if bucket == 1 { 1 } else { 2 }) as usize
        } else {
            0
        };
        Decimator {
            bucket,
            steps,
            series,
            min: vec![f64::INFINITY; series],
            min_at: vec![0; series],
            max: vec![f64::NEG_INFINITY; series],
            max_at: vec![0; series],
            in_bucket: 0,
            first_t: 0.0,
            last_t: 0.0,
            t: Vec::with_capacity(rows),
            columns: (0..series).map(|_| Vec::with_capacity(rows)).collect(),
            enabled,
        }
    }

    pub fn bucket_steps(&self) -> u64 {
        self.bucket
    }

    /// Whether `s` (a kept state) is a state of this decimator: the same steps,
    /// buckets and series.
    pub(crate) fn fits(&self, s: &Decimator) -> bool {
        let series = self.series;
        (s.bucket, s.steps, s.series, s.enabled) == (self.bucket, self.steps, series, self.enabled)
            && [
                s.min.len(),
                s.min_at.len(),
                s.max.len(),
                s.max_at.len(),
                s.columns.len(),
            ]
            .iter()
            .all(|&l| l == series)
            && s.columns.iter().all(|c| c.len() == s.t.len())
            && s.in_bucket < self.bucket
    }

    /// Take the values of a state that [`Decimator::fits`], into this decimator's
    /// buffers (allocated for the whole run).
    pub(crate) fn restore(&mut self, s: Decimator) {
        self.min = s.min;
        self.min_at = s.min_at;
        self.max = s.max;
        self.max_at = s.max_at;
        self.in_bucket = s.in_bucket;
        self.first_t = s.first_t;
        self.last_t = s.last_t;
        self.t.clear();
        self.t.extend(s.t);
        for (col, from) in self.columns.iter_mut().zip(s.columns) {
            col.clear();
            col.extend(from);
        }
    }

    /// Start a step at time t (steps must come in order).
    #[inline]
    pub fn begin(&mut self, t: f64) {
        if !self.enabled {
            return;
        }
        if self.in_bucket == 0 {
            self.first_t = t;
        }
        self.last_t = t;
    }

    /// Whether the next step begins a bucket (then every series must be put).
    #[inline]
    pub fn bucket_starts(&self) -> bool {
        self.in_bucket == 0
    }

    /// Record the current step's values of the series `from..from + row.len()` (call
    /// between `begin` and `end`); NaN: the series has no value at this step. A
    /// series left out keeps its extremes — as if it repeated a value it had in
    /// this bucket (the comparisons are strict), so within a bucket a constant
    /// series need not be put again.
    #[inline(always)]
    pub fn put_row(&mut self, from: usize, row: &[f64]) {
        if !self.enabled {
            return;
        }
        // The step's place in its bucket (a bucket never holds more than
        // `validate::MAX_STEPS` < 2³² steps).
        debug_assert!(self.in_bucket <= u64::from(u32::MAX));
        let (n, k) = (row.len(), self.in_bucket as u32);
        let (min, min_at) = (
            &mut self.min[from..from + n],
            &mut self.min_at[from..from + n],
        );
        let (max, max_at) = (
            &mut self.max[from..from + n],
            &mut self.max_at[from..from + n],
        );
        // Branch-free (NaN compares false, so it changes nothing).
        for s in 0..n {
            let v = row[s];
            let lt = v < min[s];
            min[s] = if lt { v } else { min[s] };
            min_at[s] = if lt { k } else { min_at[s] };
            let gt = v > max[s];
            max[s] = if gt { v } else { max[s] };
            max_at[s] = if gt { k } else { max_at[s] };
        }
    }

    /// Finish a step; `k` is its index (1-based) and the last is `steps`.
    #[inline]
    pub fn end(&mut self, k: u64) {
        if !self.enabled {
            return;
        }
        self.in_bucket += 1;
        if self.in_bucket == self.bucket || k == self.steps {
            self.flush();
        }
    }

    fn flush(&mut self) {
        let two = self.bucket > 1;
        self.t.push(self.first_t);
        if two {
            self.t.push(self.last_t);
        }
        for (s, col) in self.columns.iter_mut().enumerate() {
            let (min, max) = (self.min[s], self.max[s]);
            // (min and max are never NaN: they start at ±∞ and only take values.)
            if min > max {
                col.push(None);
                if two {
                    col.push(None);
                }
            } else if !two {
                col.push(Some(min));
            } else if self.min_at[s] <= self.max_at[s] {
                col.push(Some(min));
                col.push(Some(max));
            } else {
                col.push(Some(max));
                col.push(Some(min));
            }
        }
        self.min.fill(f64::INFINITY);
        self.min_at.fill(0);
        self.max.fill(f64::NEG_INFINITY);
        self.max_at.fill(0);
        self.in_bucket = 0;
    }

    pub fn series(&self) -> usize {
        self.series
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(values: &[f64], rows: usize) -> Decimator {
        let mut d = Decimator::new(values.len() as u64, 1, rows);
        for (i, v) in values.iter().enumerate() {
            let k = i as u64 + 1;
            d.begin(k as f64);
            d.put_row(0, &[*v]);
            d.end(k);
        }
        d
    }

    #[test]
    fn a_one_step_spike_survives() {
        let mut v = vec![1.0; 100_000];
        v[31_337] = 50.0;
        v[77_777] = -3.0;
        let d = run(&v, 100);
        let col: Vec<f64> = d.columns[0].iter().map(|x| x.unwrap()).collect();
        assert!(d.t.len() <= 100, "{} rows", d.t.len());
        assert_eq!(col.iter().cloned().fold(f64::MIN, f64::max), 50.0);
        assert_eq!(col.iter().cloned().fold(f64::MAX, f64::min), -3.0);
    }

    #[test]
    fn extremes_keep_time_order_within_a_bucket() {
        // bucket of 4: [5, 1, 9, 2] -> min 1 (step 2) before max 9 (step 3)
        // [8, 7, 0, 3] -> max 8 (step 5) before min 0 (step 7)
        let v = [5.0, 1.0, 9.0, 2.0, 8.0, 7.0, 0.0, 3.0];
        let d = run(&v, 4);
        assert_eq!(d.bucket_steps(), 4);
        let col: Vec<f64> = d.columns[0].iter().map(|x| x.unwrap()).collect();
        assert_eq!(col, vec![1.0, 9.0, 8.0, 0.0]);
        assert_eq!(d.t, vec![1.0, 4.0, 5.0, 8.0]);
    }

    #[test]
    fn nan_is_no_value() {
        // buckets of 3: [NaN, NaN, NaN] has no value; [4, NaN, NaN] has 4 alone
        let nan = f64::NAN;
        let d = run(&[nan, nan, nan, 4.0, nan, nan, nan, nan, 6.0], 6);
        assert_eq!(d.bucket_steps(), 3);
        assert_eq!(
            d.columns[0],
            vec![None, None, Some(4.0), Some(4.0), Some(6.0), Some(6.0)]
        );
    }

    /// A constant series put only at each bucket's first step (`put_row` from the
    /// second series on otherwise, as the frozen phase does) gives the columns of
    /// putting it every step — also when the constant is NaN or a bucket's extreme
    /// of the other series falls on the bucket's first step.
    #[test]
    fn a_constant_series_put_once_per_bucket_is_the_same() {
        for constant in [2.5, f64::NAN, -1e300] {
            let steps = 1_003u64;
            let value = |k: u64| ((k * 2_654_435_761) % 997) as f64 - 498.0;
            let mut every = Decimator::new(steps, 2, 40);
            let mut once = Decimator::new(steps, 2, 40);
            for k in 1..=steps {
                let row = [constant, value(k)];
                every.begin(k as f64);
                every.put_row(0, &row);
                every.end(k);
                once.begin(k as f64);
                if once.bucket_starts() {
                    once.put_row(0, &row);
                } else {
                    once.put_row(1, &row[1..]);
                }
                once.end(k);
            }
            assert!(every.bucket_steps() > 1);
            assert_eq!(
                format!("{:?}", every.columns),
                format!("{:?}", once.columns)
            );
            assert_eq!(every.t, once.t);
        }
    }

    #[test]
    fn zero_rows_records_nothing() {
        let d = run(&[1.0, 2.0, 3.0], 0);
        assert!(d.t.is_empty() && d.columns[0].is_empty());
    }

    #[test]
    fn short_runs_are_not_decimated() {
        let v = [3.0, 1.0, 2.0];
        let d = run(&v, 10);
        assert_eq!(d.bucket_steps(), 1);
        let col: Vec<f64> = d.columns[0].iter().map(|x| x.unwrap()).collect();
        assert_eq!(col, v.to_vec());
    }

    #[test]
    fn every_bucket_extreme_matches_brute_force() {
        // pseudo-random walk, compare each bucket's min/max with a direct scan
        let mut x = 0.0f64;
        let v: Vec<f64> = (0..10_007u64)
            .map(|k| {
                x += ((k * 2_654_435_761) % 1000) as f64 / 500.0 - 1.0;
                x
            })
            .collect();
        let d = run(&v, 200);
        let b = d.bucket_steps() as usize;
        let col: Vec<f64> = d.columns[0].iter().map(|x| x.unwrap()).collect();
        for (i, chunk) in v.chunks(b).enumerate() {
            let mn = chunk.iter().cloned().fold(f64::MAX, f64::min);
            let mx = chunk.iter().cloned().fold(f64::MIN, f64::max);
            let (a, c) = (col[2 * i], col[2 * i + 1]);
            assert_eq!(a.min(c), mn);
            assert_eq!(a.max(c), mx);
        }
    }
}
