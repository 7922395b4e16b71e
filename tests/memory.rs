//! Heap use, counted by a global allocator: the architecture invariant that memory
//! does not grow with the number of steps D (criteria accumulated on the fly, traces
//! decimated), and the documented cost of time-dependent expressions, which the
//! model's expression limits rest on (docs/model-format.md, "Limits", `expr::MAX_TIME_*`).

mod common;

use kea_core::monte_carlo::{MonteCarloRequest, Sequential, simulate};
use kea_core::{Model, NoProgress, Overrides, model_from_value};
use serde_json::{Value, json};
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

struct Counting;

thread_local! {
    /// This thread's heap in use and its peak: the engine is single-threaded, so a
    /// test's own count is not disturbed by the others running beside it.
    static NOW: Cell<usize> = const { Cell::new(0) };
    static PEAK: Cell<usize> = const { Cell::new(0) };
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        let now = NOW.get() + l.size();
        NOW.set(now);
        PEAK.set(PEAK.get().max(now));
        unsafe { System.alloc(l) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        NOW.set(NOW.get().wrapping_sub(l.size()));
        unsafe { System.dealloc(p, l) }
    }
}

#[global_allocator]
static COUNTING: Counting = Counting;

/// The heap `f` holds when it returns and the most it held meanwhile, in bytes above
/// what this thread had in use before it, and its value (dropped after the count).
fn measured<T>(f: impl FnOnce() -> T) -> (usize, usize, T) {
    let base = NOW.get();
    PEAK.set(base);
    let value = f();
    let held = NOW.get().wrapping_sub(base);
    let peak = PEAK.get() - base;
    (held, peak, value)
}

fn eye(n: usize) -> Vec<Vec<f64>> {
    (0..n)
        .map(|i| (0..n).map(|j| if i == j { 1.0 } else { 0.0 }).collect())
        .collect()
}

/// An n-state model whose `a` is `a`, every state measured.
fn model(a: Vec<Vec<Value>>, steps: u64) -> Model {
    let n = a.len();
    model_from_value(json!({
        "time": {"t0": 0.0, "t_end": 10.0, "steps": steps},
        "system": {
            "states": (0..n).map(|i| format!("x{i}")).collect::<Vec<_>>(),
            "a": a, "b": eye(n), "phi": vec![0.1; n], "y0": vec![1.0; n], "eta0": vec![1.0; n],
        },
        "measurement": {
            "names": (0..n).map(|i| format!("z{i}")).collect::<Vec<_>>(),
            "c": eye(n), "gamma": eye(n), "psi": vec![0.2; n],
        },
    }))
    .expect("a valid model")
}

/// A time-varying 3-state chain over `steps` steps.
fn chain(steps: u64) -> Model {
    let a = common::chain_a(3, |i| json!(format!("-0.5 + 0.2*sin(t + {i})")), json!(1.0));
    model(a, steps)
}

/// The peak heap of `run` (which must run `steps` steps of [`chain`]) at `small` and
/// at `large` steps: the larger may take no more than 4 KB beyond the smaller (a buffer
/// of one f64 a step would add megabytes).
fn peak_does_not_grow(what: &str, small: u64, large: u64, run: impl Fn(&Model) -> u64) {
    let peak = |steps: u64| {
        let m = chain(steps);
        let (_, peak, ran) = measured(|| run(&m));
        assert_eq!(ran, steps);
        peak
    };
    let (at_small, at_large) = (peak(small), peak(large));
    println!("{what} peak heap: {small} steps {at_small} B, {large} steps {at_large} B");
    assert!(
        at_large <= at_small + 4096,
        "{what}: {large} steps took {at_large} B of heap at the peak, {small} steps {at_small} B"
    );
}

