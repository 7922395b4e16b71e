//! Helpers shared by the core's integration tests. (Each test binary compiles this
//! module and uses part of it.)
#![allow(dead_code)]

use kea_core::Error;

/// `e` has an error at `path` whose message contains `fragment` (panics listing the
/// errors otherwise).
pub fn assert_error_at(e: &Error, path: &str, fragment: &str) {
    let errors = e.field_errors();
    assert!(
        errors
            .iter()
            .any(|e| e.path == path && e.message.contains(fragment)),
        "expected an error at `{path}` containing \"{fragment}\", got {errors:#?}"
    );
}

/// A preset's model as JSON, to modify before parsing.
pub fn preset_value(name: &str) -> serde_json::Value {
    serde_json::from_str(kea_core::presets::get_json(name).expect("a preset"))
        .expect("presets parse")
}
