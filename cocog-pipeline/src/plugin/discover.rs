//! Finding plugin libraries on disk.

use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use walkdir::WalkDir;

use super::host::{LoadedPlugin, PluginError};

/// The environment variable holding extra plugin directories (OS path-list syntax).
pub const PLUGIN_PATH_ENV: &str = "COCOG_PLUGIN_PATH";

/// `--plugin-path` entries first, then `COCOG_PLUGIN_PATH`.
pub fn plugin_dirs(cli: &[PathBuf]) -> Vec<PathBuf> {
    let mut dirs = cli.to_vec();
    if let Some(v) = std::env::var_os(PLUGIN_PATH_ENV) {
        dirs.extend(std::env::split_paths(&v).filter(|p| !p.as_os_str().is_empty()));
    }
    dirs
}

/// Is this file name a shared library for this OS?
pub fn is_library(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e == std::env::consts::DLL_EXTENSION)
}

/// What a walk of the plugin path found.
#[derive(Default)]
pub struct Discovery {
    pub plugins: Vec<Arc<LoadedPlugin>>,
    /// Plugins (files exporting the entry symbol) that failed to load, and missing dirs.
    pub errors: Vec<PluginError>,
    /// Libraries that are not plugins, with why; never opened.
    pub skipped: Vec<(PathBuf, String)>,
}

/// Loads every plugin under `dirs` (files may also be named directly). Only libraries whose
/// export table holds the entry symbol are opened, so a directory of system libraries runs
/// no stranger's constructors. A plugin that fails to load is returned as an error beside
/// the good ones, so one broken file never hides the others. A missing directory is an
/// error too: it is usually a typo.
pub fn discover(dirs: &[PathBuf]) -> Discovery {
    let mut seen = HashSet::new();
    let mut found = Discovery::default();
    for dir in dirs {
        if !dir.exists() {
            found.errors.push(PluginError::Load {
                path: dir.clone(),
                message: "no such file or directory on the plugin path".to_owned(),
            });
            continue;
        }
        let walker = WalkDir::new(dir)
            .follow_links(true)
            .max_depth(4)
            .sort_by_file_name();
        for entry in walker.into_iter().filter_map(Result::ok) {
            let path = entry.path();
            if !entry.file_type().is_file() || !is_library(path) {
                continue;
            }
            // Before the identity check: cargo hard-links the two copies, and the walk meets
            // `deps/` first, so the upper one would be the duplicate dropped unseen.
            if is_cargo_deps_copy(path, dir) {
                let why = "cargo's copy of the library one folder up".to_owned();
                found.skipped.push((path.to_path_buf(), why));
                continue;
            }
            if !seen.insert(identity(path)) {
                continue;
            }
            match LoadedPlugin::load(path) {
                Ok(p) => found.plugins.push(p),
                Err(PluginError::MissingSymbol { .. }) => found.skipped.push((
                    path.to_path_buf(),
                    "does not export the plugin entry".into(),
                )),
                Err(PluginError::NotALibrary { message, .. }) => {
                    found.skipped.push((path.to_path_buf(), message));
                }
                Err(e) => found.errors.push(e),
            }
        }
    }
    found
}

/// The same file reached by two names (links, hard links) counts once.
fn identity(path: &Path) -> (u64, u64, PathBuf) {
    #[cfg(unix)]
    if let Ok(m) = std::fs::metadata(path) {
        use std::os::unix::fs::MetadataExt;
        return (m.dev(), m.ino(), PathBuf::new());
    }
    (
        0,
        0,
        path.canonicalize().unwrap_or_else(|_| path.to_path_buf()),
    )
}

/// Cargo builds a cdylib in `target/*/deps/` and copies it up one level; with the plugin
/// path at `target/debug` the copy in `deps/` is the same plugin. Only when the walk from
/// `root` reaches the upper copy too: `--plugin-path target/debug/deps` still finds it.
fn is_cargo_deps_copy(path: &Path, root: &Path) -> bool {
    let (Some(dir), Some(name)) = (path.parent(), path.file_name()) else {
        return false;
    };
    dir != root
        && dir.file_name().is_some_and(|d| d == "deps")
        && dir
            .parent()
            .is_some_and(|up| up.starts_with(root) && up.join(name).is_file())
}
