//! A Monte Carlo with a truth (a mismatched filter): the sample variance of the
//! filtered error, about its sample mean, judged step by step against the actual error
//! variance of the mismatch's recursion ([`crate::analysis::mismatch`]), as the plain
//! Monte Carlo judges it against R_ii. With R runs, (R − 1) s² / σ² ~ χ²_{R−1}: the
//! band of one step's ratio is χ²_{R−1} quantiles / (R − 1).

use super::bands::chi2_band;
use super::result::{StateVerdict, Verdict};

/// Per state: the running sums of the ratio s² / σ²_actual and of the normalised bias,
/// and the actual SKO and bias at the last step.
pub(super) struct ActualSums {
    ratio_sum: Vec<f64>,
    count: Vec<u64>,
    inside: Vec<u64>,
    bias_sum: Vec<f64>,
    band: [f64; 2],
    /// (actual SKO, actual bias) at step D.
    pub(super) last: Vec<(f64, f64)>,
}

impl ActualSums {
    /// Sums for `n` states (0 without a truth) of a Monte Carlo of `runs` runs.
    pub(super) fn new(n: usize, runs: f64) -> Self {
        ActualSums {
            ratio_sum: vec![0.0; n],
            count: vec![0; n],
            inside: vec![0; n],
            bias_sum: vec![0.0; n],
            band: chi2_band(runs - 1.0, runs - 1.0),
            last: vec![(0.0, 0.0); n],
        }
    }

    /// State i at one step: the sample variance `sample_var` (about the sample mean)
    /// and sample mean `sample_mean` of the filtered error, against the actual
    /// variance and bias.
    pub(super) fn add(&mut self, i: usize, sample_var: f64, sample_mean: f64, var: f64, bias: f64) {
        if var > 0.0 {
            let ratio = sample_var / var;
            self.ratio_sum[i] += ratio;
            self.count[i] += 1;
            if ratio >= self.band[0] && ratio <= self.band[1] {
                self.inside[i] += 1;
            }
            self.bias_sum[i] += (sample_mean - bias) / var.sqrt();
        }
    }

    /// The verdict per state (none without a truth).
    pub(super) fn verdicts(&self, states: &[String]) -> Option<Vec<StateVerdict>> {
        if self.count.is_empty() {
            return None;
        }
        let per = |sum: f64, c: u64| (c > 0).then(|| sum / c as f64);
        Some(
            states
                .iter()
                .enumerate()
                .map(|(i, state)| {
                    let ratio = per(self.ratio_sum[i], self.count[i]);
                    StateVerdict {
                        state: state.clone(),
                        variance_ratio: ratio,
                        band: self.band,
                        fraction_in_band: per(self.inside[i] as f64, self.count[i]),
                        normalised_bias: per(self.bias_sum[i], self.count[i]),
                        verdict: Verdict::of(ratio, self.band),
                    }
                })
                .collect(),
        )
    }
}
