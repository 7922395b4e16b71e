//! An analysis interrupted after any progress report and resumed from the state it
//! kept there ends with the result of an uninterrupted run, bit for bit (but for its
//! timing): over the filter's transient and the frozen steady state, with a bound that
//! overflows on the way, measurement schedules and a time-varying a(t) and Γ(t), with
//! fixed-size and runtime-size loops. So does a Monte Carlo, interrupted in its
//! analysis or between its chunks of steps. A state that does not belong to the run is
//! ignored.

mod common;

use kea_core::analysis::{SELECTION_KEY, STATE_KEY};
use kea_core::analysis::{run, run_resumable};
use kea_core::exec::{Forgetful, Memo, Sequential};
use kea_core::model::compile::{CompiledModel, compile};
use kea_core::monte_carlo::STATE_KEY as MONTE_CARLO_KEY;
use kea_core::monte_carlo::{ModelError, MonteCarloRequest, Truth, simulate_resumable};
use kea_core::{Error, NoProgress, Overrides, Progress, model_from_value};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde_json::{Value, json};
use std::collections::HashMap;
use std::ops::ControlFlow;
use std::sync::Mutex;

/// Keeps the states at every report (under each key, the last one wins), and recalls
/// what it was given.
struct Keeper {
    given: HashMap<String, String>,
    kept: Mutex<HashMap<String, String>>,
    keep: bool,
}

impl Keeper {
    fn keeping() -> Keeper {
        Keeper {
            given: HashMap::new(),
            kept: Mutex::default(),
            keep: true,
        }
    }

    /// Recalling an analysis's state.
    fn recalling(state: String) -> Keeper {
        Keeper::recalling_all(HashMap::from([(STATE_KEY.to_string(), state)]))
    }

    fn recalling_all(states: HashMap<String, String>) -> Keeper {
        Keeper {
            given: states,
            kept: Mutex::default(),
            keep: false,
        }
    }
}

impl Memo for Keeper {
    fn recall(&self, key: &str) -> Option<String> {
        assert!(
            [STATE_KEY, MONTE_CARLO_KEY, SELECTION_KEY].contains(&key),
            "{key}"
        );
        self.given.get(key).cloned()
    }
    fn keep(&self, key: &str, value: &str) {
        assert_eq!(key, SELECTION_KEY, "a state kept as a part");
        let mut kept = self.kept.lock().unwrap();
        kept.insert(key.to_string(), value.to_string());
    }
    fn keep_state(&self, key: &str, value: &str) {
        assert!([STATE_KEY, MONTE_CARLO_KEY].contains(&key), "{key}");
        let mut kept = self.kept.lock().unwrap();
        kept.insert(key.to_string(), value.to_string());
    }
    fn state_due(&self) -> bool {
        self.keep
    }
}

