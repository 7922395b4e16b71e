//! The model's matrices and vectors: their shapes checked, their entries compiled as
//! time-varying ([`TimeMatrix`]) or constant (params allowed, `t` not).

use super::Errors;
use crate::expr::{ExprBudget, TimeMatrix, TimeMatrixBuilder, compile_const};
use crate::model::Value;
use crate::text::{entries, num};
use std::collections::BTreeMap;

/// Check rows × cols; `cols` None means "any, but all rows equal".
pub(crate) fn check_shape(
    m: &[Vec<Value>],
    rows: usize,
    cols: Option<usize>,
    path: &str,
    rows_sym: &str,
    cols_sym: &str,
    errs: &mut Errors,
) -> bool {
    let mut ok = true;
    if m.len() != rows {
        errs.at(
            path,
            format!(
                "has {} rows, expected {rows} ({rows_sym} = {rows})",
                m.len()
            ),
        );
        ok = false;
    }
    if let Some(cols) = cols {
        for (i, row) in m.iter().enumerate().take(rows) {
            if row.len() != cols {
                errs.at(
                    &format!("{path}[{i}]"),
                    format!(
                        "this row of `{}` has {}, expected {cols} ({cols_sym} = {cols})",
                        path.rsplit('.').next().unwrap_or(path),
                        entries(row.len())
                    ),
                );
                ok = false;
            }
        }
    }
    ok
}

#[allow(clippy::too_many_arguments)]
pub(super) fn time_matrix(
    m: &[Vec<Value>],
    rows: usize,
    cols: Option<usize>,
    path: &str,
    rows_sym: &str,
    params: &BTreeMap<String, f64>,
    t0: f64,
    expressions: &mut ExprBudget,
    errs: &mut Errors,
) -> TimeMatrix {
    let cols_n = cols.unwrap_or(0);
    let cols_sym = match path {
        "system.a" => "N",
        "system.b" => "L, from row 0",
        _ => "M, from row 0",
    };
    let shape_ok = check_shape(m, rows, cols, path, rows_sym, cols_sym, errs);
    let mut out = TimeMatrixBuilder::new(rows, cols_n);
    if shape_ok {
        for i in 0..rows {
            for j in 0..cols_n {
                if let Some(v) = m.get(i).and_then(|r| r.get(j)) {
                    let p = format!("{path}[{i}][{j}]");
                    if let Err(e) = out.set(i * cols_n + j, v, params, p, t0, expressions) {
                        errs.push(e);
                    }
                }
            }
        }
    }
    out.finish()
}

#[allow(clippy::too_many_arguments)]
pub(super) fn time_vector(
    v: &[Value],
    n: usize,
    path: &str,
    sym: &str,
    params: &BTreeMap<String, f64>,
    t0: f64,
    expressions: &mut ExprBudget,
    errs: &mut Errors,
) -> TimeMatrix {
    if v.len() != n {
        errs.at(
            path,
            format!("has {}, expected {n} ({sym} = {n})", entries(v.len())),
        );
    }
    let mut out = TimeMatrixBuilder::new(n, 1);
    for (i, x) in v.iter().enumerate().take(n) {
        if let Err(e) = out.set(i, x, params, format!("{path}[{i}]"), t0, expressions) {
            errs.push(e);
        }
    }
    out.finish()
}

pub(crate) fn const_vector(
    v: Option<&[Value]>,
    n: usize,
    path: &str,
    sym: &str,
    params: &BTreeMap<String, f64>,
    errs: &mut Errors,
    non_negative: bool,
) -> Vec<f64> {
    let Some(v) = v else {
        return vec![0.0; n];
    };
    if v.len() != n {
        errs.at(
            path,
            format!("has {}, expected {n} ({sym} = {n})", entries(v.len())),
        );
        return vec![0.0; n];
    }
    v.iter()
        .enumerate()
        .map(|(i, x)| {
            let p = format!("{path}[{i}]");
            match compile_const(x, params, &p) {
                Ok(x) if non_negative && x < 0.0 => {
                    errs.at(&p, format!("an SKO must be ≥ 0, got {}", num(x)));
                    0.0
                }
                Ok(x) if non_negative && !(x * x).is_finite() => {
                    errs.at(
                        &p,
                        format!("an SKO must be below 1.34e154 (its square, the variance, must be a finite f64), got {x:e}"),
                    );
                    0.0
                }
                // A square below f64's normal range has lost its precision (1e-160
                // squares to 1e-320, 3 significant digits; 1e-170 to 0), and its
                // reciprocal overflows: the gain of such a measurement was NaN.
                Ok(x) if non_negative && x > 0.0 && x * x < f64::MIN_POSITIVE => {
                    errs.at(
                        &p,
                        format!("an SKO must be 0 or at least 1.5e-154 (its square, the variance, must be a normal f64, at least 2.2e-308), got {x:e}"),
                    );
                    0.0
                }
                Ok(x) => x,
                Err(e) => {
                    errs.push(e);
                    0.0
                }
            }
        })
        .collect()
}

/// A constant rows × rows matrix (params allowed, `t` not), row-major: a discrete
/// model's Φ.
pub(super) fn const_matrix(
    m: &[Vec<Value>],
    n: usize,
    path: &str,
    params: &BTreeMap<String, f64>,
    errs: &mut Errors,
) -> Vec<f64> {
    let mut out = vec![0.0; n * n];
    if check_shape(m, n, Some(n), path, "N", "N", errs) {
        for i in 0..n {
            for j in 0..n {
                match compile_const(&m[i][j], params, &format!("{path}[{i}][{j}]")) {
                    Ok(x) => out[i * n + j] = x,
                    Err(e) => errs.push(e),
                }
            }
        }
    }
    out
}
