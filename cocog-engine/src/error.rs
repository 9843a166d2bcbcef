use thiserror::Error;

/// Bytes as MiB, for the sizes errors report.
pub(crate) fn mib(bytes: u64) -> f64 {
    bytes as f64 / f64::from(1u32 << 20)
}

/// Everything the engine can fail with.
#[derive(Debug, Error)]
pub enum EngineError {
    #[error("no GPU adapter available: {0}")]
    NoAdapter(String),
    #[error("no adapter name contains {wanted:?} (COCOG_ADAPTER); available: {available}")]
    AdapterNotFound { wanted: String, available: String },
    #[error("adapter {adapter} lacks required capability: {what}")]
    MissingCapability { adapter: String, what: String },
    #[error("failed to create device: {0}")]
    Device(#[from] wgpu::RequestDeviceError),
    #[error("GPU readback failed: {0}")]
    Readback(String),
    #[error(
        "the images of a forward pass need {needed} tile intersections and a buffer binding \
         holds {most}: render smaller images (or bands of rows, `Renderer::render_frame`) or \
         fewer, smaller Gaussians"
    )]
    TooManyIntersections { needed: u32, most: u32 },
    #[error(
        "{gaussians} Gaussians at SH degree {sh_degree} need {needed_mib:.0} MiB in one buffer \
         and this adapter binds at most {limit_mib:.0} MiB: at most {most} Gaussians fit (a \
         lower SH degree or fewer Gaussians; a GPU binds more)"
    )]
    TooManyGaussians {
        gaussians: u64,
        sh_degree: u32,
        most: u64,
        needed_mib: f64,
        limit_mib: f64,
    },
    #[error(
        "a frame {width} pixels wide needs {needed_mib:.0} MiB for the loss's {rows} rows of \
         SSIM terms and this adapter binds at most {limit_mib:.0} MiB: train on narrower \
         images (--downscale) or on a GPU that binds more"
    )]
    FrameTooWide {
        width: u32,
        rows: u32,
        needed_mib: f64,
        limit_mib: f64,
    },
    #[error("invalid input: {0}")]
    Invalid(String),
}
