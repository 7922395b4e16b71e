//! Which entries of a model depend on which params. A compiled model holds every
//! entry's value at the params' values (a constant entry is folded to its number), so
//! what an entry owes to a param is recorded here, beside it: the maximum-likelihood
//! identification (METHOD §3) needs ∂/∂θ of every entry that θ enters, and the
//! nonlinear procedure (METHOD §4) the entries' own texts, which the model keeps.

use super::{Model, Value};
use std::collections::BTreeMap;

/// The message for a name that is none of the model's params, listing them: one
/// wording for `set`, a synthesis's params, an identification's `estimate` and truth.
pub fn unknown_param(params: &BTreeMap<String, f64>, name: &str) -> String {
    let known: Vec<&str> = params.keys().map(String::as_str).collect();
    let known = if known.is_empty() {
        "none".to_string()
    } else {
        known.join(", ")
    };
    format!("no parameter \"{name}\" in the model (params: {known})")
}

/// A member of a model whose entries may be expressions.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Member {
    /// `system.a` (N×N).
    A,
    /// `system.transition` (N×N, Φ of a discrete model).
    Transition,
    /// `system.u` (N).
    U,
    /// `system.b` (N×L).
    B,
    /// `system.y0` (N).
    Y0,
    /// `system.eta0` (N).
    Eta0,
    /// `system.phi` (L).
    Phi,
    /// `system.W` (L×L).
    W,
    /// `measurement.c` (n×N).
    C,
    /// `measurement.gamma` (n×M).
    Gamma,
    /// `measurement.g` (N×M).
    G,
    /// `measurement.psi` (M).
    Psi,
    /// `measurement.V` (M×M).
    V,
    /// `measurement.schedule[i].when` (one text per measurement).
    When,
}

impl Member {
    /// The member's path in the model (`system.a`).
    pub fn path(self) -> &'static str {
        match self {
            Member::A => "system.a",
            Member::Transition => "system.transition",
            Member::U => "system.u",
            Member::B => "system.b",
            Member::Y0 => "system.y0",
            Member::Eta0 => "system.eta0",
            Member::Phi => "system.phi",
            Member::W => "system.W",
            Member::C => "measurement.c",
            Member::Gamma => "measurement.gamma",
            Member::G => "measurement.g",
            Member::Psi => "measurement.psi",
            Member::V => "measurement.V",
            Member::When => "measurement.schedule",
        }
    }
}

/// One entry of a model: its member, row and column (0 for a vector's; for `When`,
/// the row is the measurement).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct EntryRef {
    pub member: Member,
    pub row: usize,
    pub col: usize,
}

impl EntryRef {
    /// The entry's field path (`system.a[0][1]`, `system.u[2]`,
    /// `measurement.schedule[1].when`), as errors name it.
    pub fn path(&self) -> String {
        let m = self.member.path();
        match self.member {
            Member::A
            | Member::Transition
            | Member::B
            | Member::W
            | Member::C
            | Member::Gamma
            | Member::G
            | Member::V => {
                format!("{m}[{}][{}]", self.row, self.col)
            }
            Member::When => format!("{m}[{}].when", self.row),
            _ => format!("{m}[{}]", self.row),
        }
    }

    /// The entry as the model writes it.
    pub fn value<'m>(&self, model: &'m Model) -> Option<&'m Value> {
        let (s, m) = (&model.system, &model.measurement);
        let matrix = |x: Option<&'m Vec<Vec<Value>>>| x?.get(self.row)?.get(self.col);
        let vector = |x: Option<&'m Vec<Value>>| x?.get(self.row);
        match self.member {
            Member::A => matrix(Some(&s.a)),
            Member::Transition => matrix(s.transition.as_ref()),
            Member::U => vector(s.u.as_ref()),
            Member::B => matrix(Some(&s.b)),
            Member::Y0 => vector(s.y0.as_ref()),
            Member::Eta0 => vector(s.eta0.as_ref()),
            Member::Phi => vector(s.phi.as_ref()),
            Member::W => matrix(s.w.as_ref()),
            Member::C => matrix(Some(&m.c)),
            Member::Gamma => matrix(m.gamma.as_ref()),
            Member::G => matrix(m.g.as_ref()),
            Member::Psi => vector(m.psi.as_ref()),
            Member::V => matrix(m.v.as_ref()),
            Member::When => m.schedule.as_ref()?.get(self.row)?.as_ref()?.when.as_ref(),
        }
    }
}

/// For each param, the entries whose expressions name it (in the model's order).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ParamDependence {
    by_param: BTreeMap<String, Vec<EntryRef>>,
}

impl ParamDependence {
    /// The dependence of `model`'s entries on its params.
    pub fn of(model: &Model) -> ParamDependence {
        let mut by_param: BTreeMap<String, Vec<EntryRef>> = BTreeMap::new();
        for (entry, text) in expressions(model) {
            for name in crate::expr::names(text) {
                if model.params.contains_key(&name) {
                    by_param.entry(name).or_default().push(entry);
                }
            }
        }
        ParamDependence { by_param }
    }

