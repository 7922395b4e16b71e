//! The error budget (`"budget": true`, `kea_core::analysis::budget`) against the
//! analysis's own totals on every preset, a 34-digit reference, the scalar closed form
//! of the stationary shares, and a second, block-form implementation (nalgebra) of the
//! Joseph form per source on a model with a schedule, correlated W and V and b(t).

mod common;
use common::{assert_error_at, preset_value};
use kea_core::AnalysisResult;
use kea_core::analysis::budget::{Budget, SourceKind};
use kea_core::registry;
use nalgebra::DMatrix;
use serde_json::{Value, json};

fn analyse(request: Value) -> AnalysisResult {
    common::run_analysis(request)
}

fn budget_of(model: Value, set: Value) -> (AnalysisResult, Budget) {
    let r = analyse(json!({ "model": model, "set": set, "budget": true }));
    let b = r.budget.clone().expect("a budget");
    (r, b)
}

fn rel(a: f64, b: f64) -> f64 {
    ((a - b) / b).abs()
}

/// The sources' parts add up to the analysis's own filtered and open-loop variances
/// at t_D, on every preset.
#[test]
fn parts_sum_to_the_analysis_on_every_preset() {
    let names = kea_core::presets::names();
    assert!(names.len() >= 5, "{names:?}");
    for name in names {
        let (r, b) = budget_of(preset_value(name), json!({}));
        let n = r.states.len();
        assert_eq!(b.states.len(), n);
        assert!(b.sources.len() >= n + 2, "{name}: {:?}", b.sources);
        // The seed example's R_D (D = 10⁶, q/d large) is the one the analysis's
        // expanded update keeps to 7e-12 only (the 34-digit reference below): there
        // the budget's products are the closer of the two.
        let tol = if name == "seed-example" { 1e-11 } else { 1e-12 };
        for (i, s) in b.states.iter().enumerate() {
            let potential = r.final_.potential_sko[i].powi(2);
            let open = r.final_.open_loop_sko[i].powi(2);
            let e = rel(s.potential.final_variance, potential);
            assert!(e <= tol, "{name} {}: filtered {e:e}", s.state);
            let e = rel(s.open_loop.final_variance, open);
            assert!(e <= tol, "{name} {}: open-loop {e:e}", s.state);
            for shares in [&s.potential, &s.open_loop] {
                for list in [&shares.final_share, &shares.mean_share] {
                    assert_eq!(list.len(), b.sources.len());
                    let sum: f64 = list.iter().map(|x| x.expect("a variance > 0")).sum();
                    assert!((sum - 1.0).abs() <= 1e-13, "{name}: {sum}");
                    assert!(list.iter().all(|x| x.unwrap() >= 0.0), "{name}: {list:?}");
                }
            }
            // Measurement errors do not reach the open loop.
            for (k, src) in b.sources.iter().enumerate() {
                if src.kind == SourceKind::MeasurementError {
                    assert_eq!(s.open_loop.final_share[k], Some(0.0));
                }
            }
        }
    }
}

/// The seed example against the same recursion in 34-digit decimal arithmetic
/// (Python's `decimal`, the budget's product form per source; the script is in the
/// comment below): R_D = 2.790488123645772e-13, phi[0]'s share 0.13718341881521118.
///
/// ```text
/// A = 1 + (s/m)Δt, B = ((v/m)Δt)² (f ψ)², Γ_k = c v t_k / m_g, Rv = Γ² ψ²
/// r = A² R + B; q = c² r + Rv; p = r c / q; h = 1 − p c
/// R = h² r + p² Rv;  R_F = h² (A² R_F + B);  R_V = h² A² R_V + p² Rv
/// ```
#[test]
fn seed_example_matches_a_34_digit_recursion() {
    let (_, b) = budget_of(preset_value("seed-example"), json!({}));
    let names: Vec<&str> = b.sources.iter().map(|s| s.name.as_str()).collect();
    assert_eq!(names, ["eta0[Y]", "phi[0]", "psi[0]"]);
    let y = &b.states[0].potential;
    let e = rel(y.final_variance, 2.790488123645772e-13);
    assert!(e <= 2e-12, "R_D {e:e}");
    let share = y.final_share[1].unwrap();
    assert!((share - 0.13718341881521118).abs() <= 1e-10, "{share}");
    // η0 = 0: no share at all.
    assert_eq!(y.final_share[0], Some(0.0));
    assert_eq!(y.mean_share[0], Some(0.0));
}