/// A progress that stops the run at its `stop`-th report (a crash there).
fn stopping_at(stop: usize) -> impl Progress {
    let mut seen = 0;
    move |_: f64| {
        seen += 1;
        if seen == stop {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    }
}

/// The result's JSON without its timing.
fn untimed(r: &kea_core::analysis::result::AnalysisResult) -> Value {
    let mut v = serde_json::to_value(r).unwrap();
    v.as_object_mut().unwrap().remove("timing");
    v
}

fn compiled(model: Value) -> CompiledModel {
    compile(&model_from_value(model).unwrap(), &Default::default()).unwrap()
}

/// How many progress reports a run of `m` makes.
fn reports(m: &CompiledModel) -> usize {
    let mut count = 0;
    run(m, &mut |_: f64| {
        count += 1;
        ControlFlow::Continue(())
    })
    .unwrap();
    count
}

/// The run interrupted at its `stop`-th report (a crash there); the state it kept.
fn interrupted(m: &CompiledModel, stop: usize) -> String {
    let memo = Keeper::keeping();
    let r = run_resumable(m, &mut stopping_at(stop), &memo);
    assert!(
        matches!(r, Err(Error::Cancelled)),
        "interrupted at report {stop}"
    );
    let mut kept = memo.kept.into_inner().unwrap();
    kept.remove(STATE_KEY).expect("a state was kept")
}

/// Interrupted at several reports (the second, a middle one, the last) and resumed: the
/// uninterrupted result each time. Returns the steps the states were kept at.
fn resumes_exactly(model: Value) -> Vec<u64> {
    let m = compiled(model);
    let whole = untimed(&run(&m, &mut NoProgress).unwrap());
    let n = reports(&m);
    assert!(
        n >= 4,
        "the model reports {n} times: too few to interrupt it in between"
    );
    let mut at = Vec::new();
    // (The last report is the end's 100 %, after the loop: the one before is the
    // loop's last.)
    for stop in [3, n / 2, n - 1] {
        let state = interrupted(&m, stop);
        let k: Value = serde_json::from_str(&state).unwrap();
        at.push(k["k"].as_u64().unwrap());
        let resumed = run_resumable(&m, &mut NoProgress, &Keeper::recalling(state)).unwrap();
        assert_eq!(
            untimed(&resumed),
            whole,
            "resumed from the state of report {}",
            stop - 1
        );
    }
    at
}

fn tracker(steps: u64, t_end: f64) -> Value {
    json!({
        "params": {"q": 1.0, "r": 0.5},
        "time": {"t0": 0.0, "t_end": t_end, "steps": steps},
        "system": {"states": ["position", "velocity"], "a": [[0, 1], [0, 0]],
                   "b": [[0], [1]], "y0": [100, 10], "eta0": [10, 2], "phi": ["q"]},
        "measurement": {"names": ["z"], "c": [[1, 0]], "gamma": [[1]], "psi": ["r"]},
        "options": {"trace_points": 50}
    })
}

/// The tracker reaches its steady state early and freezes (the shortcut); over 10⁴ s
/// its bound overflows too (≈ 1.07 a step): states before and after both.
#[test]
fn a_frozen_run_with_an_overflowing_bound_resumes_exactly() {
    let at = resumes_exactly(tracker(200_000, 10_000.0));
    let m = compiled(tracker(200_000, 10_000.0));
    let r = run(&m, &mut NoProgress).unwrap();
    let frozen = r.steady_state.as_ref().unwrap().reached_at_step;
    assert!(r.steady_state.unwrap().shortcut_used);
    assert!(r.warnings.iter().any(|w| w.contains("overflowed at step")));
    assert!(
        at.iter().any(|&k| k > frozen),
        "a state after the freeze at {frozen}: {at:?}"
    );
}

/// a(t) and Γ(t) vary, two measurements on schedules (one every third step, one
/// unavailable for a while): Rv and the mask change as the run goes.
#[test]
fn a_time_varying_scheduled_run_resumes_exactly() {
    resumes_exactly(json!({
        "params": {"w": 2.0},
        "time": {"t0": 0.0, "t_end": 20.0, "steps": 60_000},
        "system": {"states": ["x", "v", "b"],
                   "a": [[0, 1, 0], ["-w*w*(1 + 0.1*sin(t))", "-0.2", 1], [0, 0, "-0.05"]],
                   "b": [[0, 0], [1, 0], [0, 1]], "y0": [1, 0, 0.5], "eta0": [1, 1, 0.3],
                   "phi": [0.5, 0.05]},
        "measurement": {"names": ["zx", "zv"], "c": [[1, 0, 1], [0, 1, 0]],
                        "gamma": [["1 + 0.5*cos(t)", 0], [0, 1]], "psi": [0.2, 0.3],
                        "schedule": [{"every": 3, "offset": 1}, {"unavailable": [[4, 9]]}]},
        "options": {"trace_points": 100, "steady_state_shortcut": false}
    }));
}

/// 14 states: the loop of runtime size (fixed sizes go to 12).
#[test]
fn a_runtime_size_run_resumes_exactly() {
    let n = 14;
    let a = common::chain_a(n, |_| json!(-0.5), json!(1.0));
    let c: Vec<Vec<f64>> = (0..2)
        .map(|r| (0..n).map(|j| if j == r { 1.0 } else { 0.0 }).collect())
        .collect();
    resumes_exactly(json!({
        "time": {"t0": 0.0, "t_end": 5.0, "steps": 20_000},
        "system": {"states": (0..n).map(|i| format!("x{i}")).collect::<Vec<_>>(), "a": a,
                   "b": vec![vec![1.0]; n], "y0": vec![1.0; n], "eta0": vec![1.0; n], "phi": [0.3]},
        "measurement": {"names": ["z0", "z1"], "c": c, "gamma": [[1, 0], [0, 1]], "psi": [0.1, 0.2]},
        "options": {"trace_points": 40}
    }));
}

/// A state of another run (fewer steps), or not a state at all, is not taken: the run
/// starts over and gives its own result.
#[test]
fn a_state_of_another_run_is_ignored() {
    let other = compiled(tracker(100_000, 10_000.0));
    let state = interrupted(&other, reports(&other) / 2);
    let m = compiled(tracker(200_000, 10_000.0));
    let whole = untimed(&run(&m, &mut NoProgress).unwrap());
    for given in [state, "{\"k\": 3}".to_string(), "not json".to_string()] {
        let r = run_resumable(&m, &mut NoProgress, &Keeper::recalling(given)).unwrap();
        assert_eq!(untimed(&r), whole);
    }
}

/// An unstable state (a = 5) whose mean stays 0: the open-loop covariance and the bound
/// overflow part way (their last values are carried on from there), the filter's not.
#[test]
fn a_run_whose_open_loop_covariance_overflows_resumes_exactly() {
    let model = json!({
        "time": {"t0": 0.0, "t_end": 100.0, "steps": 50_000},
        "system": {"states": ["x"], "a": [[5]], "b": [[1]], "y0": [0], "eta0": [1], "phi": [1]},
        "measurement": {"names": ["z"], "c": [[1]], "gamma": [[1]], "psi": [1]},
        "options": {"trace_points": 30, "steady_state_shortcut": false}
    });
    let r = run(&compiled(model.clone()), &mut NoProgress).unwrap();
    assert!(
        r.warnings
            .iter()
            .any(|w| w.contains("open-loop (a-priori) covariance overflowed")),
        "{:?}",
        r.warnings
    );
    resumes_exactly(model);
}

/// The Monte Carlo `req` of `model` interrupted at each report `stops` names, given
/// the number of the runs' first report and of all, and resumed from the states it
/// kept: the uninterrupted result each time. Returns the steps of the runs' states
/// (None: interrupted in the analysis).
fn simulates_exactly(
    model: Value,
    req: &MonteCarloRequest,
    stops: impl FnOnce(usize, usize) -> Vec<usize>,
) -> Vec<Option<u64>> {
    let model = model_from_value(model).unwrap();
    let set = Overrides::new();
    let sim = |progress: &mut dyn Progress, memo: &dyn Memo| {
        simulate_resumable(&model, &set, req, &Sequential, progress, memo)
    };
    let untimed = |r: &kea_core::monte_carlo::MonteCarloResult| {
        let mut v = serde_json::to_value(r).unwrap();
        v.as_object_mut().unwrap().remove("timing");
        v
    };
    let mut reports = Vec::new();
    let whole = sim(
        &mut |f: f64| {
            reports.push(f);
            ControlFlow::Continue(())
        },
        &Forgetful,
    )
    .unwrap();
    let whole = untimed(&whole);
    // The analysis reports the first 5 % (its last, 5 %, after its loop).
    let first_chunk = 1 + reports.iter().position(|&f| f > 0.05).unwrap();
    let mut at = Vec::new();
    for stop in stops(first_chunk, reports.len()) {
        let memo = Keeper::keeping();
        let r = sim(&mut stopping_at(stop), &memo);
        assert!(
            matches!(r, Err(Error::Cancelled)),
            "interrupted at report {stop}"
        );
        let kept = memo.kept.into_inner().unwrap();
        let k = kept.get(MONTE_CARLO_KEY).map(|s| {
            let s: Value = serde_json::from_str(s).unwrap();
            s["k"].as_u64().unwrap()
        });
        at.push(k);
        let resumed = sim(&mut NoProgress, &Keeper::recalling_all(kept)).unwrap();
        assert_eq!(
            untimed(&resumed),
            whole,
            "resumed from the states of report {}",
            stop - 1
        );
        assert_eq!(resumed.timing.resumed_from_step, k);
    }
    at
}

/// Interruptions in the analysis, in the runs' first chunks, in their middle and in
/// their last chunk. (A state is kept at a report that lets the run go on: the first
/// interruption is at the analysis loop's second report, after it kept one. The last
/// report is the end's 100 %; the one before is the last chunk's.)
fn spread(first_chunk: usize, n: usize) -> Vec<usize> {
    assert!(
        first_chunk >= 4 && n >= first_chunk + 4,
        "{n} reports, the runs' first at {first_chunk}: too few to interrupt"
    );
    vec![
        first_chunk - 2,
        first_chunk + 1,
        (first_chunk + n) / 2,
        n - 1,
    ]
}

/// Of [`spread`]'s interruptions, the first is in the analysis, the others in the runs.
fn spread_at(at: &[Option<u64>]) {
    assert!(at[0].is_none(), "the first interruption is in the analysis");
    assert!(at[1..].iter().all(Option::is_some), "{at:?}");
}

/// A time-varying a(t) and Γ(t), a measurement on a schedule, a constant model error
/// drawn once per run (kept with the runs), 100 runs in four blocks.
#[test]
fn a_monte_carlo_resumes_exactly() {
    let mut req = MonteCarloRequest::new(100, 7);
    req.model_error = ModelError::Constant;
    let at = simulates_exactly(
        json!({
            "time": {"t0": 0.0, "t_end": 4.0, "steps": 40_000},
            "system": {"states": ["x", "v"], "a": [[0, 1], ["-4*(1 + 0.1*sin(t))", -0.3]],
                       "b": [[0], [1]], "y0": [1, 0], "eta0": [0.5, 0.5], "phi": [0.4]},
            "measurement": {"names": ["zx", "zv"], "c": [[1, 0], [0, 1]],
                            "gamma": [["1 + 0.5*cos(t)", 0], [0, 1]], "psi": [0.2, 0.3],
                            "schedule": [{"every": 3, "offset": 1}, {"unavailable": [[1, 2]]}]},
            "options": {"trace_points": 30}
        }),
        &req,
        spread,
    );
    spread_at(&at);
    assert!(at[3] < Some(40_000), "{at:?}");
}

/// Thirteen states (the runs' loop of runtime size; fixed sizes go to 12), the truth
/// the mean (seed 000's reading), white model error, 40 runs.
#[test]
fn a_runtime_size_monte_carlo_resumes_exactly() {
    let n = 13;
    let a = common::chain_a(n, |_| json!(-0.5), json!(1.0));
    let mut req = MonteCarloRequest::new(40, 3);
    req.truth = Truth::Mean;
    let at = simulates_exactly(
        json!({
            "time": {"t0": 0.0, "t_end": 2.0, "steps": 3000},
            "system": {"states": (0..n).map(|i| format!("x{i}")).collect::<Vec<_>>(), "a": a,
                       "b": vec![vec![1.0]; n], "y0": vec![1.0; n], "eta0": vec![0.5; n], "phi": [0.3]},
            "measurement": {"names": ["z"], "c": [(0..n).map(|j| if j == 0 { 1.0 } else { 0.0 }).collect::<Vec<_>>()],
                            "gamma": [[1]], "psi": [0.1]},
            "options": {"trace_points": 25}
        }),
        &req,
        spread,
    );
    spread_at(&at);
}

/// The runs' state of another request (another seed) is not taken: the run starts over.
#[test]
fn a_monte_carlo_state_of_another_seed_is_ignored() {
    let model = model_from_value(tracker(3000, 30.0)).unwrap();
    let set = Overrides::new();
    let (one, other) = (MonteCarloRequest::new(50, 1), MonteCarloRequest::new(50, 2));
    let memo = Keeper::keeping();
    let r = simulate_resumable(
        &model,
        &set,
        &other,
        &Sequential,
        &mut stopping_at(8),
        &memo,
    );
    assert!(matches!(r, Err(Error::Cancelled)));
    let kept = memo.kept.into_inner().unwrap();
    assert!(kept.contains_key(MONTE_CARLO_KEY));
    let resumed = simulate_resumable(
        &model,
        &set,
        &one,
        &Sequential,
        &mut NoProgress,
        &Keeper::recalling_all(kept),
    )
    .unwrap();
    let fresh =
        simulate_resumable(&model, &set, &one, &Sequential, &mut NoProgress, &Forgetful).unwrap();
    assert_eq!(resumed.timing.resumed_from_step, None);
    assert_eq!(
        serde_json::to_value(&resumed.traces).unwrap(),
        serde_json::to_value(&fresh.traces).unwrap()
    );
}

/// `"steps": "auto"`: the selection is kept once made; a run interrupted in its final
/// analysis takes it on resuming instead of running its trials again (which report 0),
/// and gives the uninterrupted result. A selection of another tolerance is not taken.
#[test]
fn an_auto_steps_run_takes_its_kept_selection() {
    // (An oscillating mean: Euler's error in it halves as D doubles.)
    let mut model = tracker(0, 10.0);
    model["system"]["a"] = json!([[0, 1], [-1, -0.2]]);
    model["time"]["steps"] = json!("auto");
    model["time"]["auto"] =
        json!({"tolerance": 1e-4, "initial_steps": 1000, "max_steps": 4_096_000});
    let m = compiled(model.clone());
    let mut trial_reports = 0;
    let whole = run(&m, &mut |f: f64| {
        trial_reports += usize::from(f == 0.0);
        ControlFlow::Continue(())
    })
    .unwrap();
    let history = &whole.step_selection.as_ref().unwrap().history;
    assert!(history.len() >= 3, "{history:?}");
    assert!(trial_reports >= 3, "{trial_reports} trial reports");
    let n = reports(&m);
    let memo = Keeper::keeping();
    let r = run_resumable(&m, &mut stopping_at(n - 2), &memo);
    assert!(matches!(r, Err(Error::Cancelled)));
    let kept = memo.kept.into_inner().unwrap();
    assert!(kept.contains_key(SELECTION_KEY) && kept.contains_key(STATE_KEY));
    let mut zero_reports = 0;
    let resumed = run_resumable(
        &m,
        &mut |f: f64| {
            zero_reports += usize::from(f == 0.0);
            ControlFlow::Continue(())
        },
        &Keeper::recalling_all(kept.clone()),
    )
    .unwrap();
    assert_eq!(zero_reports, 0, "the trials were run again");
    assert_eq!(untimed(&resumed), untimed(&whole));
    assert!(resumed.timing.resumed_from_step.is_some());

    // The selection alone, of another tolerance: made again.
    model["time"]["auto"]["tolerance"] = json!(2e-6);
    let other = compiled(model);
    let selection = HashMap::from([(SELECTION_KEY.to_string(), kept[SELECTION_KEY].clone())]);
    let mut zero_reports = 0;
    let r = run_resumable(
        &other,
        &mut |f: f64| {
            zero_reports += usize::from(f == 0.0);
            ControlFlow::Continue(())
        },
        &Keeper::recalling_all(selection),
    )
    .unwrap();
    assert!(zero_reports >= 3, "the selection was made again");
    assert_eq!(untimed(&r), untimed(&run(&other, &mut NoProgress).unwrap()));
}

/// Every preset (the seed's g form, schedules, six states, paired and unpaired states)
/// analysed and simulated, each interrupted at a report drawn from a seeded stream (so
/// the same on every run) and resumed: the uninterrupted result.
#[test]
fn every_preset_resumes_exactly_at_a_drawn_report() {
    let mut rng = ChaCha8Rng::seed_from_u64(28);
    for name in kea_core::presets::names() {
        let mut model = common::preset_value(name);
        model["time"]["steps"] = json!(200_000);
        model["options"]["trace_points"] = json!(200);
        let m = compiled(model.clone());
        let whole = untimed(&run(&m, &mut NoProgress).unwrap());
        let n = reports(&m);
        assert!(n >= 4, "{name}: {n} reports");
        let stop = rng.random_range(2..n);
        let state = interrupted(&m, stop);
        let resumed = run_resumable(&m, &mut NoProgress, &Keeper::recalling(state)).unwrap();
        assert_eq!(
            untimed(&resumed),
            whole,
            "{name}: the analysis interrupted at report {stop} of {n}"
        );

        model["time"]["steps"] = json!(20_000);
        let mut draw = |first_chunk: usize, n: usize| {
            assert!(
                n >= first_chunk + 3,
                "{name}: {n} reports, the runs' first at {first_chunk}"
            );
            vec![rng.random_range(first_chunk..n)]
        };
        let at = simulates_exactly(model, &MonteCarloRequest::new(40, 11), &mut draw);
        assert!(at[0].is_some(), "{name}: interrupted in the runs");
    }
}