    /// The entries `param` enters (none for a param no expression names).
    pub fn entries(&self, param: &str) -> &[EntryRef] {
        self.by_param.get(param).map_or(&[], Vec::as_slice)
    }

    /// The params some entry depends on, in name order.
    pub fn params(&self) -> impl Iterator<Item = &str> {
        self.by_param.keys().map(String::as_str)
    }
}

/// Every entry of `model` written as an expression, with its text.
fn expressions(model: &Model) -> Vec<(EntryRef, &str)> {
    let (s, m) = (&model.system, &model.measurement);
    let matrices = [
        (Member::A, Some(&s.a)),
        (Member::Transition, s.transition.as_ref()),
        (Member::B, Some(&s.b)),
        (Member::W, s.w.as_ref()),
        (Member::C, Some(&m.c)),
        (Member::Gamma, m.gamma.as_ref()),
        (Member::G, m.g.as_ref()),
        (Member::V, m.v.as_ref()),
    ];
    let vectors = [
        (Member::U, s.u.as_ref()),
        (Member::Y0, s.y0.as_ref()),
        (Member::Eta0, s.eta0.as_ref()),
        (Member::Phi, s.phi.as_ref()),
        (Member::Psi, m.psi.as_ref()),
    ];
    fn text(v: &Value) -> Option<&str> {
        match v {
            Value::Expr(t) => Some(t.as_str()),
            Value::Number(_) => None,
        }
    }
    let mut out = Vec::new();
    for (member, rows) in matrices {
        for (row, cols) in rows.into_iter().flatten().enumerate() {
            for (col, v) in cols.iter().enumerate() {
                if let Some(t) = text(v) {
                    out.push((EntryRef { member, row, col }, t));
                }
            }
        }
    }
    for (member, values) in vectors {
        for (row, v) in values.into_iter().flatten().enumerate() {
            if let Some(t) = text(v) {
                out.push((
                    EntryRef {
                        member,
                        row,
                        col: 0,
                    },
                    t,
                ));
            }
        }
    }
    for (row, schedule) in m.schedule.iter().flatten().enumerate() {
        if let Some(t) = schedule
            .as_ref()
            .and_then(|s| s.when.as_ref())
            .and_then(text)
        {
            let entry = EntryRef {
                member: Member::When,
                row,
                col: 0,
            };
            out.push((entry, t));
        }
    }
    out.sort_by_key(|(e, _)| *e);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn model(json: serde_json::Value) -> Model {
        crate::model::model_from_value(json).expect("a model")
    }

    #[test]
    fn entries_are_found_by_the_params_their_texts_name() {
        let m = model(serde_json::json!({
            "kea_model": 1,
            "params": {"q": 0.5, "tau": 2, "qq": 1},
            "time": {"t0": 0, "t_end": 1, "steps": 10},
            "system": {
                "states": ["x", "v"],
                "a": [[0, 1], ["-1/tau", "-2*q*sin(t)"]],
                "b": [[0], ["qq"]],
                "phi": ["sqrt(q)"],
                "eta0": [1, 1]
            },
            "measurement": {"names": ["z"], "c": [[1, 0]], "gamma": [["1 + 0*tau"]], "psi": [0.1]}
        }));
        let d = ParamDependence::of(&m);
        let paths = |p: &str| d.entries(p).iter().map(EntryRef::path).collect::<Vec<_>>();
        // `q` is not `qq`, and `sin` or `t` are no params.
        assert_eq!(paths("q"), ["system.a[1][1]", "system.phi[0]"]);
        assert_eq!(paths("tau"), ["system.a[1][0]", "measurement.gamma[0][0]"]);
        assert_eq!(paths("qq"), ["system.b[1][0]"]);
        assert!(d.entries("nope").is_empty());
        assert_eq!(d.params().collect::<Vec<_>>(), ["q", "qq", "tau"]);
        // Each entry reads back as the model wrote it.
        let first = d.entries("tau")[0];
        assert_eq!(first.value(&m), Some(&Value::Expr("-1/tau".into())));
    }

    #[test]
    fn a_compiled_model_keeps_the_dependence_that_folding_hides() {
        // cv-tracker: W = q (through φ = sqrt-free `q`), ψ = `r`; folded to numbers.
        let m = crate::presets::get("cv-tracker").unwrap();
        let c = crate::model::compile(&m, &Default::default()).unwrap();
        assert_eq!(c.param_dependence, ParamDependence::of(&m));
        let paths = |p: &str| {
            c.param_dependence
                .entries(p)
                .iter()
                .map(EntryRef::path)
                .collect::<Vec<_>>()
        };
        assert_eq!(paths("q"), ["system.phi[0]"]);
        assert_eq!(paths("r"), ["measurement.psi[0]"]);
        for p in c.param_dependence.params() {
            for e in c.param_dependence.entries(p) {
                let Some(Value::Expr(text)) = e.value(&m) else {
                    panic!("{} is not an expression", e.path());
                };
                assert!(text.contains(p), "{p} in {text}");
            }
        }
    }
}