/// A source set to zero has a zero share, at t_D and on average, in every state.
#[test]
fn a_silent_source_has_no_share() {
    let (_, b) = budget_of(preset_value("helicopter-range"), json!({ "sv_f": 0.0 }));
    let k = b.sources.iter().position(|s| s.name == "phi[0]").unwrap();
    assert_eq!(b.sources[k].enters.as_deref(), Some("j_f"));
    for s in &b.states {
        for shares in [&s.potential, &s.open_loop] {
            assert_eq!(shares.final_share[k].unwrap_or(0.0), 0.0, "{}", s.state);
            assert_eq!(shares.mean_share[k].unwrap_or(0.0), 0.0, "{}", s.state);
        }
    }
    // The blade's states owe nothing to the fuselage's sources and back.
    let k = b.sources.iter().position(|s| s.name == "psi[0]").unwrap();
    assert_eq!(b.sources[k].enters.as_deref(), Some("D_f_meas"));
    let d_b = b.states.iter().find(|s| s.state == "D_b").unwrap();
    assert_eq!(d_b.potential.final_share[k], Some(0.0));
}

/// A scalar model at its stationary point: with the DARE's r∞ in closed form,
/// h = Rv/(r + Rv) and p = r/(r + Rv), the parts are h²B / (1 − h²A²) and
/// p²Rv / (1 − h²A²), so the model error's share is Rv B / (Rv B + r∞²) (c = 1).
#[test]
fn scalar_shares_equal_the_closed_form() {
    for (a, b_, phi, psi) in [
        (-0.5, 1.0, 0.3, 0.2),
        (0.2, 2.0, 0.5, 0.1),
        (-3.0, 0.5, 2.0, 0.01),
    ] {
        let (t_end, steps) = (40.0, 40_000u64);
        let dt = t_end / steps as f64;
        let model = json!({
            "kea_model": 1,
            "time": { "t0": 0, "t_end": t_end, "steps": steps },
            "system": { "states": ["x"], "a": [[a]], "b": [[b_]], "eta0": [1.0], "phi": [phi] },
            "measurement": { "names": ["z"], "c": [[1]], "gamma": [[1]], "psi": [psi] },
            "options": { "steady_state_shortcut": false }
        });
        let (_, bud) = budget_of(model, json!({}));
        let big_a: f64 = 1.0 + a * dt;
        let big_b = (b_ * dt * phi).powi(2);
        let rv = psi * psi;
        // r² + r (Rv (1 − A²) − B) − B Rv = 0
        let lin = rv * (1.0 - big_a * big_a) - big_b;
        let r = (-lin + (lin * lin + 4.0 * big_b * rv).sqrt()) / 2.0;
        let expected = rv * big_b / (rv * big_b + r * r);
        let x = &bud.states[0].potential;
        let got = x.final_share[1].unwrap();
        assert!(
            rel(got, expected) <= 1e-11,
            "a = {a}: {got} against {expected}"
        );
        let total = (big_b * rv * rv + r * r * rv) / ((r + rv).powi(2) - big_a * big_a * rv * rv);
        assert!(rel(x.final_variance, total) <= 1e-11, "a = {a}: R∞");
        assert!(x.final_share[0].unwrap() < 1e-12, "η0's part decays");
    }
}

