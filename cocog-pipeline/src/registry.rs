//! Which stage answers to which name, and who provides it.
//!
//! Built-in stages win by default. A plugin stage with the same name replaces a built-in
//! only when asked (`--use NAME=PLUGIN`), so dropping a library on the plugin path can
//! never silently change what `cocog train` does.

use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::plugin::{LoadedPlugin, PluginError, discover};
use crate::stage::{Stage, StageInfo};

#[derive(Clone, Debug, PartialEq)]
pub enum Provider {
    BuiltIn,
    Plugin {
        path: PathBuf,
        name: String,
        version: String,
    },
}

impl fmt::Display for Provider {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::BuiltIn => f.write_str("built-in"),
            Self::Plugin {
                path,
                name,
                version,
            } => write!(f, "plugin {name} {version} ({})", path.display()),
        }
    }
}

pub struct StageEntry {
    pub stage: Arc<dyn Stage>,
    pub info: StageInfo,
    pub provider: Provider,
}

#[derive(Debug, thiserror::Error)]
pub enum RegistryError {
    #[error("no stage named '{name}' (available: {available}); run `cocog plugins` to list stages")]
    Unknown { name: String, available: String },
    #[error("--use {stage}={spec}: no loaded plugin named '{spec}' provides stage '{stage}'")]
    NotProvided { stage: String, spec: String },
    #[error("--use {0}: expected STAGE=PLUGIN (a plugin name or a library path)")]
    BadUse(String),
    #[error(transparent)]
    Plugin(#[from] PluginError),
}

#[derive(Default)]
pub struct Registry {
    entries: Vec<StageEntry>,
    overrides: BTreeMap<String, usize>,
    /// Plugins on the plugin path that could not be loaded.
    pub load_errors: Vec<PluginError>,
    /// Libraries on the plugin path that are not plugins (never opened), with why.
    pub skipped: Vec<(PathBuf, String)>,
}

impl Registry {
    pub fn new() -> Self {
        Self::default()
    }

    pub fn add_builtin(&mut self, stage: Box<dyn Stage>) {
        let info = stage.info();
        self.entries.push(StageEntry {
            stage: Arc::from(stage),
            info,
            provider: Provider::BuiltIn,
        });
    }

    pub fn add_builtins(&mut self, stages: Vec<Box<dyn Stage>>) {
        for s in stages {
            self.add_builtin(s);
        }
    }

    pub fn add_plugin(&mut self, plugin: &Arc<LoadedPlugin>) {
        let provider = Provider::Plugin {
            path: plugin.path.clone(),
            name: plugin.name.clone(),
            version: plugin.version.clone(),
        };
        for handle in plugin.stage_handles() {
            let info = handle.info();
            self.entries.push(StageEntry {
                stage: Arc::new(handle),
                info,
                provider: provider.clone(),
            });
        }
    }

    /// Loads every plugin under `dirs`; failures are kept in `load_errors`.
    pub fn load_plugins(&mut self, dirs: &[PathBuf]) {
        let found = discover(dirs);
        for p in &found.plugins {
            self.add_plugin(p);
        }
        self.load_errors.extend(found.errors);
        self.skipped.extend(found.skipped);
    }

    /// Applies `--use STAGE=PLUGIN`, where PLUGIN is a loaded plugin's name or a path to
    /// a library (loaded now; any failure is fatal because the user asked for it).
    pub fn use_plugin(&mut self, spec: &str) -> Result<(), RegistryError> {
        let (stage, who) = spec
            .split_once('=')
            .filter(|(s, w)| !s.is_empty() && !w.is_empty())
            .ok_or_else(|| RegistryError::BadUse(spec.to_owned()))?;
        let as_path = Path::new(who);
        let by_path = as_path.exists() || who.contains(std::path::MAIN_SEPARATOR);
        let found = if by_path {
            let plugin = LoadedPlugin::load(as_path)?;
            let before = self.entries.len();
            self.add_plugin(&plugin);
            (before..self.entries.len()).find(|&i| self.entries[i].info.name == stage)
        } else {
            self.entries.iter().position(|e| {
                e.info.name == stage
                    && matches!(&e.provider, Provider::Plugin { name, .. } if name == who)
            })
        };
        let index = found.ok_or_else(|| RegistryError::NotProvided {
            stage: stage.to_owned(),
            spec: who.to_owned(),
        })?;
        self.overrides.insert(stage.to_owned(), index);
        Ok(())
    }

    /// The entry that runs for `name`: an override, else the built-in, else a plugin.
    pub fn resolve(&self, name: &str) -> Result<&StageEntry, RegistryError> {
        self.active_index(name)
            .map(|i| &self.entries[i])
            .ok_or_else(|| RegistryError::Unknown {
                name: name.to_owned(),
                available: match self.names() {
                    n if n.is_empty() => "none".to_owned(),
                    n => n.join(", "),
                },
            })
    }

    fn active_index(&self, name: &str) -> Option<usize> {
        if let Some(&i) = self.overrides.get(name) {
            return Some(i);
        }
        let matching = || {
            self.entries
                .iter()
                .enumerate()
                .filter(|(_, e)| e.info.name == name)
        };
        matching()
            .find(|(_, e)| e.provider == Provider::BuiltIn)
            .or_else(|| matching().next())
            .map(|(i, _)| i)
    }

    /// Every stage entry with whether it is the one that runs for its name.
    pub fn entries(&self) -> impl Iterator<Item = (&StageEntry, bool)> {
        self.entries
            .iter()
            .enumerate()
            .map(|(i, e)| (e, self.active_index(&e.info.name) == Some(i)))
    }

    /// Distinct stage names, sorted.
    pub fn names(&self) -> Vec<String> {
        let mut names: Vec<String> = self.entries.iter().map(|e| e.info.name.clone()).collect();
        names.sort();
        names.dedup();
        names
    }
}
