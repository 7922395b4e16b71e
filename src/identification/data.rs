//! The measurements of an identification ([`Data`]), read from a CSV file's text
//! ([`from_csv`]: the shell reads the file) or from the request's inline rows
//! ([`from_rows`]), and written back as CSV ([`to_csv`]).
//!
//! **The formats.** CSV: a header row, `t` first, then one column per measurement
//! name in any order (`t,z2,z1`), then one row per measured step. Cells are trimmed;
//! an empty cell is a missing measurement, every other cell a finite number (`nan`,
//! `inf` and text are errors). A trailing newline, CRLF line ends, a UTF-8 BOM and
//! RFC 4180 quoting are accepted; blank lines are skipped. Inline:
//! `"rows": [[t, z1, z2], …]`, each row of 1 + m entries in the model's order of
//! the measurements, `null` for a missing measurement (never for t).
//!
//! **The grid.** The result always has D = [`Grid::steps`] rows, row k at the grid's
//! t_k = t0 + k·Δt, k = 1…D, whose time is the grid's (not the input's digits). An
//! input row gives the step whose t_k its t matches within [`TOLERANCE`]·Δt, plus
//! 4ε·(|t0| + |t_k|) for f64's own rounding where the times are large (ε = 2⁻⁵²), so
//! that CSV decimals such as `0.3` or `0.30000000000000004` find t_3 = 3 × 0.1, and
//! epoch times find theirs. A step with no input row is a step whose measurements
//! are all missing. A t off the grid, before t_1, after t_D, or not greater than the
//! previous row's is an error; so are more input rows than D.
//!
//! **The errors.** Every problem found is listed (at most
//! [`crate::error::MAX_REPORTED_ERRORS`], then one entry counts the rest), each
//! saying what was expected. CSV errors sit at `path` (`data.csv`) and name the file
//! line and the data row, counted from 1 after the header, and the column:
//! `line 4 (data row 3), column "z1": "abc" is not a number …`. Inline errors sit at
//! their entry, counted from 0 as JSON paths are: `data.rows[2][1]`. The header's
//! errors are reported alone (without a header the rows cannot be read).
//!
//! **The limits.** At most [`MAX_ROWS`] input rows; the grid as the model allows it
//! (1 ≤ D ≤ [`crate::model::limits::MAX_STEPS`]). Nothing here panics, and the only
//! NaN in a result is a missing measurement.

use super::model::Data;
use crate::error::{Error, FieldError, MAX_REPORTED_ERRORS, got, omitted_entry};
use crate::model::limits::MAX_STEPS;
use crate::text::{csv_text, entries, num, short};
use serde_json::Value;

/// The most input rows read (a CSV of about 10⁶ lines is tens of MB).
pub const MAX_ROWS: usize = 1_000_000;

/// How near (in units of Δt) an input t must be to its grid time t_k.
pub const TOLERANCE: f64 = 1e-9;

/// The model's time grid t_k = t0 + k·Δt, k = 1…`steps` (D).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Grid {
    pub t0: f64,
    pub dt: f64,
    pub steps: usize,
}

impl Grid {
    /// The grid of D = `steps` steps from t0 to t_end: Δt = (t_end − t0)/D.
    pub fn new(t0: f64, t_end: f64, steps: usize) -> Grid {
        Grid {
            t0,
            dt: (t_end - t0) / steps as f64,
            steps,
        }
    }

    /// t_k = t0 + k·Δt, as the analysis computes it.
    pub fn t(&self, k: usize) -> f64 {
        self.t0 + k as f64 * self.dt
    }

    /// Refuse a grid that cannot hold data (the model's checks make this unreachable
    /// from a compiled model).
    fn check(&self, m: usize, path: &str) -> Result<(), Error> {
        let ok = self.t0.is_finite()
            && self.dt.is_finite()
            && self.dt > 0.0
            && (1..=MAX_STEPS as usize).contains(&self.steps)
            && self.t(self.steps).is_finite()
            && self.steps.checked_mul(m).is_some();
        if ok {
            return Ok(());
        }
        Err(Error::invalid(
            path,
            format!(
                "cannot be read against the model's time grid t0 = {}, Δt = {}, D = {}: expected a finite t0, Δt > 0 and 1 ≤ D ≤ {MAX_STEPS}",
                num(self.t0),
                num(self.dt),
                self.steps
            ),
        ))
    }

