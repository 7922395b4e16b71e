//! The parts every kind's request shares, read once for all of them: the request as
//! an object, its members against the kind's list, `model` and `set` (parameter
//! overrides), and the model's errors placed under `model.` (the one place that
//! prefix is written).

use crate::error::{Error, FieldError, got, json_kind, member_path, omitted_count};
use crate::model::CompiledModel;
use crate::model::Model;
use crate::model::Overrides;
use serde_json::{Map, Value};

/// The request as a JSON object, or an error at the root.
pub fn object(request: Value) -> Result<Map<String, Value>, Error> {
    match request {
        Value::Object(m) => Ok(m),
        other => Err(Error::invalid(
            "",
            format!("expected a JSON object, got {}", json_kind(&other)),
        )),
    }
}

/// Errors for members of `obj` outside `allowed`.
pub fn unknown_members(obj: &Map<String, Value>, allowed: &[&str]) -> Vec<FieldError> {
    obj.keys()
        .filter(|k| !allowed.contains(&k.as_str()))
        .map(|k| {
            FieldError::new(
                k.clone(),
                format!("unknown member; expected one of: {}", allowed.join(", ")),
            )
        })
        .collect()
}

/// The `model` and `set` members of a request; problems are added to `errors` with
/// paths into the request (`model.system.a[0][0]`, `set.q`).
pub fn model_and_set(
    obj: &Map<String, Value>,
    errors: &mut Vec<FieldError>,
) -> (Option<Model>, Overrides) {
    let model = match obj.get("model") {
        None => {
            errors.push(FieldError::new(
                "model",
                "missing: give `model` (a model object) or `model_id` (a stored model)",
            ));
            None
        }
        Some(v) => match crate::model::model_from_value(v.clone()) {
            Ok(m) => Some(m),
            Err(e) => {
                errors.extend(e.with_prefix("model").field_errors());
                None
            }
        },
    };
    let set = match overrides(obj.get("set")) {
        Ok(s) => s,
        Err(e) => {
            errors.extend(e);
            Overrides::new()
        }
    };
    (model, set)
}

/// Parse `set` (parameter overrides): an object of finite numbers.
pub fn overrides(set: Option<&Value>) -> Result<Overrides, Vec<FieldError>> {
    let Some(set) = set else {
        return Ok(Overrides::new());
    };
    let Value::Object(m) = set else {
        return Err(vec![FieldError::new(
            "set",
            format!(
                "expected an object of parameter values (e.g. {{\"q\": 0.5}}), got {}",
                json_kind(set)
            ),
        )]);
    };
    let mut out = Overrides::new();
    let mut errors = Vec::new();
    for (name, v) in m {
        match v.as_f64() {
            Some(x) if x.is_finite() => {
                out.insert(name.clone(), x);
            }
            _ => errors.push(FieldError::new(
                member_path("set", name),
                format!("expected a number, got {}", json_kind(v)),
            )),
        }
    }
    if errors.is_empty() {
        Ok(out)
    } else {
        Err(errors)
    }
}

/// Validate and compile `model` with `set`. Where the model is valid without `set`
/// (and no error is about `set` itself: an unknown name), its errors are the values'
/// doing (`set: {q: -3}` makes `phi[0]` negative): one more entry, at `set`, names
/// them, so that a request naming only `model_id` and `set` learns what it sent
/// wrong. Paths are the model's own (see [`locate`]).
pub fn compile(model: &Model, set: &Overrides) -> Result<CompiledModel, Error> {
    match crate::model::compile(model, set) {
        Err(Error::Invalid(mut errors))
            if !set.is_empty()
                && !errors.iter().any(|e| e.path.starts_with("set"))
                && crate::model::compile(model, &Overrides::new()).is_ok() =>
        {
            let values: Vec<String> = set
                .iter()
                .map(|(k, v)| format!("{k} = {}", crate::text::num(*v)))
                .collect();
            errors.push(FieldError::new(
                "set",
                format!(
                    "the model is valid without `set`; with {} it is not (the other errors say where)",
                    values.join(", ")
                ),
            ));
            Err(Error::Invalid(errors))
        }
        r => r,
    }
}

