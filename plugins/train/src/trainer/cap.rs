//! How many Gaussians a run can hold: its widest per-Gaussian GPU buffer must fit one buffer
//! binding. A run is refused up front past it, and density control stops growing the set at
//! it (with a warning) instead of failing in a wgpu panic thousands of steps in.

use cocog_engine::EngineError;

use crate::TrainConfig;

/// Bytes per base Gaussian of the widest buffer a run of `config` binds: the SH rows at its
/// largest degree or the 48-byte projected records, times the M + 1 sets of a cocog step
/// (their projections and SH gradients keep a row per set), and at least h_θ's 64-float
/// hidden rows.
pub(super) fn bytes_per_gaussian(config: &TrainConfig) -> u64 {
    let per_set = cocog_engine::bytes_per_gaussian(config.max_sh_degree);
    match &config.coc {
        None => per_set,
        Some(c) => (per_set * u64::from(c.net.copies + 1)).max(256),
    }
}

/// The most Gaussians a run of `config` holds within bindings of `limit` bytes.
pub(super) fn most_gaussians(config: &TrainConfig, limit: u64) -> u32 {
    (limit / bytes_per_gaussian(config)).min(u64::from(u32::MAX)) as u32
}

/// `Err` when `n` starting Gaussians are past `most_gaussians`.
pub(super) fn check(n: u32, config: &TrainConfig, limit: u64) -> Result<(), EngineError> {
    let per = bytes_per_gaussian(config);
    cocog_engine::check_fits_at(limit, u64::from(n), per, config.max_sh_degree)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::CocTrainConfig;
    use cocog_engine::coc::CocVariant;

    #[test]
    fn a_cocog_step_binds_a_row_per_set() {
        let mut c = TrainConfig::default();
        assert_eq!(bytes_per_gaussian(&c), 192);
        c.coc = Some(CocTrainConfig::new(CocVariant::Paper));
        // SH 3 gradients for M + 1 = 6 sets.
        assert_eq!(bytes_per_gaussian(&c), 1152);
        let lavapipe = 128 << 20;
        assert_eq!(most_gaussians(&c, lavapipe), 116_508);
        assert!(check(116_508, &c, lavapipe).is_ok());
        let e = check(200_000, &c, lavapipe).unwrap_err().to_string();
        assert!(e.contains("at most 116508 Gaussians fit"), "{e}");
        c.max_sh_degree = 0;
        assert_eq!(bytes_per_gaussian(&c), 288);
    }
}
