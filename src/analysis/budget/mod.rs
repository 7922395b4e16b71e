//! The error budget: of each state's filtered (potential) and open-loop variance, the
//! part each error source causes — each initial SKO η0_i, each model-error source F_l
//! (a group of them where W correlates them) and each measurement-error source Φ_m
//! (likewise V).
//!
//! With the optimal filter's gains p_k held fixed, the Joseph form (METHOD §1.3)
//!
//! ```text
//! R_k = h_k (A R_{k−1} Aᵀ + B) h_kᵀ + p_k Rv p_kᵀ,   h_k = I − p_k C      (2.1), (2.7)
//! ```
//!
//! is linear in (R_0, B, Rv), and so is the open-loop P^Y_k = A P^Y Aᵀ + B (§1.5).
//! Split R_0 = Σ_i η0_i² e_i e_iᵀ, B = Σ_G bΔt_G W_GG bΔt_Gᵀ and
//! Rv = Σ_G Γ_G V_GG Γ_Gᵀ over the sources; one recursion per source, from its own
//! part alone, gives its part R^s_k, and Σ_s R^s_k = R_k (to rounding: the filter's
//! own R_k is a different sum of the same terms). The gains come from the filter's own
//! step ([`crate::numerics::riccati::SequentialJoseph`], the one Riccati), run again beside the sources — so the
//! analysis's loop is not touched, and the budget costs nothing when not asked for.
//!
//! A source's share of a state's variance is R^s_ii / Σ_s R^s_ii, at t_D and averaged
//! over the steps (the share of Σ_k R_ii: the share of the time-averaged variance).

use crate::error::Error;
use crate::model::compile::{CompiledModel, MeasurementNoise};
use crate::numerics::lanes::Lanes;
use crate::progress::Progress;
use serde::{Deserialize, Serialize};

mod pass;

/// The error budget of an analysis (`"budget": true`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Budget {
    /// The error sources, in the order of every `share` list.
    pub sources: Vec<BudgetSource>,
    /// Per state, each source's share of its variances.
    pub states: Vec<StateBudget>,
}

/// One error source (or a group that W or V correlates).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BudgetSource {
    /// The model member that sets its level: `eta0[D_f]` (the initial SKO of state
    /// D_f), `phi[0]` (model-error source 0), `psi[1]` (measurement-error source 1);
    /// `phi[0,1]` for sources W correlates (they cannot be told apart).
    pub name: String,
    /// `initial`, `model_error` or `measurement_error`.
    pub kind: SourceKind,
    /// The one state (b's column) or measurement (Γ's column) it enters, when there is
    /// exactly one and b or Γ does not vary in t.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub enters: Option<String>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SourceKind {
    Initial,
    ModelError,
    MeasurementError,
}

/// A state's budget: of its filtered (potential) variance R_ii and its open-loop
/// variance P^Y_ii.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StateBudget {
    pub state: String,
    pub potential: Shares,
    pub open_loop: Shares,
}

/// A variance split over the sources: at t_D and averaged over the steps 1..D.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Shares {
    /// Σ_s of the sources' parts at t_D: the variance (to rounding).
    pub final_variance: f64,
    /// Each source's part / final_variance (null where the variance is 0).
    pub final_share: Vec<Option<f64>>,
    /// The variance averaged over the steps.
    pub mean_variance: f64,
    /// Each source's part of it.
    pub mean_share: Vec<Option<f64>>,
}

/// Where one source's level enters the model.
#[derive(Clone, Debug)]
enum Level {
    /// R_0 = η0_i² e_i e_iᵀ.
    Initial(usize),
    /// B = bΔt_G W_GG bΔt_Gᵀ over b's columns G.
    Model(Vec<usize>),
    /// Rv = Γ_G V_GG Γ_Gᵀ over Γ's columns G.
    Measurement(Vec<usize>),
}

/// The sources of a model: every state's η0, then W's and V's groups (indices joined
/// where an off-diagonal entry is not 0), in index order.
fn levels(m: &CompiledModel) -> Vec<Level> {
    let n = m.n_states();
    let mut out: Vec<Level> = (0..n).map(Level::Initial).collect();
    out.extend(groups(&m.w, m.phi.len()).into_iter().map(Level::Model));
    out.extend(
        groups(&m.v, m.psi.len())
            .into_iter()
            .map(Level::Measurement),
    );
    out
}

