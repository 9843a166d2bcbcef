//! The stages linked into the `cocog` binary.

use cocog_pipeline::Registry;

pub fn register(registry: &mut Registry) {
    registry.add_builtins(cocog_ingest::stages());
    registry.add_builtins(cocog_densify::stages());
    registry.add_builtins(cocog_train::stages());
    registry.add_builtins(cocog_prune::stages());
    registry.add_builtins(cocog_export::stages());
    registry.add_builtins(cocog_convert::stages());
    registry.add_builtins(cocog_eval::stages());
    registry.add_builtins(cocog_render::stages());
}
