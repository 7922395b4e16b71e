//! The nonlinear run (METHOD §4): the procedure's K filters, the plain EKF and the
//! Q-scale EKFs in one [`Bank`] over the data, then the choice of the iterate.
//! Memory does not grow with D beyond the data: the sums, the checkpoints and the
//! decimated traces are kept as the steps go.

use super::bank::{Bank, Design};
use super::gamma::{gamma, weights};
use super::request::{NonlinearRequest, Source};
use super::result::{Checkpoint, NonlinearResult, QScale, ScalePoint, Snapshot, Summary, Traces};
use crate::error::Error;
use crate::progress::{Progress, steps_between_reports};
use std::borrow::Cow;
use std::ops::ControlFlow;

/// Run `r`.
pub fn run(r: &NonlinearRequest, progress: &mut dyn Progress) -> Result<NonlinearResult, Error> {
    let data = match &r.source {
        Source::Truth(t) => Cow::Owned(super::truth::simulate(t, "data.truth")?),
        _ => Cow::Borrowed(&r.data),
    };
    let model = &r.model;
    let (n, m, d) = (model.n_states(), model.n_measurements(), model.steps);
    let k = r.alpha.len();
    let g = gamma(&r.alpha);
    let w = weights(&g);
    let mut designs: Vec<Design> = (0..k)
        .map(|i| Design {
            label: format!("iterate {}", i + 1),
            q: 1.0,
            r: 1.0 / g[i][i],
            couplings: (0..i).map(|c| (c, w[i][c])).collect(),
        })
        .collect();
    // The uncoupled EKFs (the plain one, each Q scale): one filter of the bank per
    // distinct design — with α_0 = 1 iterate 1 *is* the plain EKF, and a scale of 1 too.
    let mut uncoupled = |q: f64, label: String| {
        let same = |d: &Design| d.q == q && d.r == 1.0 && d.couplings.is_empty();
        match designs.iter().position(same) {
            Some(i) => i,
            None => {
                designs.push(Design {
                    label,
                    q,
                    r: 1.0,
                    couplings: Vec::new(),
                });
                designs.len() - 1
            }
        }
    };
    let ekf = uncoupled(1.0, "the EKF".into());
    let scaled: Vec<usize> = r
        .q_scales
        .iter()
        .map(|&s| uncoupled(s, format!("the EKF with W × {}", crate::text::short(s))))
        .collect();
    let filters = designs.len();
    let mut bank = Bank::new(model, designs, r.residuals);

    let truth = data.truth.as_deref();
    // Per filter and state: Σ e⁺², Σ e⁻², count.
    let mut err_post = vec![0.0; filters * n];
    let mut err_prior = vec![0.0; filters * n];
    let mut err_count = vec![0u64; n];

    let stride = if r.trace_points == 0 {
        usize::MAX
    } else {
        d.div_ceil(r.trace_points).max(1)
    };
    let mut trace = Recorder::new(filters, n, m, truth.is_some(), k, ekf);
    if r.trace_points > 0 {
        trace.record(&bank, 0, model.t0, &[], truth.map(|t| &t[..n]), k);
    }
    let mut checkpoints = Vec::with_capacity(r.checkpoints.len());
    let mut next_checkpoint = 0;

    let between = steps_between_reports(super::work::per_step(r));
    for step in 1..=d {
        let (t_prev, t) = (model.t(step - 1), model.t(step));
        let y = &data.y[(step - 1) * m..step * m];
        bank.step(step as u64, t_prev, t, y)
            .map_err(|e| e.with_prefix("model"))?;
        if let Some(truth) = truth {
            let xt = &truth[step * n..(step + 1) * n];
            for (i, &x) in xt.iter().enumerate() {
                if x.is_nan() {
                    continue;
                }
                err_count[i] += 1;
                for (f, filter) in bank.filters.iter().enumerate() {
                    let e = filter.x[i] - x;
                    let ep = filter.x_prior[i] - x;
                    err_post[f * n + i] += e * e;
                    err_prior[f * n + i] += ep * ep;
                }
            }
        }
        if next_checkpoint < r.checkpoints.len() && r.checkpoints[next_checkpoint] == step {
            next_checkpoint += 1;
            let snap = |f: usize, i: Option<usize>| {
                let filter = &bank.filters[f];
                Snapshot {
                    i,
                    prior: filter.x_prior.clone(),
                    posterior: filter.x.clone(),
                    p_posterior: filter.p.chunks(n).map(<[f64]>::to_vec).collect(),
                }
            };
            checkpoints.push(Checkpoint {
                n: step,
                t,
                ekf: snap(ekf, None),
                iterates: (0..k).map(|i| snap(i, Some(i + 1))).collect(),
            });
        }
        if step % stride == 0 || (step == d && r.trace_points > 0) {
            trace.record(
                &bank,
                step,
                t,
                y,
                truth.map(|tr| &tr[step * n..(step + 1) * n]),
                k,
            );
        }
        if (step as u64).is_multiple_of(between)
            && let ControlFlow::Break(()) = progress.report(step as f64 / d as f64)
        {
            return Err(Error::Cancelled);
        }
    }

    let summary = |f: usize, i: Option<usize>| {
        let filter = &bank.filters[f];
        let count: u64 = bank.measured.iter().sum();
        let mean = |sums: &[f64]| {
            if count == 0 {
                f64::NAN
            } else {
                sums.iter().sum::<f64>() / count as f64
            }
        };
        let by = filter
            .sum_prior
            .iter()
            .zip(&bank.measured)
            .map(|(s, &c)| (c > 0).then(|| s / c as f64))
            .collect();
        let rms = |sums: &[f64]| {
            truth.map(|_| {
                (0..n)
                    .map(|i| {
                        (err_count[i] > 0).then(|| (sums[f * n + i] / err_count[i] as f64).sqrt())
                    })
                    .collect()
            })
        };
        Summary {
            i,
            delta: mean(&filter.sum_prior),
            delta_posterior: mean(&filter.sum_posterior),
            delta_by_measurement: by,
            rms: rms(&err_post),
            rms_prior: rms(&err_prior),
        }
    };
    if bank.measured.iter().all(|&c| c == 0) {
        return Err(Error::invalid(
            "data",
            "no measurement in the data: the filters have nothing to choose by",
        ));
    }
    let iterates: Vec<Summary> = (0..k).map(|i| summary(i, Some(i + 1))).collect();
    let i_star = argmin(iterates.iter().map(|s| s.delta)).unwrap_or(0) + 1;
    let i_star_posterior = argmin(iterates.iter().map(|s| s.delta_posterior)).unwrap_or(0) + 1;
    let i_stop_first_increase = (1..k)
        .find(|&i| iterates[i].delta > iterates[i - 1].delta)
        .unwrap_or(k);
    let best_rms = least_rms(&iterates, n, truth.is_some())
        .map(|v| v.into_iter().map(|i| i.map(|i| i + 1)).collect());
    let grid: Vec<ScalePoint> = r
        .q_scales
        .iter()
        .enumerate()
        .map(|(j, &scale)| ScalePoint {
            scale,
            summary: summary(scaled[j], None),
        })
        .collect();
    let chosen = argmin(grid.iter().map(|p| p.summary.delta));
    let grid_summaries: Vec<Summary> = grid.iter().map(|p| p.summary.clone()).collect();
    let q_best = least_rms(&grid_summaries, n, truth.is_some() && !grid.is_empty());
    let traces = trace.finish(chosen.map(|c| scaled[c]), k);
    let r_diag: Vec<Vec<f64>> = (0..k)
        .map(|i| (0..m).map(|j| model.v[j * m + j] / g[i][i]).collect())
        .collect();
    Ok(NonlinearResult {
        states: model.states.clone(),
        measurements: model.names.clone(),
        steps: d,
        dt: model.dt,
        alpha: r.alpha.clone(),
        gamma: g,
        weights: w,
        r: r_diag,
        earlier_residuals: r.residuals,
        iterates,
        i_star,
        i_stop_first_increase,
        i_star_posterior,
        best_rms,
        ekf: summary(ekf, None),
        q_scale: QScale {
            grid,
            chosen,
            best_rms: q_best,
        },
        checkpoints,
        traces,
        ignored_columns: data.ignored.clone(),
        measured: bank.measured.clone(),
        timing: Default::default(),
    })
}