/// The connected index sets of a symmetric k×k matrix's off-diagonal non-zeros.
fn groups(cov: &[f64], k: usize) -> Vec<Vec<usize>> {
    let mut group: Vec<usize> = (0..k).collect();
    fn root(g: &mut [usize], mut i: usize) -> usize {
        while g[i] != i {
            g[i] = g[g[i]];
            i = g[i];
        }
        i
    }
    for i in 0..k {
        for j in i + 1..k {
            if cov[i * k + j] != 0.0 || cov[j * k + i] != 0.0 {
                let (a, b) = (root(&mut group, i), root(&mut group, j));
                group[a.max(b)] = a.min(b);
            }
        }
    }
    let mut out: Vec<Vec<usize>> = Vec::new();
    let mut at = vec![usize::MAX; k];
    for i in 0..k {
        let r = root(&mut group, i);
        if at[r] == usize::MAX {
            at[r] = out.len();
            out.push(Vec::new());
        }
        out[at[r]].push(i);
    }
    out
}

fn describe(m: &CompiledModel, level: &Level) -> BudgetSource {
    let joined = |g: &[usize]| {
        g.iter()
            .map(|i| i.to_string())
            .collect::<Vec<_>>()
            .join(",")
    };
    // The one row with a non-zero in column `col` of a constant (rows × cols) matrix.
    let single = |values: &[f64], cols: usize, col: usize, names: &[String]| {
        let mut rows = (0..names.len()).filter(|&r| values[r * cols + col] != 0.0);
        match (rows.next(), rows.next()) {
            (Some(r), None) => Some(names[r].clone()),
            _ => None,
        }
    };
    match level {
        Level::Initial(i) => BudgetSource {
            name: format!("eta0[{}]", m.states[*i]),
            kind: SourceKind::Initial,
            enters: Some(m.states[*i].clone()),
        },
        Level::Model(g) => BudgetSource {
            name: format!("phi[{}]", joined(g)),
            kind: SourceKind::ModelError,
            enters: (g.len() == 1 && m.b.is_constant())
                .then(|| single(&m.b.values, m.b.cols, g[0], &m.states))
                .flatten(),
        },
        Level::Measurement(g) => {
            let gamma = match &m.noise {
                MeasurementNoise::Gamma(t) => t,
                MeasurementNoise::SeedG(_) => return measurement_source(g, None),
            };
            let enters = (g.len() == 1 && gamma.is_constant())
                .then(|| single(&gamma.values, gamma.cols, g[0], &m.measurements))
                .flatten();
            measurement_source(g, enters)
        }
    }
}

fn measurement_source(g: &[usize], enters: Option<String>) -> BudgetSource {
    let joined = g
        .iter()
        .map(|i| i.to_string())
        .collect::<Vec<_>>()
        .join(",");
    BudgetSource {
        name: format!("psi[{joined}]"),
        kind: SourceKind::MeasurementError,
        enters,
    }
}

/// The number of sources of a model's budget (for its work estimate).
pub fn source_count(m: &CompiledModel) -> usize {
    levels(m).len()
}

/// One source's recursion: its parts of R_k and P^Y_k and their running sums.
struct Part {
    level: Level,
    r: Vec<f64>,
    /// None for a measurement-error source (its open-loop part is 0).
    p_y: Option<Vec<f64>>,
    /// Its B (model-error sources), else zeros.
    big_b: Vec<f64>,
    sum_r: Vec<f64>,
    sum_p: Vec<f64>,
}

/// The error budget of `m`'s analysis over `steps` steps; `frozen_at`: the step from
/// which the analysis's steady-state shortcut held R and the gains (its
/// `steady_state`, when `shortcut_used`): the gains are held from there too. Errors are
/// placed in the request (`model.…`; `budget` for a filter step that failed here).
pub fn run(
    m: &CompiledModel,
    steps: u64,
    frozen_at: Option<u64>,
    progress: &mut dyn Progress,
) -> Result<Budget, Error> {
    let n = m.n_states();
    let mut parts: Vec<Part> = levels(m)
        .into_iter()
        .map(|level| {
            let mut r = vec![0.0; n * n];
            if let Level::Initial(i) = level {
                r[i * n + i] = m.eta0[i] * m.eta0[i];
            }
            let p_y = (!matches!(level, Level::Measurement(_))).then(|| r.clone());
            Part {
                level,
                r,
                p_y,
                big_b: vec![0.0; n * n],
                sum_r: vec![0.0; n],
                sum_p: vec![0.0; n],
            }
        })
        .collect();
    dispatch(m, steps, frozen_at, &mut parts, progress)?;

    let sources = parts.iter().map(|p| describe(m, &p.level)).collect();
    let states = (0..n)
        .map(|i| {
            let fin_r: Vec<f64> = parts.iter().map(|p| p.r[i * n + i]).collect();
            let mean_r: Vec<f64> = parts.iter().map(|p| p.sum_r[i] / steps as f64).collect();
            let fin_p: Vec<f64> = parts
                .iter()
                .map(|p| p.p_y.as_ref().map_or(0.0, |p| p[i * n + i]))
                .collect();
            let mean_p: Vec<f64> = parts.iter().map(|p| p.sum_p[i] / steps as f64).collect();
            StateBudget {
                state: m.states[i].clone(),
                potential: shares(&fin_r, &mean_r),
                open_loop: shares(&fin_p, &mean_p),
            }
        })
        .collect();
    Ok(Budget { sources, states })
}