/// The budget against a second implementation: the block-form Joseph update per
/// source in nalgebra (q, K = r Cᵀ q⁻¹ of the available rows, H = I − K C), on a model
/// with correlated model errors (one group), correlated measurement errors (psi[1,2]),
/// b varying in t and a measurement every third step only.
#[test]
fn equals_a_block_form_recursion_per_source() {
    let (t_end, steps) = (5.0, 500u64);
    let model = json!({
        "kea_model": 1,
        "time": { "t0": 0, "t_end": t_end, "steps": steps },
        "system": {
            "states": ["x1", "x2", "x3"],
            "a": [[0, 1, 0], [0, -0.5, 1], [0, 0, -2]],
            "b": [[0, 0], [1, "0.5*sin(t)"], [0, 1]],
            "eta0": [1.0, 0.5, 0.2],
            "W": [[1.0, 0.3], [0.3, 2.0]]
        },
        "measurement": {
            "names": ["z1", "z2"],
            "c": [[1, 0, 0], [0, 1, 0]],
            "gamma": [[1, 0, 0], [0, 1, 1]],
            "V": [[0.04, 0, 0], [0, 0.01, 0.002], [0, 0.002, 0.02]],
            "schedule": [null, { "every": 3 }]
        }
    });
    let (r, b) = budget_of(model, json!({}));
    let names: Vec<&str> = b.sources.iter().map(|s| s.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "eta0[x1]", "eta0[x2]", "eta0[x3]", "phi[0,1]", "psi[0]", "psi[1,2]"
        ]
    );

    let (n, dt) = (3, t_end / steps as f64);
    let a = DMatrix::from_row_slice(3, 3, &[0., 1., 0., 0., -0.5, 1., 0., 0., -2.]);
    let big_a = DMatrix::identity(n, n) + a * dt;
    let w = DMatrix::from_row_slice(2, 2, &[1.0, 0.3, 0.3, 2.0]);
    let c = DMatrix::from_row_slice(2, 3, &[1., 0., 0., 0., 1., 0.]);
    let gamma = DMatrix::from_row_slice(2, 3, &[1., 0., 0., 0., 1., 1.]);
    let v = DMatrix::from_row_slice(3, 3, &[0.04, 0., 0., 0., 0.01, 0.002, 0., 0.002, 0.02]);
    let rv = &gamma * &v * gamma.transpose();
    let rv_of = |cols: &[usize]| {
        let mut vs = DMatrix::zeros(3, 3);
        for &i in cols {
            for &j in cols {
                vs[(i, j)] = v[(i, j)];
            }
        }
        &gamma * vs * gamma.transpose()
    };
    let rv_parts = [rv_of(&[0]), rv_of(&[1, 2])];
    let eta0 = [1.0, 0.5, 0.2];
    // Sources: η0 ×3, the W group, the two V groups; R and P^Y parts, sums of diagonals.
    let mut r_parts: Vec<DMatrix<f64>> = (0..6).map(|_| DMatrix::zeros(n, n)).collect();
    for i in 0..3 {
        r_parts[i][(i, i)] = eta0[i] * eta0[i];
    }
    let mut p_parts = r_parts.clone();
    let mut big_r = DMatrix::from_diagonal(&nalgebra::DVector::from_iterator(
        3,
        eta0.iter().map(|e| e * e),
    ));
    let mut sum_r = [[0.0f64; 3]; 6];
    for k in 1..=steps {
        let t_prev = (k - 1) as f64 * dt;
        let bd = DMatrix::from_row_slice(3, 2, &[0., 0., 1., 0.5 * t_prev.sin(), 0., 1.]) * dt;
        let big_b = &bd * &w * bd.transpose();
        let rows: Vec<usize> = if k % 3 == 0 { vec![0, 1] } else { vec![0] };
        let cs = c.select_rows(&rows);
        let rvs = rv.select_rows(&rows).select_columns(&rows);
        let rp = &big_a * &big_r * big_a.transpose() + &big_b;
        let q = &cs * &rp * cs.transpose() + &rvs;
        let gain = &rp * cs.transpose() * q.try_inverse().unwrap();
        let h = DMatrix::identity(n, n) - &gain * &cs;
        big_r = &h * &rp * h.transpose() + &gain * &rvs * gain.transpose();
        for s in 0..6 {
            let bs = if s == 3 {
                big_b.clone()
            } else {
                DMatrix::zeros(n, n)
            };
            let noise = if s >= 4 {
                let rvs = rv_parts[s - 4].select_rows(&rows).select_columns(&rows);
                &gain * rvs * gain.transpose()
            } else {
                DMatrix::zeros(n, n)
            };
            r_parts[s] =
                &h * (&big_a * &r_parts[s] * big_a.transpose() + &bs) * h.transpose() + noise;
            p_parts[s] = &big_a * &p_parts[s] * big_a.transpose() + &bs;
            for i in 0..3 {
                sum_r[s][i] += r_parts[s][(i, i)];
            }
        }
    }
    for (i, st) in b.states.iter().enumerate() {
        let total: f64 = (0..6).map(|s| r_parts[s][(i, i)]).sum();
        let open: f64 = (0..6).map(|s| p_parts[s][(i, i)]).sum();
        let mean: f64 = (0..6).map(|s| sum_r[s][i]).sum::<f64>() / steps as f64;
        assert!(
            rel(st.potential.final_variance, total) <= 1e-12,
            "{}",
            st.state
        );
        assert!(
            rel(st.open_loop.final_variance, open) <= 1e-12,
            "{}",
            st.state
        );
        assert!(
            rel(st.potential.mean_variance, mean) <= 1e-12,
            "{}",
            st.state
        );
        assert!(rel(r.final_.potential_sko[i].powi(2), total) <= 1e-12);
        for s in 0..6 {
            let close = |got: Option<f64>, want: f64| (got.unwrap() - want).abs() <= 1e-12;
            assert!(
                close(st.potential.final_share[s], r_parts[s][(i, i)] / total),
                "{} {s}",
                st.state
            );
            assert!(
                close(
                    st.potential.mean_share[s],
                    sum_r[s][i] / steps as f64 / mean
                ),
                "{} {s}",
                st.state
            );
            assert!(
                close(st.open_loop.final_share[s], p_parts[s][(i, i)] / open),
                "{} {s}",
                st.state
            );
        }
    }
}