/// The index of the least finite value.
fn argmin(v: impl Iterator<Item = f64>) -> Option<usize> {
    let mut best: Option<(usize, f64)> = None;
    for (i, x) in v.enumerate() {
        if x.is_finite() && best.is_none_or(|(_, b)| x < b) {
            best = Some((i, x));
        }
    }
    best.map(|(i, _)| i)
}

/// Per state, the index into `list` of the least RMS (with a truth).
fn least_rms(list: &[Summary], n: usize, truth: bool) -> Option<Vec<Option<usize>>> {
    truth.then(|| {
        (0..n)
            .map(|i| {
                argmin(
                    list.iter()
                        .map(|s| s.rms.as_ref().and_then(|r| r[i]).unwrap_or(f64::NAN)),
                )
            })
            .collect()
    })
}

/// The decimated traces, kept for every filter of the bank as the steps go (the
/// Q-scale EKF's are chosen at the end).
struct Recorder {
    n: usize,
    m: usize,
    ekf: usize,
    traces: Traces,
    /// [filter][state][point].
    estimates: Vec<Vec<Vec<f64>>>,
}

impl Recorder {
    fn new(filters: usize, n: usize, m: usize, truth: bool, k: usize, ekf: usize) -> Recorder {
        Recorder {
            n,
            m,
            ekf,
            traces: Traces {
                measurements: vec![Vec::new(); m],
                truth: truth.then(|| vec![Vec::new(); n]),
                ekf_sko: vec![Vec::new(); n],
                iterate_1_sko: vec![Vec::new(); n],
                residuals: vec![vec![Vec::new(); m]; k],
                ..Traces::default()
            },
            estimates: vec![vec![Vec::new(); n]; filters],
        }
    }

