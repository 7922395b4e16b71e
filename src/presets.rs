//! Preset models: JSON files in the repository's `presets/` folder, embedded at build
//! time so the CLI, the server and the wasm build share exactly the same models.

use crate::model::Model;
use serde::Serialize;

/// (name, JSON text) of every preset, in display order.
const PRESETS: &[(&str, &str)] = &[
    ("seed-example", include_str!("../presets/seed-example.json")),
    (
        "helicopter-range",
        include_str!("../presets/helicopter-range.json"),
    ),
    ("cv-tracker", include_str!("../presets/cv-tracker.json")),
    (
        "helicopter-hover",
        include_str!("../presets/helicopter-hover.json"),
    ),
    (
        "helicopter-angle",
        include_str!("../presets/helicopter-angle.json"),
    ),
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
        .map(|(name, _)| {
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
    PRESETS.iter().find(|(n, _)| *n == name).map(|(_, j)| *j)
}

/// The preset as a model.
pub fn get(name: &str) -> Option<Model> {
    get_json(name).map(|j| crate::model_from_json(j).expect("embedded presets parse (tested)"))
}

/// Names of all presets.
pub fn names() -> Vec<&'static str> {
    PRESETS.iter().map(|(n, _)| *n).collect()
}

#[cfg(test)]
mod tests {
    #[test]
    fn every_preset_parses_and_validates() {
        for name in super::names() {
            let m = super::get(name).unwrap();
            crate::check(&m, &Default::default())
                .unwrap_or_else(|e| panic!("preset {name} invalid: {e}"));
        }
    }
}