    /// The step k (1…D) whose t_k is `t` (written `written` in the input).
    fn step_of(&self, t: f64, written: &str) -> Result<usize, String> {
        let d = self.steps;
        let tol =
            |k: usize| TOLERANCE * self.dt + 4.0 * f64::EPSILON * (self.t0.abs() + self.t(k).abs());
        let x = (t - self.t0) / self.dt;
        let nearest = x.round();
        if nearest >= 1.0 && nearest <= d as f64 {
            let k = nearest as usize;
            if (t - self.t(k)).abs() <= tol(k) {
                return Ok(k);
            }
        }
        let steps = format!(
            "the steps are t_k = t0 + k·Δt, k = 1…{d}, with t0 = {}, Δt = {}",
            short(self.t0),
            short(self.dt)
        );
        if t < self.t(1) - tol(1) {
            return Err(format!(
                "t = {written} is before the model's first step t_1 = {} ({steps})",
                short(self.t(1))
            ));
        }
        if t > self.t(d) + tol(d) {
            return Err(format!(
                "t = {written} is after the model's last step t_{d} = {} ({steps})",
                short(self.t(d))
            ));
        }
        // (Here t_1 ≤ t ≤ t_D, so D ≥ 2 and the two steps either side exist.)
        let below = (x.floor().max(1.0) as usize).min(d - 1);
        Err(format!(
            "t = {written} is not on the model's grid t0 + k·Δt (t0 = {}, Δt = {}, within {TOLERANCE:e}·Δt): the nearest steps are t = {} and {}",
            short(self.t0),
            short(self.dt),
            short(self.t(below)),
            short(self.t(below + 1))
        ))
    }
}

/// The measurements in the CSV `text` (the format in the module's doc), the columns
/// matched to `names` (the model's measurements, in its order), on `grid`. `path` is
/// where the CSV sits in the request (`data.csv`): every error is at it.
pub fn from_csv(text: &str, names: &[String], grid: &Grid, path: &str) -> Result<Data, Error> {
    grid.check(names.len(), path)?;
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .trim(csv::Trim::All)
        .from_reader(text.as_bytes());
    let mut records = reader.records();
    let header = match records.next() {
        None => {
            return Err(Error::invalid(
                path,
                format!(
                    "empty: expected a header row, then a row per measured step; {}",
                    expected_columns(names)
                ),
            ));
        }
        Some(Err(e)) => return Err(Error::invalid(path, format!("header: {e}"))),
        Some(Ok(h)) => h,
    };
    let columns = header_columns(&header, names).map_err(|es| {
        let mut errs = Errors::default();
        for e in es {
            errs.push(FieldError::new(path, e));
        }
        errs.finish(None)
    })?;

    let mut fill = Fill::new(grid, names.len());
    let mut rows = 0;
    for record in records {
        rows += 1;
        if rows > MAX_ROWS {
            return Err(too_many(path, "the CSV has more than", grid));
        }
        let record = match record {
            Ok(r) => r,
            Err(e) => {
                // (From text, only a malformed record: the reader has no I/O to fail.)
                fill.errors
                    .push(FieldError::new(path, format!("data row {rows}: {e}")));
                break;
            }
        };
        let line = line_of(&record, text).unwrap_or(rows as u64 + 1);
        let at = format!("line {line} (data row {rows})");
        if record.len() != header.len() {
            fill.errors.push(FieldError::new(
                path,
                format!(
                    "{at}: {} fields, expected {} ({}), as in the header",
                    record.len(),
                    header.len(),
                    header.iter().collect::<Vec<_>>().join(", ")
                ),
            ));
            continue;
        }
        let cell = &record[0];
        let t = match number(cell) {
            Ok(Some(t)) => Some(t),
            Ok(None) => {
                let message = format!("{at}, column \"t\": empty; every row needs its time");
                fill.errors.push(FieldError::new(path, message));
                None
            }
            Err(what) => {
                let message = format!("{at}, column \"t\": \"{}\" {what}", shown(cell));
                fill.errors.push(FieldError::new(path, message));
                None
            }
        };
        let mut values = vec![f64::NAN; names.len()];
        for (c, &j) in columns.iter().enumerate() {
            let cell = &record[c + 1];
            match number(cell) {
                Ok(v) => values[j] = v.unwrap_or(f64::NAN),
                Err(what) => fill.errors.push(FieldError::new(
                    path,
                    format!(
                        "{at}, column \"{}\": \"{}\" {what} (an empty cell is a missing measurement)",
                        names[j],
                        shown(cell)
                    ),
                )),
            }
        }
        if let Some(t) = t {
            let label = format!("line {line}, data row {rows}");
            fill.row(t, &shown(cell), &values, &label, |m| {
                FieldError::new(path, format!("{at}: {m}"))
            });
        }
    }
    fill.finish(&format!("the CSV has {rows} data rows"), rows, path)
}

