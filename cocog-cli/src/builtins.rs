//! The stages linked into the `cocog` binary.

use cocog_pipeline::Registry;

/// Stages that will exist but are not built yet, with what brings them: `cocog` names
/// them in its error instead of a bare "unknown stage".
pub const PLANNED: &[(&str, &str)] = &[
    (
        "eval-scene",
        "the GPU engine (issue #5): it renders the scene first",
    ),
    ("render", "the GPU engine (issue #5)"),
];

/// What brings a planned stage, if `name` is one.
pub fn planned(name: &str) -> Option<&'static str> {
    PLANNED.iter().find(|(n, _)| *n == name).map(|(_, by)| *by)
}

pub fn register(registry: &mut Registry) {
    registry.add_builtins(cocog_ingest::stages());
    registry.add_builtins(cocog_densify::stages());
    registry.add_builtins(cocog_train::stages());
    registry.add_builtins(cocog_prune::stages());
    registry.add_builtins(cocog_export::stages());
    registry.add_builtins(cocog_convert::stages());
    registry.add_builtins(cocog_eval::stages());
}
