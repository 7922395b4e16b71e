//! The traces: the layout of a step's row (its series and its criteria ratios (3.23)),
//! the row's way into the running sums (3.24) and the decimated traces, and the traces
//! assembled at the end (relative errors (3.20), local criteria (3.23)).

use super::criteria::Running;
use crate::analysis::result::{StateTrace, Traces};
use crate::model::compile::CompiledModel;
use crate::numerics::decimate::Decimator;

/// Series kept in the traces for every state (in this order; a step's row holds
/// series s of state i at s · n + i). The first three are constant once the Riccati
/// recursion is frozen (the shortcut), the last three are the bound set's ratios —
/// followed in the row by the covariance set's, so the six criteria are contiguous.
pub(crate) const SERIES: usize = 10;
const S_ZETA: usize = 0;
const S_POT: usize = 1;
const S_MEAS: usize = 2;
/// The series from here on change every step.
const S_Y: usize = 3;
const S_ETA: usize = 4;
const S_CHI: usize = 5;
const S_OPEN: usize = 6;
const S_RYZ: usize = 7;
const S_RZX: usize = 8;
const S_RYX: usize = 9;

/// A step whose row is written (its trace values and criteria ratios) and how.
#[derive(Clone, Copy, Debug, serde::Serialize, serde::Deserialize)]
pub(super) struct Written {
    pub(super) k: u64,
    #[serde(with = "crate::resume::f64_bits")]
    pub(super) t: f64,
    pub(super) bound_ok: bool,
    pub(super) open_ok: bool,
    /// The row's constant series were written at this step.
    pub(super) constants: bool,
}

/// Adds a written row to the criteria's sums (with the `part` it was written for)
/// and to the traces.
#[inline(always)]
pub(super) fn take_row(
    row: &mut [f64],
    part: &[u64],
    running: &mut Running,
    dec: &mut Decimator,
    n: usize,
    w: Written,
) {
    running.add(&row[S_RYZ * n..], part);
    // Series without a value at this step (after the sums: their parts are 0).
    if !w.bound_ok {
        for s in [S_ETA, S_CHI, S_RYZ, S_RZX, S_RYX] {
            row[s * n..s * n + n].fill(f64::NAN);
        }
    }
    if !w.open_ok {
        row[S_OPEN * n..S_OPEN * n + n].fill(f64::NAN);
    }
    dec.begin(w.t);
    if w.constants || dec.bucket_starts() {
        dec.put_row(0, &row[..SERIES * n]);
    } else {
        dec.put_row(S_Y * n, &row[S_Y * n..SERIES * n]);
    }
    dec.end(w.k);
}

pub(super) fn build_traces(
    m: &CompiledModel,
    dec: Decimator,
    y_max: &[f64],
    z_max: &[f64],
    warnings: &mut Vec<String>,
) -> Traces {
    let n = m.n_states();
    let bucket_steps = dec.bucket_steps();
    let Decimator { t, mut columns, .. } = dec;
    let mut take = |i: usize, s: usize| std::mem::take(&mut columns[s * n + i]);
    // y always has a value (a mean that overflows stops the run); every other series
    // is null where it has none (an overflowed bound, an unavailable measurement), and
    // never a stand-in 0.
    let plain = |v: Vec<Option<f64>>| {
        v.into_iter()
            .map(|x| x.unwrap_or(f64::NAN))
            .collect::<Vec<f64>>()
    };
    // Relative errors and local criteria are values over y_B and z_B: with extreme
    // scales (y_B = 1e-300) they can overflow f64; null then, counted for a warning.
    let overflowed = std::cell::Cell::new(0u64);
    let finite = |x: f64| {
        if x.is_finite() {
            Some(x)
        } else {
            overflowed.set(overflowed.get() + 1);
            None
        }
    };
    let scale_opt = |v: Vec<Option<f64>>, f: Option<f64>| -> Vec<Option<f64>> {
        v.into_iter()
            .map(|x| x.zip(f).and_then(|(x, f)| finite(x * f)))
            .collect()
    };
    let mut states = Vec::with_capacity(n);
    let mut overflowing_states = Vec::new();
    for i in 0..n {
        overflowed.set(0);
        let yb = y_max[i];
        let pair = m.pair_of_state[i];
        let zb = pair.map(|j| z_max[j]);
        let y = plain(take(i, S_Y));
        let eta = take(i, S_ETA);
        let chi = take(i, S_CHI);
        let zeta = pair.map(|_| take(i, S_ZETA));
        let measured = pair.map(|_| take(i, S_MEAS));
        let yb_ok = (yb > 0.0).then_some(yb);
        let zb_ok = zb.filter(|z| *z > 0.0);
        let rel = |v: &[Option<f64>], b: Option<f64>| -> Vec<Option<f64>> {
            v.iter()
                .map(|x| x.zip(b).and_then(|(x, b)| finite(x / b)))
                .collect()
        };
        let local_yz =
            pair.map(|_| scale_opt(take(i, S_RYZ), zb_ok.zip(yb_ok).map(|(z, y)| z / y)));
        let local_zx =
            pair.map(|_| scale_opt(take(i, S_RZX), zb_ok.zip(yb_ok).map(|(z, y)| y / z)));
        let local_yx = scale_opt(take(i, S_RYX), yb_ok.map(|_| 1.0));
        states.push(StateTrace {
            state: m.states[i].clone(),
            rel_y: rel(&eta, yb_ok),
            rel_x: rel(&chi, yb_ok),
            rel_z: zeta.as_ref().map(|z| rel(z, zb_ok)),
            y,
            eta,
            zeta,
            chi,
            potential_sko: take(i, S_POT),
            open_loop_sko: take(i, S_OPEN),
            measured_sko: measured,
            local_yz,
            local_zx,
            local_yx,
        });
        if overflowed.get() > 0 {
            overflowing_states.push(format!("\"{}\" ({} values)", m.states[i], overflowed.get()));
        }
    }
    if !overflowing_states.is_empty() {
        warnings.push(format!(
            "trace values of {} overflowed f64 and are null: relative errors (3.20) and local criteria (3.23) are ratios to y_B and z_B, which this model's scales (y_B or z_B tiny against the SKOs, or far apart) put beyond 1.8e308",
            overflowing_states.join(", ")
        ));
    }
    Traces {
        bucket_steps,
        t,
        states,
    }
}