/// The measurements in the request's inline `rows`, `[[t, z1, z2, …], …]` (`null`:
/// missing), the values in the order of `names`, on `grid`; `path` is where the rows
/// sit in the request (`data.rows`), and each error is at its entry's path.
pub fn from_rows(rows: &Value, names: &[String], grid: &Grid, path: &str) -> Result<Data, Error> {
    grid.check(names.len(), path)?;
    let shape = format!("[t, {}]", names.join(", "));
    let shape = if names.is_empty() {
        "[t]".into()
    } else {
        shape
    };
    let Some(rows) = rows.as_array() else {
        return Err(Error::invalid(
            path,
            format!("expected an array of rows {shape}, got {}", got(rows)),
        ));
    };
    if rows.len() > MAX_ROWS {
        return Err(too_many(path, "more than", grid));
    }
    let m = names.len();
    let mut fill = Fill::new(grid, m);
    for (i, row) in rows.iter().enumerate() {
        let at = format!("{path}[{i}]");
        let cells = match row.as_array() {
            Some(c) if c.len() == 1 + m => c,
            Some(c) => {
                let message = format!(
                    "expected an array of {} {shape}, got {}",
                    entries(1 + m),
                    entries(c.len())
                );
                fill.errors.push(FieldError::new(at, message));
                continue;
            }
            None => {
                let message = format!("expected an array {shape}, got {}", got(row));
                fill.errors.push(FieldError::new(at, message));
                continue;
            }
        };
        let t = match &cells[0] {
            Value::Number(n) if n.as_f64().is_some_and(f64::is_finite) => Some(n),
            other => {
                let message = format!(
                    "expected a number, the time t (it cannot be missing), got {}",
                    got(other)
                );
                fill.errors
                    .push(FieldError::new(format!("{at}[0]"), message));
                None
            }
        };
        let mut values = vec![f64::NAN; m];
        for (j, name) in names.iter().enumerate() {
            match &cells[1 + j] {
                Value::Null => {}
                Value::Number(n) if n.as_f64().is_some_and(f64::is_finite) => {
                    values[j] = n.as_f64().unwrap_or(f64::NAN);
                }
                other => fill.errors.push(FieldError::new(
                    format!("{at}[{}]", 1 + j),
                    format!(
                        "expected a number, or null for a missing value, of measurement \"{name}\", got {}",
                        got(other)
                    ),
                )),
            }
        }
        if let Some(t) = t {
            let written = t.to_string();
            let t = t.as_f64().unwrap_or(f64::NAN);
            fill.row(t, &written, &values, &at, |m| {
                FieldError::new(format!("{at}[0]"), m)
            });
        }
    }
    fill.finish(&format!("{} rows", rows.len()), rows.len(), path)
}

/// `data` as CSV text that [`from_csv`] reads back to the same bits: the header
/// `t,name…`, then every row (a step with nothing measured too), an empty cell for a
/// missing value, numbers in Rust's shortest round-trip form.
pub fn to_csv(data: &Data, names: &[String]) -> String {
    let m = data.m;
    let header = std::iter::once("t".to_string()).chain(names.iter().cloned());
    let rows = (0..data.rows()).map(|k| {
        let z = data.z.get(k * m..k * m + m).unwrap_or(&[]);
        std::iter::once(num(data.t[k])).chain(
            z.iter()
                .map(|&v| if v.is_nan() { String::new() } else { num(v) }),
        )
    });
    csv_text(header, rows)
}

/// The header's columns 2… as indices into `names`, or every problem with it.
fn header_columns(header: &csv::StringRecord, names: &[String]) -> Result<Vec<usize>, Vec<String>> {
    let expected = expected_columns(names);
    let mut errors = Vec::new();
    let first = header.get(0).unwrap_or("");
    if first != "t" {
        let message = match header.iter().position(|h| h == "t") {
            Some(c) => format!(
                "header: `t` must be the first column, not column {}; {expected}",
                c + 1
            ),
            None if header.len() == 1 && (first.contains(';') || first.contains('\t')) => format!(
                "header: one column \"{}\": the columns are separated by commas; {expected}",
                shown(first)
            ),
            None => format!(
                "header: the first column must be `t`, the time, got \"{}\"; {expected}",
                shown(first)
            ),
        };
        errors.push(message);
    }
    let mut seen: Vec<Option<usize>> = vec![None; names.len()];
    let mut columns = Vec::new();
    for (c, h) in header.iter().enumerate() {
        if h == "t" {
            // (The first column's; or one elsewhere, said above or here.)
            if c > 0 && first == "t" {
                errors.push(format!(
                    "header: column \"t\" appears twice (columns 1 and {})",
                    c + 1
                ));
            }
            continue;
        }
        match names.iter().position(|n| n == h) {
            Some(j) => match seen[j] {
                Some(before) => errors.push(format!(
                    "header: column \"{}\" appears twice (columns {} and {})",
                    shown(h),
                    before + 1,
                    c + 1
                )),
                None => {
                    seen[j] = Some(c);
                    columns.push(j);
                }
            },
            // (The first column, not `t`, is said above.)
            None if c == 0 => {}
            None if h.is_empty() => {
                errors.push(format!("header: column {} has no name; {expected}", c + 1))
            }
            None => errors.push(format!(
                "header: column {} \"{}\" is not a measurement of the model; {expected}",
                c + 1,
                shown(h)
            )),
        }
    }
    for (j, name) in names.iter().enumerate() {
        if seen[j].is_none() {
            errors.push(format!(
                "header: no column for measurement \"{name}\"; {expected}"
            ));
        }
    }
    if errors.is_empty() {
        Ok(columns)
    } else {
        Err(errors)
    }
}