/// Place an error of the model (its compilation, or a run of it) in the request:
/// paths about the overrides (`set.…`) stay, and so does the entry that counts the
/// errors left out (it is about the whole list, at the top level); the rest go under
/// `model`.
pub fn locate(err: Error) -> Error {
    let under_set = |p: &str| p == "set" || p.starts_with("set.") || p.starts_with("set[");
    match err {
        Error::Invalid(v) => Error::Invalid(
            v.into_iter()
                .map(|e| {
                    if under_set(&e.path) || omitted_count(&e).is_some() {
                        e
                    } else {
                        Error::Invalid(vec![e])
                            .with_prefix("model")
                            .field_errors()
                            .remove(0)
                    }
                })
                .collect(),
        ),
        e @ Error::Numerical { .. } => e.with_prefix("model"),
        e => e,
    }
}

/// A whole number at `obj[name]`, if there is one; a value that is not one is an
/// error (`expected {what}, got …`).
pub fn whole(
    obj: &Map<String, Value>,
    name: &str,
    what: &str,
    errors: &mut Vec<FieldError>,
) -> Option<u64> {
    let v = obj.get(name)?;
    let n = crate::json::whole_u64(v);
    if n.is_none() {
        errors.push(FieldError::new(
            name,
            format!("expected {what}, got {}", got(v)),
        ));
    }
    n
}

/// A yes/no at `obj[name]`, if given; anything but `true` or `false` is an error.
pub fn flag(obj: &Map<String, Value>, name: &str, errors: &mut Vec<FieldError>) -> Option<bool> {
    let v = obj.get(name)?;
    let b = v.as_bool();
    if b.is_none() {
        errors.push(FieldError::new(
            name,
            format!("expected true or false, got {}", got(v)),
        ));
    }
    b
}

/// Which of `choices` (name, meaning) the text at `obj[name]` is, if given; anything
/// else is an error listing them.
pub fn choice(
    obj: &Map<String, Value>,
    name: &str,
    choices: &[(&str, &str)],
    errors: &mut Vec<FieldError>,
) -> Option<usize> {
    let v = obj.get(name)?;
    let found = v
        .as_str()
        .and_then(|s| choices.iter().position(|(c, _)| *c == s));
    if found.is_none() {
        let list: Vec<String> = choices
            .iter()
            .map(|(c, what)| format!("\"{c}\" ({what})"))
            .collect();
        errors.push(FieldError::new(
            name,
            format!("expected {}, got {}", list.join(" or "), got(v)),
        ));
    }
    found
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn locate_keeps_set_paths_and_prefixes_model_paths() {
        let e = Error::Invalid(vec![
            FieldError::new("set.q", "unknown"),
            FieldError::new("system.a[0][1]", "bad"),
            FieldError::new("", "root"),
            FieldError::new("", "… and 7 more errors (only the first 100 are listed)"),
        ]);
        let paths: Vec<String> = locate(e)
            .field_errors()
            .into_iter()
            .map(|e| e.path)
            .collect();
        assert_eq!(paths, vec!["set.q", "model.system.a[0][1]", "model", ""]);
    }

    #[test]
    fn overrides_are_numbers() {
        let ok = overrides(Some(&serde_json::json!({"q": 2, "r": 0.5}))).unwrap();
        assert_eq!(ok.get("q"), Some(&2.0));
        let err = overrides(Some(&serde_json::json!({"q": "x"}))).unwrap_err();
        assert_eq!(err[0].path, "set.q");
        let err = overrides(Some(&serde_json::json!([1]))).unwrap_err();
        assert_eq!(err[0].path, "set");
    }
}
