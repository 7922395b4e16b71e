//! An analysis interrupted after any progress report and resumed from the state it
//! kept there ends with the result of an uninterrupted run, bit for bit (but for its
//! timing): over the filter's transient and the frozen steady state, with a bound that
//! overflows on the way, measurement schedules and a time-varying a(t) and Γ(t), with
//! fixed-size and runtime-size loops. A state that does not belong to the run is
//! ignored.

mod common;

use kea_core::analysis::{run, run_resumable};
use kea_core::exec::Memo;
use kea_core::resume::STATE_KEY;
use kea_core::validate::{CompiledModel, compile};
use kea_core::{Error, NoProgress, model_from_value};
use serde_json::{Value, json};
use std::ops::ControlFlow;
use std::sync::Mutex;

/// Keeps the state at every report (the last one wins), and recalls what it was given.
struct Keeper {
    given: Option<String>,
    kept: Mutex<Option<String>>,
    keep: bool,
}

impl Keeper {
    fn keeping() -> Keeper {
        Keeper {
            given: None,
            kept: Mutex::new(None),
            keep: true,
        }
    }

    fn recalling(state: String) -> Keeper {
        Keeper {
            given: Some(state),
            kept: Mutex::new(None),
            keep: false,
        }
    }
}

impl Memo for Keeper {
    fn recall(&self, key: &str) -> Option<String> {
        assert_eq!(key, STATE_KEY);
        self.given.clone()
    }
    fn keep(&self, key: &str, value: &str) {
        assert_eq!(key, STATE_KEY);
        *self.kept.lock().unwrap() = Some(value.to_string());
    }
    fn state_due(&self) -> bool {
        self.keep
    }
}

/// The result's JSON without its timing.
fn untimed(r: &kea_core::result::AnalysisResult) -> Value {
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
    let mut seen = 0;
    let r = run_resumable(
        m,
        &mut |_: f64| {
            seen += 1;
            if seen == stop {
                ControlFlow::Break(())
            } else {
                ControlFlow::Continue(())
            }
        },
        &memo,
    );
    assert!(
        matches!(r, Err(Error::Cancelled)),
        "interrupted at report {stop}"
    );
    memo.kept.into_inner().unwrap().expect("a state was kept")
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
    let a: Vec<Vec<f64>> = (0..n)
        .map(|i| {
            (0..n)
                .map(|j| {
                    if j == i {
                        -0.5
                    } else if j == i + 1 {
                        1.0
                    } else {
                        0.0
                    }
                })
                .collect()
        })
        .collect();
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