/// The line where `record` starts in `text`. (The reader puts a record after a blank
/// line at the blank line.)
fn line_of(record: &csv::StringRecord, text: &str) -> Option<u64> {
    let p = record.position()?;
    let rest = text.as_bytes().get(p.byte() as usize..)?;
    let blank = rest.iter().take_while(|&&b| b == b'\r' || b == b'\n');
    Some(p.line() + blank.filter(|&&b| b == b'\n').count() as u64)
}

/// "expected the columns t, then z1, z2 in any order".
fn expected_columns(names: &[String]) -> String {
    if names.is_empty() {
        "expected the single column t".into()
    } else {
        format!(
            "expected the columns t, then {} in any order",
            names.join(", ")
        )
    }
}

/// A cell as a message shows it: at most 40 characters, then "…".
pub(crate) fn shown(cell: &str) -> String {
    match cell.char_indices().nth(40) {
        Some((end, _)) => format!("{}…", &cell[..end]),
        None => cell.to_string(),
    }
}

/// A cell: empty (missing), a finite number, or what it is not.
pub(crate) fn number(cell: &str) -> Result<Option<f64>, &'static str> {
    if cell.is_empty() {
        return Ok(None);
    }
    match cell.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(Some(v)),
        Ok(_) => Err("is not a finite number"),
        Err(_) => Err("is not a number"),
    }
}

/// The error of an input beyond [`MAX_ROWS`].
fn too_many(path: &str, what: &str, grid: &Grid) -> Error {
    Error::invalid(
        path,
        format!(
            "{what} {MAX_ROWS} rows, the most kea reads (and the model has D = {} steps, at most one row each)",
            grid.steps
        ),
    )
}

/// The field errors found, the first [`MAX_REPORTED_ERRORS`] kept and the rest
/// counted (so that a file of bad cells does not build millions of them).
/// (Shared with the nonlinear data's reader, `crate::nonlinear::data`.)
#[derive(Default)]
pub(crate) struct Errors {
    kept: Vec<FieldError>,
    more: usize,
}

impl Errors {
    pub(crate) fn push(&mut self, e: FieldError) {
        if self.kept.len() < MAX_REPORTED_ERRORS {
            self.kept.push(e);
        } else {
            self.more += 1;
        }
    }

    /// Nothing found, or the errors as `Error::Invalid` ([`Errors::finish`]).
    pub(crate) fn result(self) -> Result<(), Error> {
        if self.kept.is_empty() {
            Ok(())
        } else {
            Err(self.finish(None))
        }
    }

    /// The errors as `Error::Invalid`, `first` ahead of the others, capped.
    fn finish(mut self, first: Option<FieldError>) -> Error {
        if let Some(e) = first {
            self.kept.insert(0, e);
        }
        let total = self.kept.len() + self.more;
        if total > MAX_REPORTED_ERRORS {
            self.kept.truncate(MAX_REPORTED_ERRORS);
            self.kept.push(omitted_entry(total - MAX_REPORTED_ERRORS));
        }
        Error::Invalid(self.kept)
    }
}

/// The data being filled in, row after row, with the errors found.
struct Fill<'a> {
    grid: &'a Grid,
    m: usize,
    z: Vec<f64>,
    /// The step, the t as written, and the label of the last row whose t is a step.
    last: Option<(usize, String, String)>,
    errors: Errors,
}

impl<'a> Fill<'a> {
    fn new(grid: &'a Grid, m: usize) -> Self {
        Fill {
            grid,
            m,
            z: vec![f64::NAN; grid.steps * m],
            last: None,
            errors: Errors::default(),
        }
    }

    /// An input row at `t` (written `written`, its row's `label` for later messages)
    /// with `values` (NaN: missing); `error` places a message about its t.
    fn row(
        &mut self,
        t: f64,
        written: &str,
        values: &[f64],
        label: &str,
        error: impl Fn(String) -> FieldError,
    ) {
        let k = match self.grid.step_of(t, written) {
            Ok(k) => k,
            Err(m) => return self.errors.push(error(m)),
        };
        // (Each row is checked against the one before it: every pair in order means
        // all in order, and one misplaced row is one error, not a cascade.)
        if let Some((before, t_before, at)) = &self.last {
            if k == *before {
                self.errors.push(error(format!(
                    "t = {written} is again the step t_{k} = {} of the previous row ({at}: t = {t_before}): each step takes at most one row",
                    short(self.grid.t(k))
                )));
            } else if k < *before {
                self.errors.push(error(format!(
                    "t = {written} is less than the previous row's t = {t_before} ({at}): the rows must be in increasing t"
                )));
            }
        }
        let m = self.m;
        self.z[(k - 1) * m..k * m].copy_from_slice(values);
        self.last = Some((k, written.to_string(), label.to_string()));
    }

