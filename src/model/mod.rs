//! The model: its JSON format ([`format`]: what a user submits), its compilation into
//! a [`CompiledModel`] or a list of errors at their field paths ([`compile`]), and the
//! measurement schedule ([`schedule`]).

pub mod compile;
pub mod format;
pub mod limits;
pub mod params;
pub mod schedule;

pub use compile::{CompiledModel, Form, compile, compile_discrete};

/// Validate a model without running it, in its form (a discrete model, with
/// `system.transition`, as the identification reads it); every problem found is
/// returned.
pub fn check(model: &Model, set: &Overrides) -> Result<(), Error> {
    match model.system.transition {
        Some(_) => compile_discrete(model, set),
        None => compile(model, set),
    }
    .map(|_| ())
}

/// Parameter overrides (`--set name=value`, a request's `set`): each must name one
/// of the model's params.
pub type Overrides = std::collections::BTreeMap<String, f64>;
pub use format::*;

use crate::error::{self, Error, FieldError};
use crate::json::from_value_at;
use crate::json::parse_json;

/// Parse a model from a JSON value, with serde errors located at their field path.
pub fn model_from_value(value: serde_json::Value) -> Result<Model, Error> {
    // Not an object, or without the required parts: say so for all of them at once
    // (serde would read an array as the fields in order, and name one missing field).
    let Some(object) = value.as_object() else {
        return Err(Error::invalid(
            "",
            format!(
                "a model is a JSON object ({{\"kea_model\": 1, \"time\": …, \"system\": …, \"measurement\": …}}), got {}",
                error::json_kind(&value)
            ),
        ));
    };
    let missing: Vec<FieldError> = ["time", "system", "measurement"]
        .into_iter()
        .filter(|k| !object.contains_key(*k))
        .map(|k| {
            FieldError::new(
                k,
                "missing: a model needs time, system and measurement (docs/model-format.md)",
            )
        })
        .collect();
    if !missing.is_empty() {
        // A misspelt section ("sytem") is the likely cause of a missing one: name it,
        // as serde would have had it reached it.
        let unknown = object
            .keys()
            .filter(|k| !MODEL_MEMBERS.contains(&k.as_str()))
            .map(|k| FieldError::new(k, unknown_model_member(k)));
        return Err(Error::Invalid(unknown.chain(missing).collect()));
    }
    from_value_at(value, &[])
}

/// The members of a model (`Model`'s fields; a test compares them with serde's list).
const MODEL_MEMBERS: [&str; 9] = [
    "kea_model",
    "name",
    "description",
    "params",
    "time",
    "system",
    "measurement",
    "criteria",
    "options",
];

/// The error at a top-level member a model does not have.
fn unknown_model_member(name: &str) -> String {
    let expected = format!("expected one of: {}", MODEL_MEMBERS.join(", "));
    if name == "model" {
        format!(
            "unknown member; a model's members are at its top level ({expected}), not inside \"model\" (`{{\"model\": …}}` is the shape of a request that carries a model, not of a model)"
        )
    } else {
        format!("unknown member; {expected}")
    }
}

/// Parse a model from JSON text, with serde errors located at their field path.
pub fn model_from_json(text: &str) -> Result<Model, Error> {
    let value = parse_json(text.as_bytes())
        .map_err(|e| Error::invalid("", format!("not valid JSON: {e}")))?;
    model_from_value(value)
}