#[test]
fn an_analysis_heap_does_not_grow_with_the_steps() {
    // 10⁴ steps already fill every one of the 1000 trace rows.
    peak_does_not_grow("analysis", 10_000, 1_000_000, |m| {
        kea_core::analyze(m, &Overrides::new(), &mut NoProgress)
            .unwrap()
            .steps
    });
}

#[test]
fn a_monte_carlo_heap_does_not_grow_with_the_steps() {
    let req = MonteCarloRequest::new(8, 7);
    peak_does_not_grow("Monte Carlo (8 runs)", 10_000, 200_000, |m| {
        simulate(m, &Overrides::new(), &req, &Sequential, &mut NoProgress)
            .unwrap()
            .steps
    });
}

/// A 45-state model whose `a` holds `count` distinct time-dependent texts of `chars`
/// characters each (the densest shape: one operator or operand per character).
fn expressions(count: usize, chars: usize) -> Model {
    let n = 45;
    let mut a = vec![vec![json!(0.0); n]; n];
    for k in 0..count {
        let head = format!("0.001*sin(t+{k})");
        let text = format!("{head}{}", "+t".repeat((chars - head.len()) / 2));
        a[k / n][k % n] = json!(text);
    }
    model(a, 10)
}

#[test]
fn expressions_at_the_model_limits_take_the_documented_memory() {
    use kea_core::expr::{MAX_EXPRESSION_CHARS, MAX_TIME_EXPRESSION_CHARS, MAX_TIME_EXPRESSIONS};
    let set = Overrides::new();
    // (held by the compiled model, an analysis's peak) of a model, with the same
    // model's one-expression figures subtracted: what its expressions cost.
    let cost = |count: usize, chars: usize| {
        let run = |m: &Model| {
            let (held, peak, _) = measured(|| {
                let c = kea_core::model::compile(m, &set).unwrap();
                kea_core::analysis::run(&c, &mut NoProgress).unwrap();
                c
            });
            (held, peak)
        };
        let (held, peak) = run(&expressions(count, chars));
        let (held1, peak1) = run(&expressions(1, chars));
        (held - held1, peak - peak1)
    };
    const KB: f64 = 1024.0;
    const MB: f64 = 1024.0 * 1024.0;
    // Per expression, short and at the longest text (docs/model-format.md: "a parsed one, in both
    // its forms, holds ≈ 45 KB plus ≈ 0.7 KB per character, shared by the analyses
    // that run it"): an analysis's peak adds little to what the compiled model holds.
    let (held_short, peak_short) = cost(101, 20);
    let (held_long, peak_long) = cost(41, MAX_EXPRESSION_CHARS);
    let per = |b: usize, count: usize| b as f64 / (count - 1) as f64 / KB;
    let per_char = (per(peak_long, 41) - per(peak_short, 101)) / (MAX_EXPRESSION_CHARS - 20) as f64;
    println!(
        "per expression: 20 characters {:.1} KB held, {:.1} KB at an analysis's peak; \
         1000 characters {:.1} KB, {:.1} KB; {per_char:.2} KB per character at the peak",
        per(held_short, 101),
        per(peak_short, 101),
        per(held_long, 41),
        per(peak_long, 41),
    );
    assert!(per(held_short, 101) <= 50.0 && per(peak_short, 101) <= 50.0);
    assert!(per_char <= 1.0);
    // The whole model at the limits (docs/model-format.md: ≈ 85 MB held, little more at the peak;
    // before the parses were shared, ≈ 40 MB held and ≈ 125 MB at the peak).
    let chars = MAX_TIME_EXPRESSION_CHARS / MAX_TIME_EXPRESSIONS;
    let (held, peak) = cost(MAX_TIME_EXPRESSIONS, chars);
    println!(
        "{MAX_TIME_EXPRESSIONS} expressions of {chars} characters: {:.1} MB held, {:.1} MB at the peak",
        held as f64 / MB,
        peak as f64 / MB
    );
    assert!(held as f64 <= 100.0 * MB && peak as f64 <= 105.0 * MB);
}
