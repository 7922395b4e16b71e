//! Preset models: JSON files in the repository's `presets/` folder, embedded at build
//! time so the CLI, the server and the wasm build share exactly the same models.

use crate::model::Model;
use serde::Serialize;

/// A preset: its name, its model's JSON text, and its synthesis example's (a request
/// without `model`: `presets/synthesis/NAME.json`), both from the repository's files.
macro_rules! preset {
    ($name:literal) => {
        (
            $name,
            include_str!(concat!("../presets/", $name, ".json")),
            include_str!(concat!("../presets/synthesis/", $name, ".json")),
        )
    };
}

/// (name, model JSON, synthesis example JSON) of every preset, in display order.
const PRESETS: &[(&str, &str, &str)] = &[
    preset!("seed-example"),
    preset!("helicopter-range"),
    preset!("cv-tracker"),
    preset!("helicopter-hover"),
    preset!("helicopter-angle"),
];

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PresetInfo {
    pub name: String,
    pub title: String,
    pub description: String,
    pub states: usize,
    pub measurements: usize,
}

/// Name, title and description of every preset.
pub fn list() -> Vec<PresetInfo> {
    PRESETS
        .iter()
        .map(|(name, ..)| {
            let m = get(name).expect("embedded presets parse (tested)");
            PresetInfo {
                name: name.to_string(),
                title: m.name.clone().unwrap_or_else(|| name.to_string()),
                description: m.description.clone().unwrap_or_default(),
                states: m.system.states.len(),
                measurements: m.measurement.names.len(),
            }
        })
        .collect()
}

/// The preset's JSON text exactly as shipped.
pub fn get_json(name: &str) -> Option<&'static str> {
    PRESETS
        .iter()
        .find(|(n, ..)| *n == name)
        .map(|(_, j, _)| *j)
}

/// The preset's synthesis example exactly as shipped: a request's `target` and `mode`
/// (no `model`) that asks a question this preset answers — which sensor accuracy
/// reaches a filtering effect — with a threshold it can reach (docs/synthesis.md).
pub fn synthesis_json(name: &str) -> Option<&'static str> {
    PRESETS.iter().find(|(n, ..)| *n == name).map(|(.., s)| *s)
}

/// The preset as a model.
pub fn get(name: &str) -> Option<Model> {
    get_json(name)
        .map(|j| crate::model::model_from_json(j).expect("embedded presets parse (tested)"))
}

/// Names of all presets.
pub fn names() -> Vec<&'static str> {
    PRESETS.iter().map(|(n, ..)| *n).collect()
}

#[cfg(test)]
mod tests {
    #[test]
    fn every_preset_parses_and_validates() {
        for name in super::names() {
            let m = super::get(name).unwrap();
            crate::model::check(&m, &Default::default())
                .unwrap_or_else(|e| panic!("preset {name} invalid: {e}"));
        }
    }

    /// Each preset's synthesis example reaches its target: a bisection finds its
    /// answer, a grid has a cheapest cell meeting it, and neither is the whole range
    /// (an example whose every point meets the target shows nothing).
    #[test]
    fn every_synthesis_example_finds_an_answer_inside_its_range() {
        use crate::synthesis::{self, Details, Status};
        for name in super::names() {
            let mut request: serde_json::Value =
                serde_json::from_str(super::synthesis_json(name).unwrap()).unwrap();
            assert!(
                request.get("model").is_none(),
                "{name}: the example has no model"
            );
            request["model"] = serde_json::from_str(super::get_json(name).unwrap()).unwrap();
            let request = synthesis::request_from_value(request)
                .unwrap_or_else(|e| panic!("{name}: example invalid: {e}"));
            let r = synthesis::synthesize(
                &request,
                &crate::exec::Sequential,
                &mut crate::progress::NoProgress,
            )
            .unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(r.status, Status::Found, "{name}: {}", r.message);
            let v = r.verification.as_ref().unwrap();
            assert!(v.passed, "{name}: {}", r.message);
            if let Details::Grid(g) = &r.details {
                let meets = g.cells.iter().filter(|c| c.point.meets).count();
                assert!(
                    0 < meets && meets < g.cells.len(),
                    "{name}: {meets} cells meet"
                );
            }
        }
    }
}