    /// The data, or the errors, with the count of `rows` (`counted` in words: "the
    /// CSV has 5 data rows") checked against D.
    fn finish(self, counted: &str, rows: usize, path: &str) -> Result<Data, Error> {
        let d = self.grid.steps;
        let first = (rows > d).then(|| {
            FieldError::new(
                path,
                format!(
                    "{counted}, but the model has D = {d} steps: at most one row per step (a step without a row is missing)"
                ),
            )
        });
        if first.is_some() || !self.errors.kept.is_empty() {
            return Err(self.errors.finish(first));
        }
        Ok(Data {
            m: self.m,
            t: (1..=d).map(|k| self.grid.t(k)).collect(),
            z: self.z,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::error::omitted_count;
    use serde_json::json;

    fn names(n: &[&str]) -> Vec<String> {
        n.iter().map(|s| s.to_string()).collect()
    }

    /// t0 = 0, Δt = 0.1, D = `steps`.
    fn tenths(steps: usize) -> Grid {
        Grid {
            t0: 0.0,
            dt: 0.1,
            steps,
        }
    }

    /// The errors of `from_csv(text)` on z1, z2, as `path: message` lines.
    fn csv_errors(text: &str, grid: &Grid) -> Vec<String> {
        match from_csv(text, &names(&["z1", "z2"]), grid, "data.csv") {
            Ok(d) => panic!("expected errors, got {d:?}"),
            Err(e) => e.field_errors().iter().map(|e| e.to_string()).collect(),
        }
    }

    fn rows_errors(rows: &Value, grid: &Grid) -> Vec<String> {
        match from_rows(rows, &names(&["z1", "z2"]), grid, "data.rows") {
            Ok(d) => panic!("expected errors, got {d:?}"),
            Err(e) => e.field_errors().iter().map(|e| e.to_string()).collect(),
        }
    }

    /// The same bits, NaN included.
    fn assert_same(a: &Data, b: &Data) {
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(a.m, b.m);
        assert_eq!(bits(&a.t), bits(&b.t));
        assert_eq!(bits(&a.z), bits(&b.z));
    }

    #[test]
    fn columns_in_any_order_empty_cells_and_skipped_steps() {
        let grid = Grid {
            t0: 0.0,
            dt: 0.5,
            steps: 4,
        };
        let text = "t, z2 ,z1\n0.5, 2, 1\n 1 ,,3\n2,5,6\n";
        let d = from_csv(text, &names(&["z1", "z2"]), &grid, "data.csv").unwrap();
        assert_eq!(d.m, 2);
        assert_eq!(d.t, vec![0.5, 1.0, 1.5, 2.0]);
        let nan = f64::NAN;
        assert_same(
            &d,
            &Data {
                m: 2,
                t: vec![0.5, 1.0, 1.5, 2.0],
                // (1.5 has no row: all missing; 1 has no z2.)
                z: vec![1.0, 2.0, 3.0, nan, nan, nan, 6.0, 5.0],
            },
        );
    }

    #[test]
    fn decimals_find_their_grid_steps() {
        assert_eq!(3.0 * 0.1, 0.30000000000000004);
        let z = names(&["z"]);
        for third in ["0.3", "0.30000000000000004", "0.29999999995"] {
            let text = format!("t,z\n0.1,1\n0.2,2\n{third},3\n");
            let d = from_csv(&text, &z, &tenths(3), "data.csv").unwrap();
            assert_eq!(d.t, vec![0.1, 0.2, 0.30000000000000004], "{third}");
            assert_eq!(d.z, vec![1.0, 2.0, 3.0]);
        }
        // Beyond 1e-9·Δt (1e-10 here), a t is off the grid.
        let e = from_csv("t,z\n0.3000000002,1\n", &z, &tenths(4), "data.csv").unwrap_err();
        assert!(e.to_string().contains("is not on the model's grid"), "{e}");
        // Epoch times, where 1e-9·Δt is far below f64's spacing of t: f64's rounding
        // of t0 + k·Δt and of the decimal is allowed for.
        let grid = Grid::new(1234567890.1, 1234567890.1 + 100.0, 10000);
        assert_ne!("1234567890.13".parse::<f64>().unwrap(), grid.t(3)); // (one ulp)
        let d = from_csv(
            "t,z\n1234567890.13,1\n1234567890.14,2\n1234567990.1,3\n",
            &z,
            &grid,
            "data.csv",
        )
        .unwrap();
        let measured: Vec<usize> = (0..10000).filter(|&k| !d.z[k].is_nan()).collect();
        assert_eq!(measured, vec![2, 3, 9999]);
        assert_eq!(d.t[2], grid.t(3));
    }

    #[test]
    fn times_off_the_grid_out_of_range_repeated_or_out_of_order() {
        let grid = tenths(10);
        assert_eq!(
            csv_errors("t,z1,z2\n0.1,1,2\n0.35,1,2\n", &grid),
            [
                "data.csv: line 3 (data row 2): t = 0.35 is not on the model's grid t0 + k·Δt (t0 = 0, Δt = 0.1, within 1e-9·Δt): the nearest steps are t = 0.3 and 0.4"
            ]
        );
        assert_eq!(
            csv_errors("t,z1,z2\n0,1,2\n1.1,1,2\n", &grid),
            [
                "data.csv: line 2 (data row 1): t = 0 is before the model's first step t_1 = 0.1 (the steps are t_k = t0 + k·Δt, k = 1…10, with t0 = 0, Δt = 0.1)",
                "data.csv: line 3 (data row 2): t = 1.1 is after the model's last step t_10 = 1 (the steps are t_k = t0 + k·Δt, k = 1…10, with t0 = 0, Δt = 0.1)",
            ]
        );
        // A blank line is skipped, and the lines still counted.
        assert_eq!(
            csv_errors("t,z1,z2\n0.1,1,2\n\n0.2,1,2\n0.2,3,4\n", &grid),
            [
                "data.csv: line 5 (data row 3): t = 0.2 is again the step t_2 = 0.2 of the previous row (line 4, data row 2: t = 0.2): each step takes at most one row"
            ]
        );
        // One misplaced row is one error.
        assert_eq!(
            csv_errors("t,z1,z2\n0.1,1,2\n0.3,1,2\n0.2,3,4\n0.4,1,1\n", &grid),
            [
                "data.csv: line 4 (data row 3): t = 0.2 is less than the previous row's t = 0.3 (line 3, data row 2): the rows must be in increasing t"
            ]
        );
    }

    #[test]
    fn header_errors_name_the_column_and_the_expected_ones() {
        let grid = tenths(10);
        let expected = "expected the columns t, then z1, z2 in any order";
        assert_eq!(
            csv_errors("t,z1\n0.1,1\n", &grid),
            [format!(
                "data.csv: header: no column for measurement \"z2\"; {expected}"
            )]
        );
        assert_eq!(
            csv_errors("t,z1,z2,z3\n", &grid),
            [format!(
                "data.csv: header: column 4 \"z3\" is not a measurement of the model; {expected}"
            )]
        );
        assert_eq!(
            csv_errors("t,z1,z2,z1\n", &grid),
            ["data.csv: header: column \"z1\" appears twice (columns 2 and 4)"]
        );
        assert_eq!(
            csv_errors("t,z1,t,z2\n", &grid),
            ["data.csv: header: column \"t\" appears twice (columns 1 and 3)"]
        );
        assert_eq!(
            csv_errors("time,z1,z2\n", &grid),
            [format!(
                "data.csv: header: the first column must be `t`, the time, got \"time\"; {expected}"
            )]
        );
        assert_eq!(
            csv_errors("z1,t,z2\n", &grid),
            [format!(
                "data.csv: header: `t` must be the first column, not column 2; {expected}"
            )]
        );
        assert_eq!(
            csv_errors("t;z1;z2\n", &grid)[0],
            format!(
                "data.csv: header: one column \"t;z1;z2\": the columns are separated by commas; {expected}"
            )
        );
        assert_eq!(
            csv_errors("t,z1,z2,\n", &grid),
            [format!(
                "data.csv: header: column 4 has no name; {expected}"
            )]
        );
        assert_eq!(
            csv_errors("", &grid),
            [format!(
                "data.csv: empty: expected a header row, then a row per measured step; {expected}"
            )]
        );
    }

    #[test]
    fn cell_errors_name_the_line_the_column_and_the_value() {
        let grid = tenths(10);
        let long = "y".repeat(1000);
        assert_eq!(
            csv_errors(&format!("t,z1,z2\n0.1,{long},1\n"), &grid),
            [format!(
                "data.csv: line 2 (data row 1), column \"z1\": \"{}…\" is not a number (an empty cell is a missing measurement)",
                &long[..40]
            )]
        );
        assert_eq!(
            csv_errors("t,z1,z2\n0.1,1\n", &grid),
            ["data.csv: line 2 (data row 1): 2 fields, expected 3 (t, z1, z2), as in the header"]
        );
        let note = "(an empty cell is a missing measurement)";
        assert_eq!(
            csv_errors(
                "t,z1,z2\n0.1,1,2\n0.2,abc,2\n0.3,nan,inf\n,1,2\nx,1,2\n",
                &grid
            ),
            [
                format!(
                    "data.csv: line 3 (data row 2), column \"z1\": \"abc\" is not a number {note}"
                ),
                format!(
                    "data.csv: line 4 (data row 3), column \"z1\": \"nan\" is not a finite number {note}"
                ),
                format!(
                    "data.csv: line 4 (data row 3), column \"z2\": \"inf\" is not a finite number {note}"
                ),
                "data.csv: line 5 (data row 4), column \"t\": empty; every row needs its time"
                    .into(),
                "data.csv: line 6 (data row 5), column \"t\": \"x\" is not a number".into(),
            ]
        );
    }

    #[test]
    fn bom_crlf_and_quotes_are_read() {
        let text = "\u{feff}t,z1,\"z2\"\r\n0.1,1,2\r\n0.2,,\"3\"\r\n";
        let d = from_csv(text, &names(&["z1", "z2"]), &tenths(3), "data.csv").unwrap();
        assert_eq!(d.t, vec![0.1, 0.2, 0.30000000000000004]);
        assert_eq!(d.z[..2], [1.0, 2.0]);
        assert!(d.z[2].is_nan());
        assert_eq!(d.z[3], 3.0);
        assert!(d.z[4..].iter().all(|v| v.is_nan()));
        // The lines counted in a CRLF file with blank lines, and an error of the first
        // data row past them.
        let grid = tenths(10);
        assert_eq!(
            csv_errors(
                "\u{feff}t,z1,z2\r\n\r\n0.1,1,2\r\n\r\n\r\n0.2,x,2\r\n0.3,x,2",
                &grid
            ),
            [
                "data.csv: line 6 (data row 2), column \"z1\": \"x\" is not a number (an empty cell is a missing measurement)",
                "data.csv: line 7 (data row 3), column \"z1\": \"x\" is not a number (an empty cell is a missing measurement)",
            ]
        );
        assert_eq!(
            csv_errors("t,z1,z2\n\n0.1,x,2\n", &grid)[0],
            "data.csv: line 3 (data row 1), column \"z1\": \"x\" is not a number (an empty cell is a missing measurement)"
        );
    }

    #[test]
    fn inline_rows_with_null() {
        let rows = json!([[0.1, 1, null], [0.3, null, -2.5]]);
        let d = from_rows(&rows, &names(&["z1", "z2"]), &tenths(3), "data.rows").unwrap();
        let nan = f64::NAN;
        assert_same(
            &d,
            &Data {
                m: 2,
                t: vec![0.1, 0.2, 0.30000000000000004],
                z: vec![1.0, nan, nan, nan, nan, -2.5],
            },
        );
    }

    #[test]
    fn inline_rows_errors_at_their_entries() {
        let grid = tenths(10);
        let rows = json!([
            [null, 1, 2],
            [0.2, "a", 2],
            [0.3, 1],
            5,
            [0.25, 1, 2],
            [0.1, 1, 2]
        ]);
        assert_eq!(
            rows_errors(&rows, &grid),
            [
                "data.rows[0][0]: expected a number, the time t (it cannot be missing), got null",
                "data.rows[1][1]: expected a number, or null for a missing value, of measurement \"z1\", got a string (\"a\")",
                "data.rows[2]: expected an array of 3 entries [t, z1, z2], got 2 entries",
                "data.rows[3]: expected an array [t, z1, z2], got 5",
                "data.rows[4][0]: t = 0.25 is not on the model's grid t0 + k·Δt (t0 = 0, Δt = 0.1, within 1e-9·Δt): the nearest steps are t = 0.2 and 0.3",
                "data.rows[5][0]: t = 0.1 is less than the previous row's t = 0.2 (data.rows[1]): the rows must be in increasing t",
            ]
        );
        assert_eq!(
            rows_errors(&json!({"t": [0.1]}), &grid),
            ["data.rows: expected an array of rows [t, z1, z2], got an object"]
        );
        assert_eq!(
            rows_errors(&json!([[0.1, 1, 2], [0.1, 1, 2]]), &grid),
            [
                "data.rows[1][0]: t = 0.1 is again the step t_1 = 0.1 of the previous row (data.rows[0]: t = 0.1): each step takes at most one row"
            ]
        );
    }

    #[test]
    fn more_rows_than_steps() {
        let grid = Grid {
            t0: 0.0,
            dt: 0.5,
            steps: 2,
        };
        let errors = csv_errors("t,z1,z2\n0.5,1,2\n1,1,2\n1.5,1,2\n", &grid);
        assert_eq!(
            errors[0],
            "data.csv: the CSV has 3 data rows, but the model has D = 2 steps: at most one row per step (a step without a row is missing)"
        );
        assert!(errors[1].contains("line 4 (data row 3): t = 1.5 is after"));
        let errors = rows_errors(&json!([[0.5, 1, 2], [1, 1, 2], [1.5, 1, 2]]), &grid);
        assert!(
            errors[0].starts_with("data.rows: 3 rows, but the model has D = 2 steps"),
            "{}",
            errors[0]
        );
        assert_eq!(errors.len(), 2);
    }

    #[test]
    fn at_most_max_rows_are_read() {
        let grid = Grid {
            t0: 0.0,
            dt: 1.0,
            steps: 2 * MAX_ROWS,
        };
        let rows = Value::Array(vec![Value::Null; MAX_ROWS + 1]);
        let e = from_rows(&rows, &[], &grid, "data.rows").unwrap_err();
        assert_eq!(
            e.to_string(),
            "data.rows: more than 1000000 rows, the most kea reads (and the model has D = 2000000 steps, at most one row each)"
        );
        let mut text = String::from("t\n");
        for k in 1..=MAX_ROWS {
            text.push_str(&format!("{k}\n"));
        }
        assert_eq!(
            from_csv(&text, &[], &grid, "data.csv").unwrap().rows(),
            2 * MAX_ROWS
        );
        text.push_str(&format!("{}\n", MAX_ROWS + 1));
        let e = from_csv(&text, &[], &grid, "data.csv").unwrap_err();
        assert!(
            e.to_string()
                .starts_with("data.csv: the CSV has more than 1000000 rows"),
            "{e}"
        );
    }

    #[test]
    fn the_error_list_is_capped() {
        let grid = tenths(200);
        let text = |rows: usize| {
            let mut text = String::from("t,z1,z2\n");
            for k in 1..=rows {
                text.push_str(&format!("{},x,1\n", k as f64 / 10.0));
            }
            text
        };
        let list = |e: Error| e.field_errors();
        let e = list(from_csv(&text(150), &names(&["z1", "z2"]), &grid, "data.csv").unwrap_err());
        assert_eq!(e.len(), MAX_REPORTED_ERRORS + 1);
        assert!(
            e[0].message
                .starts_with("line 2 (data row 1), column \"z1\"")
        );
        assert_eq!(omitted_count(&e[MAX_REPORTED_ERRORS]), Some(50));
        // With more rows than steps, that comes first, and counts among the errors
        // (250 rows past the 200 steps: 250 cells, 50 times after t_D, and the count).
        let e = list(from_csv(&text(250), &names(&["z1", "z2"]), &grid, "data.csv").unwrap_err());
        assert_eq!(e.len(), MAX_REPORTED_ERRORS + 1);
        assert!(e[0].message.starts_with("the CSV has 250 data rows"));
        assert_eq!(
            omitted_count(&e[MAX_REPORTED_ERRORS]),
            Some(301 - MAX_REPORTED_ERRORS)
        );
    }

    #[test]
    fn a_grid_that_cannot_hold_data_is_an_error() {
        let z = names(&["z"]);
        for grid in [
            Grid {
                t0: 0.0,
                dt: 0.0,
                steps: 3,
            },
            Grid {
                t0: 0.0,
                dt: f64::NAN,
                steps: 3,
            },
            Grid {
                t0: f64::INFINITY,
                dt: 1.0,
                steps: 3,
            },
            Grid {
                t0: 0.0,
                dt: 1.0,
                steps: 0,
            },
            Grid {
                t0: 0.0,
                dt: 1e308,
                steps: 10,
            },
        ] {
            let e = from_csv("t,z\n", &z, &grid, "data.csv").unwrap_err();
            assert!(e.to_string().contains("the model's time grid"), "{e}");
            assert!(from_rows(&json!([]), &z, &grid, "data.rows").is_err());
        }
    }

    #[test]
    fn to_csv_reads_back_bit_for_bit() {
        let nan = f64::NAN;
        let grid = Grid::new(0.1, 1.0, 4);
        let values = [
            0.1 + 0.2,
            -0.0,
            1e-300,
            1e300,
            nan,
            f64::MIN_POSITIVE,
            nan,
            nan,
            nan,
            5e-324,
            -1.5,
            1.0 / 3.0,
        ];
        let d = Data {
            m: 3,
            t: (1..=4).map(|k| grid.t(k)).collect(),
            z: values.to_vec(),
        };
        let n = names(&["a", "b", "c"]);
        let text = to_csv(&d, &n);
        assert!(
            text.starts_with("t,a,b,c\n0.325,0.30000000000000004,-0,1e-300\n"),
            "{text}"
        );
        assert!(text.contains(",,,\n"), "{text}"); // the step with nothing measured
        assert_same(&from_csv(&text, &n, &grid, "data.csv").unwrap(), &d);
    }
}
