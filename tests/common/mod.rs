//! Helpers shared by the core's integration tests.

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