/// `budget` is a yes/no; the work estimate grows with the sources and says so.
#[test]
fn budget_is_a_flag_and_costs_per_source() {
    let model = preset_value("helicopter-range");
    let e = registry::prepare("analysis", json!({ "model": model, "budget": "yes" }))
        .err()
        .expect("refused");
    assert_error_at(&e, "budget", "expected true or false");
    let work = |budget: bool| {
        registry::prepare("analysis", json!({ "model": model, "budget": budget }))
            .unwrap()
            .work()
    };
    let (plain, with) = (work(false), work(true));
    assert!(
        with.units > 5.0 * plain.units,
        "{} against {}",
        with.units,
        plain.units
    );
    assert!(with.explain.contains("12 sources"), "{}", with.explain);
    // Without it, no budget in the result.
    let r = analyse(json!({ "model": model }));
    assert!(r.budget.is_none());
}

/// Past N = 12 the pass is runtime-sized: its parts still add up to the analysis's
/// variances (a 13-state chain, 5 of its states measured).
#[test]
fn a_runtime_sized_model_adds_up_too() {
    let n = 13;
    let a = common::chain_a(n, |i| json!(-0.3 - 0.05 * i as f64), json!(1.0));
    let eye = |k: usize, m: usize| -> Vec<Vec<f64>> {
        (0..k)
            .map(|i| (0..m).map(|j| if i == j { 1.0 } else { 0.0 }).collect())
            .collect()
    };
    let model = json!({
        "kea_model": 1,
        "time": { "t0": 0, "t_end": 5, "steps": 2000 },
        "system": {
            "states": (0..n).map(|i| format!("x{i}")).collect::<Vec<_>>(),
            "a": a, "b": eye(n, n), "phi": vec![0.3; n], "eta0": vec![0.5; n]
        },
        "measurement": {
            "names": (0..5).map(|i| format!("z{i}")).collect::<Vec<_>>(),
            "c": eye(5, n), "gamma": eye(5, 5), "psi": vec![0.1; 5]
        }
    });
    let (r, b) = budget_of(model, json!({}));
    assert_eq!(b.sources.len(), n + n + 5);
    for (i, s) in b.states.iter().enumerate() {
        let e = rel(
            s.potential.final_variance,
            r.final_.potential_sko[i].powi(2),
        );
        assert!(e <= 1e-12, "{}: {e:e}", s.state);
        let e = rel(
            s.open_loop.final_variance,
            r.final_.open_loop_sko[i].powi(2),
        );
        assert!(e <= 1e-12, "{}: open loop {e:e}", s.state);
    }
}
