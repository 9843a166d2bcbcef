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
}
