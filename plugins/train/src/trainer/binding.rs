//! The up-front check that a cocog run's per-pixel GPU buffers each fit one buffer binding, so
//! a photo too large for the adapter is refused by name before any GPU work instead of failing
//! in a wgpu panic at the first step (or at the compositor's start, thousands of steps in).
//! A plain 3DGS run trains such photos in bands of rows instead (`bands.rs`); a CoC step
//! cannot, since F's instance norms see whole frames. The loss works in bands of rows and
//! needs no check.

use cocog_engine::nn::CompositorConfig;

use crate::TrainConfig;

/// The largest per-pixel buffer of a run on `w`×`h` photos, in bytes, and what it holds.
pub(super) struct Need {
    pub bytes: u64,
    pub what: String,
    /// Command-line ways out besides a smaller photo.
    pub remedies: &'static str,
}

/// The largest binding a run of `config` on `w`×`h` photos asks for: its rgba renders (one,
/// or one per CoC set), or, when the compositor F starts within the run, one render's feature
/// map of F (channels floats per pixel: 256 bytes at 64 channels, so lavapipe's 128 MiB covers
/// 524k pixels; F runs the renders in chunks of as many as a binding holds).
pub(super) fn largest_binding(w: u32, h: u32, config: &TrainConfig) -> Need {
    let pixels = u64::from(w) * u64::from(h);
    let sets = config.coc.as_ref().map_or(1, |c| c.net.copies + 1);
    let rgba = Need {
        bytes: 16 * pixels * u64::from(sets),
        what: format!("{sets} rgba render{}", if sets == 1 { "" } else { "s" }),
        remedies: "",
    };
    let Some(coc) = config.coc.as_ref() else {
        return rgba;
    };
    if !coc.composites_at(config.iterations) {
        return rgba;
    }
    let channels = coc.compositor_channels;
    let maps = Need {
        bytes: CompositorConfig::with_channels(channels).map_bytes(pixels, 1),
        what: format!(
            "a feature map of the compositor F, {channels} channels for one render, from \
             iteration {}",
            coc.composite_start.max(coc.blur_start)
        ),
        remedies: ", fewer --compositor-channels, or --composite-start past --iterations \
                   (uniform averaging of the renders throughout)",
    };
    if maps.bytes > rgba.bytes { maps } else { rgba }
}

/// `Err` naming the photo size, the buffer, the adapter's limit and the ways out when the
/// largest binding exceeds `limit`.
pub(super) fn check(
    w: u32,
    h: u32,
    config: &TrainConfig,
    limit: u64,
    adapter: &str,
) -> Result<(), String> {
    let need = largest_binding(w, h, config);
    if need.bytes <= limit {
        return Ok(());
    }
    let mib = |b: u64| b as f64 / f64::from(1 << 20);
    let scale = (need.bytes as f64 / limit as f64).sqrt().ceil();
    Err(format!(
        "{w}×{h} photos need a {:.0} MiB GPU buffer binding ({}), and {adapter} binds at most \
         {:.0} MiB: train on smaller images (--downscale {scale} or more){}",
        mib(need.bytes),
        need.what,
        mib(limit),
        need.remedies
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::CocTrainConfig;
    use cocog_engine::coc::CocVariant;

    const LAVAPIPE: u64 = 128 << 20;

    fn cocog(iterations: u32) -> TrainConfig {
        TrainConfig {
            iterations,
            coc: Some(CocTrainConfig::new(CocVariant::Lens)),
            ..TrainConfig::default()
        }
    }

    #[test]
    fn plain_3dgs_needs_one_rgba_render() {
        let c = TrainConfig::default();
        assert_eq!(largest_binding(400, 300, &c).bytes, 16 * 120_000);
        // 8.4 Mpixel fit lavapipe, one more row does not.
        assert!(check(4096, 2048, &c, LAVAPIPE, "lavapipe").is_ok());
        let e = check(4096, 2049, &c, LAVAPIPE, "lavapipe").unwrap_err();
        assert!(
            e.contains("4096×2049") && e.contains("--downscale 2"),
            "{e}"
        );
    }

    #[test]
    fn the_compositor_counts_only_when_it_starts_within_the_run() {
        // Lens defaults: M = 5, F from 6000 with 64 channels. At 1000×600 one render's maps
        // (154 MB) outgrow lavapipe's binding where the six renders (58 MB) do not.
        let before = cocog(5999);
        assert_eq!(largest_binding(1000, 600, &before).bytes, 16 * 600_000 * 6);
        assert!(check(1000, 600, &before, LAVAPIPE, "lavapipe").is_ok());
        let after = cocog(6000);
        let need = largest_binding(1000, 600, &after);
        assert_eq!(need.bytes, 4 * 600_000 * 64);
        let e = check(1000, 600, &after, LAVAPIPE, "lavapipe").unwrap_err();
        assert!(
            e.contains("146 MiB")
                && e.contains("compositor F")
                && e.contains("from iteration 6000"),
            "{e}"
        );
        assert!(
            e.contains("--downscale 2") && e.contains("--composite-start"),
            "{e}"
        );
        // The dev scenes at full size (400×300) fit: F takes its renders in chunks.
        assert!(check(400, 300, &after, LAVAPIPE, "lavapipe").is_ok());
        assert_eq!(largest_binding(400, 300, &after).bytes, 4 * 120_000 * 64);
        // Fewer channels shrink the maps below the renders.
        let mut narrow = cocog(7000);
        narrow.coc.as_mut().unwrap().compositor_channels = 2;
        assert_eq!(largest_binding(400, 300, &narrow).bytes, 16 * 120_000 * 6);
    }
}
