//! `cocog`: parses the command line, assembles the stage registry and runs stages.
//! No algorithms live here.

mod builtins;
mod cli;
mod commands;
mod demo;
mod lens;
mod lens_units;
mod plugins;
mod progress;
mod sweep;

use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use clap::Parser;
use cocog_pipeline::LogLevel;
use cocog_pipeline::registry::RegistryError;
use cocog_pipeline::runner::RunError;

use crate::cli::Cli;
use crate::progress::CliContext;

/// Exit codes: documented in `cocog --help`.
pub mod exit {
    pub const FAILURE: u8 = 1;
    pub const USAGE: u8 = 2;
    pub const UNAVAILABLE: u8 = 3;
    pub const CANCELLED: u8 = 130;
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    if let Some(name) = &cli.global.adapter {
        // The engine reads COCOG_ADAPTER where it opens the device, in the binary's stages
        // and in plugins alike, so the flag travels as that variable.
        // SAFETY: nothing else runs yet (no threads: the Ctrl-C handler starts below).
        unsafe { std::env::set_var("COCOG_ADAPTER", name) };
    }
    // Without it, a headless machine's stderr says `error: XDG_RUNTIME_DIR is invalid` on
    // every GPU command although nothing failed (why: cocog_engine's headless.rs).
    // SAFETY: as above, no other thread exists yet.
    unsafe { cocog_engine::quiet_headless_vulkan() };
    let level = if cli.global.quiet {
        LogLevel::Warn
    } else if cli.global.verbose {
        LogLevel::Debug
    } else {
        LogLevel::Info
    };
    // One line instead of a backtrace; the stage runner turns the panic into an error
    // that names the stage. RUST_BACKTRACE still gets the full trace.
    if std::env::var_os("RUST_BACKTRACE").is_none() {
        std::panic::set_hook(Box::new(|info| eprintln!("internal error: {info}")));
    }
    let cancel = Arc::new(AtomicBool::new(false));
    let flag = Arc::clone(&cancel);
    // First Ctrl-C asks the stage to stop cleanly (its staging output is removed); a
    // second one exits at once.
    let _ = ctrlc::set_handler(move || {
        if flag.swap(true, Ordering::SeqCst) {
            eprintln!(
                "\naborted: an output being written stays as a hidden .NAME.cocog-tmp-* file or \
                 folder beside it (the next run onto it removes it); a training's last \
                 checkpoint is kept"
            );
            std::process::exit(i32::from(exit::CANCELLED));
        }
        eprintln!("\ncancelling: finishing the current step (Ctrl-C again to abort)");
    });
    let ctx = CliContext::new(level, cancel, cli.global.progress_every);
    match commands::dispatch(&cli, &ctx) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", one_line(&e));
            ExitCode::from(exit_code(&e))
        }
    }
}

/// The whole cause chain on one line, without repeating a cause already in the message.
fn one_line(e: &anyhow::Error) -> String {
    let mut s = String::new();
    for cause in e.chain() {
        let t = cause.to_string();
        if s.contains(&t) {
            continue;
        }
        if !s.is_empty() {
            s.push_str(": ");
        }
        s.push_str(&t);
    }
    s
}

fn exit_code(e: &anyhow::Error) -> u8 {
    for cause in e.chain() {
        if let Some(r) = cause.downcast_ref::<RunError>() {
            if r.is_cancelled() {
                return exit::CANCELLED;
            }
            if let RunError::Registry(RegistryError::Unknown { .. }) = r {
                return exit::UNAVAILABLE;
            }
            if let RunError::Pipeline { .. } = r {
                return exit::USAGE;
            }
        }
        if let Some(RegistryError::Unknown { .. }) = cause.downcast_ref::<RegistryError>() {
            return exit::UNAVAILABLE;
        }
        if cause.downcast_ref::<commands::UsageError>().is_some() {
            return exit::USAGE;
        }
        // A value the stage refuses (`--downscale 0`, an unknown `--background`) is as much a
        // usage error as one clap refuses, whichever side of the stage boundary checks it.
        if let Some(cocog_pipeline::StageError::Options(_)) =
            cause.downcast_ref::<cocog_pipeline::StageError>()
        {
            return exit::USAGE;
        }
    }
    exit::FAILURE
}