    fn record(
        &mut self,
        bank: &Bank,
        step: usize,
        t: f64,
        y: &[f64],
        truth: Option<&[f64]>,
        k: usize,
    ) {
        let tr = &mut self.traces;
        tr.n.push(step);
        tr.t.push(t);
        for j in 0..self.m {
            tr.measurements[j].push(y.get(j).copied().filter(|v| v.is_finite()));
        }
        if let (Some(out), Some(x)) = (&mut tr.truth, truth) {
            for i in 0..self.n {
                out[i].push(Some(x[i]).filter(|v| !v.is_nan()));
            }
        }
        for (f, filter) in bank.filters.iter().enumerate() {
            for i in 0..self.n {
                self.estimates[f][i].push(filter.x[i]);
            }
        }
        let sko = |f: usize, i: usize| bank.filters[f].p[i * self.n + i].max(0.0).sqrt();
        for i in 0..self.n {
            tr.ekf_sko[i].push(sko(self.ekf, i));
            tr.iterate_1_sko[i].push(sko(0, i));
        }
        for (f, filter) in bank.filters.iter().take(k).enumerate() {
            for j in 0..self.m {
                let r = if step == 0 {
                    f64::NAN
                } else {
                    filter.residual_prior[j]
                };
                tr.residuals[f][j].push(Some(r).filter(|v| v.is_finite()));
            }
        }
    }

    fn finish(mut self, chosen: Option<usize>, k: usize) -> Traces {
        // (Cloned: the EKF and a Q-scaled one may be an iterate's filter.)
        self.traces.q_scaled = chosen.map(|c| self.estimates[c].clone());
        self.traces.ekf = self.estimates[self.ekf].clone();
        self.estimates.truncate(k);
        self.traces.iterates = self.estimates;
        self.traces
    }
}
