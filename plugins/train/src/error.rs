use cocog_engine::EngineError;
use thiserror::Error;

/// Everything training can fail with.
#[derive(Debug, Error)]
pub enum TrainError {
    #[error(transparent)]
    Engine(#[from] EngineError),
    #[error("invalid training input: {0}")]
    Invalid(String),
    /// A failed step lost the GPU parameters (Batch::new consumes them); the run cannot go on.
    #[error("a previous step failed and left the trainer without parameters")]
    Poisoned,
    /// The loss or the parameters stopped being numbers: going on would only write a model no
    /// reader accepts. The message says which, where, and what the run left on disk.
    #[error(
        "training diverged: {0}. A learning rate too large for the \
         scene's scale is the usual cause: compare the scene scale printed at the start with \
         the scene's size, and try a smaller --position-lr or --scene-scale"
    )]
    Diverged(String),
}