/// The pass in AVX2 + FMA where the analysis's build ([`crate::analysis::build`]) is
/// AVX2 or wider, else portable (the same bits either way).
fn dispatch(
    m: &CompiledModel,
    steps: u64,
    frozen_at: Option<u64>,
    parts: &mut [Part],
    progress: &mut dyn Progress,
) -> Result<(), Error> {
    #[cfg(target_arch = "x86_64")]
    if crate::analysis::build() != crate::analysis::Build::Baseline {
        #[target_feature(enable = "avx2,fma")]
        fn avx2(
            m: &CompiledModel,
            steps: u64,
            frozen_at: Option<u64>,
            parts: &mut [Part],
            progress: &mut dyn Progress,
        ) -> Result<(), Error> {
            sized::<crate::numerics::lanes::Avx2>(m, steps, frozen_at, parts, progress)
        }
        // SAFETY: `build` chose AVX2 + FMA (or wider) only where the CPU has them.
        return unsafe { avx2(m, steps, frozen_at, parts, progress) };
    }
    sized::<crate::numerics::lanes::Scalar>(m, steps, frozen_at, parts, progress)
}

/// The pass compiled for the model's state dimension (1..=12, else runtime-sized).
#[inline(always)]
fn sized<L: Lanes>(
    m: &CompiledModel,
    steps: u64,
    frozen_at: Option<u64>,
    parts: &mut [Part],
    progress: &mut dyn Progress,
) -> Result<(), Error> {
    let (s, f, p) = (steps, frozen_at, progress);
    match m.n_states() {
        1 => pass::run::<1, L>(m, s, f, parts, p),
        2 => pass::run::<2, L>(m, s, f, parts, p),
        3 => pass::run::<3, L>(m, s, f, parts, p),
        4 => pass::run::<4, L>(m, s, f, parts, p),
        5 => pass::run::<5, L>(m, s, f, parts, p),
        6 => pass::run::<6, L>(m, s, f, parts, p),
        7 => pass::run::<7, L>(m, s, f, parts, p),
        8 => pass::run::<8, L>(m, s, f, parts, p),
        9 => pass::run::<9, L>(m, s, f, parts, p),
        10 => pass::run::<10, L>(m, s, f, parts, p),
        11 => pass::run::<11, L>(m, s, f, parts, p),
        12 => pass::run::<12, L>(m, s, f, parts, p),
        _ => pass::run::<0, L>(m, s, f, parts, p),
    }
}

fn shares(fin: &[f64], mean: &[f64]) -> Shares {
    let split = |v: &[f64]| {
        let total: f64 = v.iter().sum();
        let share = v.iter().map(|x| (total > 0.0).then(|| x / total)).collect();
        (total, share)
    };
    let (final_variance, final_share) = split(fin);
    let (mean_variance, mean_share) = split(mean);
    Shares {
        final_variance,
        final_share,
        mean_variance,
        mean_share,
    }
}

/// The filter's step failed where the analysis's did not (it cannot: the same step
/// on the same inputs).
#[cold]
fn lost(k: u64, t: f64) -> Error {
    Error::Numerical {
        step: k,
        t,
        path: "budget".into(),
        message: "the budget's run of the filter's covariance recursion failed where the analysis's did not".into(),
    }
}

/// Units of one budget step: the filter's step again, and per source a prediction,
/// h r hᵀ (1.5 N³) and its open-loop prediction.
pub fn step_units(n: usize, nm: usize, sources: usize) -> f64 {
    let (n, nm) = (n as f64, nm as f64);
    crate::analysis::work::step_cost(n as usize)
        + sources as f64 * (2.0 * n * n * n + 4.0 * n * n + nm * n + 50.0)
}

/// The budget's work: D (for `"auto"` the cap) × its step, which runs the filter's
/// step again and one recursion per source — the work grows with the number of
/// sources. Its units and how they were computed.
pub fn work(compiled: &CompiledModel) -> (f64, String) {
    let (n, nm) = (compiled.n_states(), compiled.n_measurements());
    let sources = source_count(compiled);
    let step = step_units(n, nm, sources);
    let steps = compiled.max_steps();
    (
        steps as f64 * step,
        format!("D = {steps} steps × {step:.0} ({sources} sources)"),
    )
}
