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

/// Loads every library under `dirs` (files may also be named directly). Libraries that
/// fail to load are returned as errors beside the good ones, so one broken file never
/// hides the others. A missing directory is an error too: it is usually a typo.
pub fn discover(dirs: &[PathBuf]) -> (Vec<Arc<LoadedPlugin>>, Vec<PluginError>) {
    let mut seen = HashSet::new();
    let mut plugins = Vec::new();
    let mut errors = Vec::new();
    for dir in dirs {
        if !dir.exists() {
            errors.push(PluginError::Load {
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
            let key = path.canonicalize().unwrap_or_else(|_| path.to_path_buf());
            if !seen.insert(key) {
                continue;
            }
            match LoadedPlugin::load(path) {
                Ok(p) => plugins.push(p),
                Err(e) => errors.push(e),
            }
        }
    }
    (plugins, errors)
}
