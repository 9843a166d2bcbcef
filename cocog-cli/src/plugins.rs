//! `cocog plugins`: every stage, who provides it, and libraries that failed to load.

use anyhow::{Result, bail};
use cocog_pipeline::plugin::ABI_VERSION;
use cocog_pipeline::{Provider, Registry};
use serde_json::{Value, json};

pub fn list(registry: &Registry, as_json: bool, verbose: bool) -> Result<()> {
    let mut rows = Vec::new();
    for (entry, active) in registry.entries() {
        let (provider, file, version) = match &entry.provider {
            Provider::BuiltIn => ("built-in".to_owned(), None, crate_version()),
            Provider::Plugin {
                path,
                name,
                version,
            } => (
                name.clone(),
                Some(path.display().to_string()),
                version.clone(),
            ),
        };
        rows.push(json!({
            "stage": entry.info.name,
            "kind": entry.info.kind.as_str(),
            "needs_gaussians": entry.info.needs_gaussians,
            "provider": provider,
            "version": version,
            "file": file,
            "abi": ABI_VERSION,
            "active": active,
            "description": entry.info.description,
            "options": entry.info.options,
        }));
    }
    let errors: Vec<String> = registry.load_errors.iter().map(|e| e.to_string()).collect();
    let skipped: Vec<Value> = registry
        .skipped
        .iter()
        .map(|(path, why)| json!({ "file": path.display().to_string(), "why": why }))
        .collect();
    if as_json {
        let v = json!({
            "abi_version": ABI_VERSION,
            "stages": rows,
            "errors": errors,
            "skipped": skipped,
        });
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        print_table(&rows);
        if verbose {
            for (path, why) in &registry.skipped {
                eprintln!("skipped {}: {why}", path.display());
            }
        } else if !skipped.is_empty() {
            let n = skipped.len();
            let what = if n == 1 { "library" } else { "libraries" };
            eprintln!(
                "skipped {n} {what} without the cocog plugin entry, unopened (-v lists them)"
            );
        }
        for e in &errors {
            eprintln!("error: {e}");
        }
    }
    if !errors.is_empty() {
        bail!("{} plugin file(s) could not be loaded", errors.len());
    }
    Ok(())
}

fn crate_version() -> String {
    cocog_pipeline::VERSION.to_owned()
}

fn print_table(rows: &[Value]) {
    let s = |r: &Value, k: &str| r.get(k).and_then(Value::as_str).unwrap_or("").to_owned();
    println!(
        "{:<16} {:<10} {:<20} {:<8} {:<4} FILE",
        "STAGE", "KIND", "PROVIDER", "VERSION", "ABI"
    );
    for r in rows {
        let active = r.get("active").and_then(Value::as_bool).unwrap_or(false);
        let mut provider = s(r, "provider");
        if !active {
            provider.push_str(" (inactive)");
        }
        println!(
            "{:<16} {:<10} {:<20} {:<8} {:<4} {}",
            s(r, "stage"),
            s(r, "kind"),
            provider,
            s(r, "version"),
            ABI_VERSION,
            r.get("file")
                .and_then(Value::as_str)
                .unwrap_or("(linked in)")
        );
    }
    if rows
        .iter()
        .any(|r| r.get("active") == Some(&Value::Bool(false)))
    {
        println!(
            "\nInactive stages are shadowed by a built-in; select one with --use STAGE=PLUGIN."
        );
    }
}
