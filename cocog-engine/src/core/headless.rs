//! Keeps a headless run's stderr free of a window-system probe's false alarm.
//!
//! wgpu enables every surface extension the Vulkan driver offers (`VK_KHR_wayland_surface`
//! among them) whether or not a window is ever made, and its instance hook may only add
//! extensions, never remove them. Mesa's implicit device-select layer sees that extension and,
//! on every `vkEnumeratePhysicalDevices`, asks libwayland for the compositor so it can list the
//! GPU driving the display first. Without `XDG_RUNTIME_DIR` (ssh sessions, containers, CI)
//! libwayland then prints `error: XDG_RUNTIME_DIR is invalid or not set in the environment.`,
//! twice per adapter query, although nothing failed.
//!
//! In that case no Wayland compositor can be reached, so the layer has nothing to learn, and
//! cocog ranks adapters itself (`GpuContext::new`): the layer is turned off through its
//! documented switch, `NODEVICE_SELECT=1`. Tried and not chosen: a private 0700 runtime dir
//! also silences it, but leaves a folder to clean up (a killed run cannot) and tells every
//! library in the process that a desktop session exists where there is none.

use std::ffi::OsString;
use std::path::Path;

/// Whether the device-select layer's Wayland probe can only fail (and print an error) in an
/// environment read through `var`, and the user has not asked anything of that layer.
pub fn device_select_probe_is_futile(var: impl Fn(&str) -> Option<OsString>) -> bool {
    // libwayland's own test: a runtime dir, or a socket path, that is absolute.
    let absolute = |name: &str| var(name).is_some_and(|v| Path::new(&v).is_absolute());
    var("NODEVICE_SELECT").is_none()
        && var("MESA_VK_DEVICE_SELECT").is_none()
        && !absolute("XDG_RUNTIME_DIR")
        && !absolute("WAYLAND_DISPLAY")
}

/// Turns Mesa's device-select layer off when its probe is futile (see the module notes).
///
/// # Safety
/// Sets an environment variable, which races with any other thread reading the environment:
/// call it at the start of `main`, before any thread exists.
pub unsafe fn quiet_headless_vulkan() {
    if device_select_probe_is_futile(|name| std::env::var_os(name)) {
        // SAFETY: the caller guarantees no other thread runs yet.
        unsafe { std::env::set_var("NODEVICE_SELECT", "1") };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn futile(vars: &[(&str, &str)]) -> bool {
        device_select_probe_is_futile(|name| {
            vars.iter()
                .find(|(k, _)| *k == name)
                .map(|(_, v)| OsString::from(v))
        })
    }

    #[test]
    fn only_a_headless_environment_turns_the_layer_off() {
        assert!(futile(&[]));
        assert!(futile(&[("XDG_RUNTIME_DIR", "")]));
        assert!(futile(&[
            ("XDG_RUNTIME_DIR", "run/user"),
            ("DISPLAY", ":0")
        ]));
        assert!(futile(&[("WAYLAND_DISPLAY", "wayland-0")]));
        // A reachable compositor, or the user choosing a device through the layer.
        assert!(!futile(&[("XDG_RUNTIME_DIR", "/run/user/1000")]));
        assert!(!futile(&[("WAYLAND_DISPLAY", "/tmp/wayland-0")]));
        assert!(!futile(&[("MESA_VK_DEVICE_SELECT", "10de:2330")]));
        assert!(!futile(&[("NODEVICE_SELECT", "0")]));
    }
}
