//! The measurements of a nonlinear run ([`Measured`]), from a CSV file's text
//! ([`from_csv`]: the shell reads the file) or the request's inline rows
//! ([`from_rows`]), and, where the data carry them, the true states.
//!
//! **CSV.** A header row naming the columns, in any order: `t`; one column per
//! measurement name (each required); optionally `STATE_true` per state (the truth,
//! e.g. `x1_true`) — kea then reports the true errors. Other columns (a row counter
//! `n`, notes) are ignored and listed in the result. Cells are trimmed; an empty
//! cell is a missing value; any other cell must be a finite number. Rows sit on the
//! model's grid t_n = t0 + nΔt, n = 0…D, in increasing time, each t within
//! [`TOLERANCE`]·Δt of its t_n; a row at t0 may hold the truth there but no
//! measurement (the filters start from x⁰ at t0; the first measurement is at t_1). A
//! step with no row has nothing measured and no truth.
//!
//! **Inline.** `"rows": [[t, y1, …, yn], …]` in the model's order of the
//! measurements, `null` for a missing one; no truth.
//!
//! **Errors** name the line, the data row (from 1 after the header), the column and
//! the cell (`line 4 (data row 3), column "y": "abc" is not a number`), or the inline
//! entry's path (`data.rows[2][1]`); at most [`crate::error::MAX_REPORTED_ERRORS`] are listed.

use crate::error::{Error, FieldError, got};
use crate::identification::data::{Errors, number, shown};
use crate::text::short;
use serde_json::Value;

pub use crate::identification::data::{Grid, TOLERANCE};

/// The most rows read: one per grid point of the longest grid (D ≤ 10⁷ here: 10⁷
/// rows of CSV are hundreds of MB).
pub const MAX_ROWS: usize = 10_000_001;

/// The data on the model's grid.
#[derive(Clone, Debug, Default)]
pub struct Measured {
    /// m values per step n = 1…D (row n−1), NaN where not measured.
    pub y: Vec<f64>,
    /// N values per grid point n = 0…D, NaN where unknown; None without truth.
    pub truth: Option<Vec<f64>>,
    /// The columns ignored.
    pub ignored: Vec<String>,
}

/// The grid index n (0…D) of `t` (written `written`), or why there is none: the
/// nonlinear grid starts at t0 (n = 0), the identification's at t_1.
fn index(grid: &Grid, t: f64, written: &str) -> Result<usize, String> {
    let d = grid.steps;
    let tol =
        |n: usize| TOLERANCE * grid.dt + 4.0 * f64::EPSILON * (grid.t0.abs() + grid.t(n).abs());
    let nearest = ((t - grid.t0) / grid.dt).round();
    if nearest >= 0.0 && nearest <= d as f64 {
        let n = nearest as usize;
        if (t - grid.t(n)).abs() <= tol(n) {
            return Ok(n);
        }
    }
    Err(format!(
        "t = {written} is not on the model's grid t_n = t0 + n·Δt, n = 0…{d} (t0 = {}, Δt = {}, t_D = {}, within {TOLERANCE:e}·Δt)",
        short(grid.t0),
        short(grid.dt),
        short(grid.t(d))
    ))
}

/// The rows placed on the grid, in order.
struct Fill {
    grid: Grid,
    m: usize,
    n_states: usize,
    y: Vec<f64>,
    truth: Option<Vec<f64>>,
    last: Option<usize>,
}

impl Fill {
    fn new(grid: Grid, m: usize, n_states: usize, with_truth: bool) -> Fill {
        Fill {
            grid,
            m,
            n_states,
            y: vec![f64::NAN; grid.steps * m],
            truth: with_truth.then(|| vec![f64::NAN; (grid.steps + 1) * n_states]),
            last: None,
        }
    }

    /// Place one row at `t`; `Err(message)` when it cannot be.
    fn row(&mut self, t: f64, written: &str, y: &[f64], truth: &[f64]) -> Result<(), String> {
        let n = index(&self.grid, t, written)?;
        if let Some(last) = self.last
            && n <= last
        {
            return Err(format!(
                "t = {written} is not after the previous row's t = {} (the rows must be in increasing time, one per step)",
                short(self.grid.t(last))
            ));
        }
        if n == 0 && y.iter().any(|v| v.is_finite()) {
            return Err(format!(
                "t = {written} is t0, where the filters start from the model's y0: a measurement there cannot be used (the first is at t_1 = {})",
                short(self.grid.t(1))
            ));
        }
        self.last = Some(n);
        if n > 0 {
            self.y[(n - 1) * self.m..n * self.m].copy_from_slice(y);
        }
        if let Some(tr) = &mut self.truth {
            tr[n * self.n_states..(n + 1) * self.n_states].copy_from_slice(truth);
        }
        Ok(())
    }
}

/// What a column holds.
#[derive(Clone, Copy)]
enum Column {
    T,
    Measurement(usize),
    Truth(usize),
    Ignored,
}

/// The data in the CSV `text` (the module's format), for the measurements `names`
/// and the states `states`, on `grid`; every error at `path` (`data.csv`).
pub fn from_csv(
    text: &str,
    names: &[String],
    states: &[String],
    grid: Grid,
    path: &str,
) -> Result<Measured, Error> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .trim(csv::Trim::All)
        .from_reader(text.as_bytes());
    let mut records = reader.records();
    let expected = format!(
        "expected the columns t and {} in any order, and optionally {}",
        names.join(", "),
        states
            .iter()
            .map(|s| format!("{s}_true"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    let header = match records.next() {
        None => return Err(Error::invalid(path, format!("empty: {expected}"))),
        Some(Err(e)) => return Err(Error::invalid(path, format!("header: {e}"))),
        Some(Ok(h)) => h,
    };
    let mut errs = Errors::default();
    let mut columns = Vec::with_capacity(header.len());
    let mut ignored = Vec::new();
    let mut seen: Vec<(String, usize)> = Vec::new();
    for (c, h) in header.iter().enumerate() {
        let column = if h == "t" {
            Column::T
        } else if let Some(j) = names.iter().position(|n| n == h) {
            Column::Measurement(j)
        } else if let Some(i) = states
            .iter()
            .position(|s| h.strip_suffix("_true") == Some(s))
        {
            Column::Truth(i)
        } else {
            ignored.push(h.to_string());
            Column::Ignored
        };
        if !matches!(column, Column::Ignored) {
            if let Some((_, before)) = seen.iter().find(|(name, _)| name == h) {
                errs.push(FieldError::new(
                    path,
                    format!(
                        "header: column \"{}\" appears twice (columns {} and {})",
                        shown(h),
                        before + 1,
                        c + 1
                    ),
                ));
            }
            seen.push((h.to_string(), c));
        }
        columns.push(column);
    }
    if !columns.iter().any(|c| matches!(c, Column::T)) {
        errs.push(FieldError::new(
            path,
            format!("header: no column \"t\"; {expected}"),
        ));
    }
    for (j, name) in names.iter().enumerate() {
        if !columns
            .iter()
            .any(|c| matches!(c, Column::Measurement(k) if *k == j))
        {
            errs.push(FieldError::new(
                path,
                format!("header: no column for measurement \"{name}\"; {expected}"),
            ));
        }
    }
    errs.result()?;
    let with_truth = columns.iter().any(|c| matches!(c, Column::Truth(_)));
    let mut fill = Fill::new(grid, names.len(), states.len(), with_truth);
    let mut errs = Errors::default();
    let mut y = vec![f64::NAN; names.len()];
    let mut truth = vec![f64::NAN; states.len()];
    let mut rows = 0usize;
    for record in records {
        rows += 1;
        if rows > MAX_ROWS {
            return Err(Error::invalid(
                path,
                format!("more than {MAX_ROWS} rows, the most kea reads"),
            ));
        }
        let record = match record {
            Ok(r) => r,
            Err(e) => {
                errs.push(FieldError::new(path, format!("data row {rows}: {e}")));
                break;
            }
        };
        let line = record.position().map_or(rows as u64 + 1, |p| p.line());
        let at = || format!("line {line} (data row {rows})");
        if record.len() != header.len() {
            errs.push(FieldError::new(
                path,
                format!(
                    "{}: {} fields, expected {} as in the header",
                    at(),
                    record.len(),
                    header.len()
                ),
            ));
            continue;
        }
        y.fill(f64::NAN);
        truth.fill(f64::NAN);
        let mut t = None;
        let mut ok = true;
        for (c, column) in columns.iter().enumerate() {
            let cell = &record[c];
            let slot = match *column {
                Column::Ignored => continue,
                Column::T => None,
                Column::Measurement(j) => Some(&mut y[j]),
                Column::Truth(i) => Some(&mut truth[i]),
            };
            match (number(cell), slot) {
                (Ok(Some(v)), None) => t = Some(v),
                (Ok(None), None) => {
                    errs.push(FieldError::new(
                        path,
                        format!("{}, column \"t\": empty; every row needs its time", at()),
                    ));
                    ok = false;
                }
                (Ok(v), Some(slot)) => *slot = v.unwrap_or(f64::NAN),
                (Err(what), _) => {
                    errs.push(FieldError::new(
                        path,
                        format!(
                            "{}, column \"{}\": \"{}\" {what} (an empty cell is a missing value)",
                            at(),
                            shown(&header[c]),
                            shown(cell)
                        ),
                    ));
                    ok = false;
                }
            }
        }
        if let (true, Some(t)) = (ok, t) {
            let written = record[columns
                .iter()
                .position(|c| matches!(c, Column::T))
                .unwrap_or(0)]
            .to_string();
            if let Err(m) = fill.row(t, &written, &y, &truth) {
                errs.push(FieldError::new(
                    path,
                    format!("{}, column \"t\": {m}", at()),
                ));
            }
        }
    }
    errs.result()?;
    Ok(Measured {
        y: fill.y,
        truth: fill.truth,
        ignored,
    })
}

/// The data in the request's inline `rows` (`[[t, y1, …], …]`, `null`: missing), the
/// values in the order of `names`, on `grid`; each error at its entry (`data.rows[2][1]`).
pub fn from_rows(
    rows: &Value,
    names: &[String],
    grid: Grid,
    path: &str,
) -> Result<Measured, Error> {
    let shape = format!("[t, {}]", names.join(", "));
    let Some(rows) = rows.as_array() else {
        return Err(Error::invalid(
            path,
            format!("expected an array of rows {shape}, got {}", got(rows)),
        ));
    };
    if rows.len() > MAX_ROWS {
        return Err(Error::invalid(
            path,
            format!("more than {MAX_ROWS} rows, the most kea reads"),
        ));
    }
    let m = names.len();
    let mut fill = Fill::new(grid, m, 0, false);
    let mut errs = Errors::default();
    let mut y = vec![f64::NAN; m];
    for (i, row) in rows.iter().enumerate() {
        let at = format!("{path}[{i}]");
        let Some(cells) = row.as_array().filter(|c| c.len() == 1 + m) else {
            errs.push(FieldError::new(
                at,
                format!(
                    "expected an array {shape} of {} numbers, got {}",
                    1 + m,
                    got(row)
                ),
            ));
            continue;
        };
        let t = cells[0].as_f64().filter(|t| t.is_finite());
        if t.is_none() {
            errs.push(FieldError::new(
                format!("{at}[0]"),
                format!("expected a number, the time t, got {}", got(&cells[0])),
            ));
        }
        y.fill(f64::NAN);
        let mut ok = t.is_some();
        for j in 0..m {
            match &cells[1 + j] {
                Value::Null => {}
                Value::Number(v) if v.as_f64().is_some_and(f64::is_finite) => {
                    y[j] = v.as_f64().unwrap_or(f64::NAN);
                }
                other => {
                    errs.push(FieldError::new(
                        format!("{at}[{}]", 1 + j),
                        format!(
                            "expected a number, or null for a missing value, of measurement \"{}\", got {}",
                            names[j],
                            got(other)
                        ),
                    ));
                    ok = false;
                }
            }
        }
        if let (true, Some(t)) = (ok, t)
            && let Err(message) = fill.row(t, &cells[0].to_string(), &y, &[])
        {
            errs.push(FieldError::new(format!("{at}[0]"), message));
        }
    }
    errs.result()?;
    Ok(Measured {
        y: fill.y,
        truth: None,
        ignored: Vec::new(),
    })
}

/// `data` as CSV text that [`from_csv`] reads back to the same bits: `t`, the
/// measurements, then `STATE_true` per state where there is a truth; one row per grid
/// point n = 0…D (the row at t0 holds only the truth), an empty cell for a missing
/// value, numbers in Rust's shortest round-trip form.
pub fn to_csv(data: &Measured, names: &[String], states: &[String], grid: Grid) -> String {
    let (m, n) = (names.len(), states.len());
    let mut header = vec!["t".to_string()];
    header.extend(names.iter().cloned());
    if data.truth.is_some() {
        header.extend(states.iter().map(|s| format!("{s}_true")));
    }
    let cell = |v: f64| {
        if v.is_nan() {
            String::new()
        } else {
            crate::text::num(v)
        }
    };
    let first = if data.truth.is_some() { 0 } else { 1 };
    let rows = (first..=grid.steps).map(|k| {
        let mut row = vec![crate::text::num(grid.t(k))];
        for j in 0..m {
            row.push(if k == 0 {
                String::new()
            } else {
                cell(data.y[(k - 1) * m + j])
            });
        }
        if let Some(tr) = &data.truth {
            row.extend(tr[k * n..(k + 1) * n].iter().map(|&v| cell(v)));
        }
        row
    });
    crate::text::csv_text(header, rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid() -> Grid {
        Grid {
            t0: 0.0,
            dt: 0.1,
            steps: 3,
        }
    }

    fn s(v: &[&str]) -> Vec<String> {
        v.iter().map(|x| x.to_string()).collect()
    }

    #[test]
    fn columns_in_any_order_truth_and_ignored() {
        let text = "n,t,x1_true,y\n0,0,5,\n1,0.1,6,6.5\n3,0.30000000000000004,,7\n";
        let d = from_csv(text, &s(&["y"]), &s(&["x1", "x2"]), grid(), "data.csv").unwrap();
        assert_eq!(d.ignored, vec!["n"]);
        assert_eq!(d.y[0], 6.5);
        assert!(d.y[1].is_nan());
        assert_eq!(d.y[2], 7.0);
        let tr = d.truth.unwrap();
        assert_eq!((tr[0], tr[2]), (5.0, 6.0));
        assert!(tr[1].is_nan() && tr[6].is_nan());
    }

    #[test]
    fn errors_name_the_row_the_column_and_the_cell() {
        let text = "t,y\n0.1,abc\n0.25,1\n0.2,1\n0,3\n";
        let e = from_csv(text, &s(&["y"]), &s(&["x1"]), grid(), "data.csv")
            .unwrap_err()
            .field_errors();
        let messages: Vec<&str> = e.iter().map(|e| e.message.as_str()).collect();
        assert!(
            messages[0].contains("line 2 (data row 1), column \"y\": \"abc\" is not a number"),
            "{messages:?}"
        );
        assert!(
            messages[1].contains("data row 2") && messages[1].contains("not on the model's grid"),
            "{messages:?}"
        );
        assert!(
            messages[2].contains("data row 4") && messages[2].contains("not after"),
            "{messages:?}"
        );
        let e = from_csv("t,z\n", &s(&["y"]), &s(&["x1"]), grid(), "data.csv").unwrap_err();
        assert!(
            e.field_errors()[0]
                .message
                .contains("no column for measurement \"y\"")
        );
    }

    #[test]
    fn written_and_read_back_to_the_same_bits() {
        let text = "t,y,x1_true,x2_true\n0,,5,1\n0.1,6.123456789012345,6,\n0.3,7,,2\n";
        let d = from_csv(text, &s(&["y"]), &s(&["x1", "x2"]), grid(), "data.csv").unwrap();
        let back = to_csv(&d, &s(&["y"]), &s(&["x1", "x2"]), grid());
        let again = from_csv(&back, &s(&["y"]), &s(&["x1", "x2"]), grid(), "data.csv").unwrap();
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&d.y), bits(&again.y));
        assert_eq!(
            bits(d.truth.as_ref().unwrap()),
            bits(again.truth.as_ref().unwrap())
        );
    }

    #[test]
    fn inline_rows() {
        let rows = serde_json::json!([[0.1, 1.0], [0.2, null], [0.3, "x"]]);
        let e = from_rows(&rows, &s(&["y"]), grid(), "data.rows").unwrap_err();
        assert_eq!(e.field_errors()[0].path, "data.rows[2][1]");
        let rows = serde_json::json!([[0.1, 1.0], [0.3, 2.0]]);
        let d = from_rows(&rows, &s(&["y"]), grid(), "data.rows").unwrap();
        assert_eq!(d.y[0], 1.0);
        assert!(d.y[1].is_nan());
        assert_eq!(d.y[2], 2.0);
    }
}
