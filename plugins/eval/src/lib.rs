//! The `eval` stage: scores a folder of predicted images against a folder of ground truths,
//! matched by file stem, and writes `metrics.json` (per-image and mean PSNR, SSIM in two
//! conventions, LPIPS when its weights are installed). The summary it returns is the same JSON.
//!
//! The CLI's `cocog eval --pred DIR --gt DIR` maps to: input = DIR of predictions, option
//! `gt` = ground-truth DIR. [`format_table`] renders the result for a terminal.

use cocog_metrics::Observer;
use cocog_pipeline::{
    Context, OptionKind, OptionSpec, OutputKind, Stage, StageError, StageInfo, StageKind,
    StageRequest,
};
use serde_json::Value;

pub use cocog_metrics::{
    EvalOptions, LpipsMode, MetricsError, evaluate_dirs, format_table, write_json_atomic,
};

/// The stages this crate provides.
pub fn stages() -> Vec<Box<dyn Stage>> {
    vec![Box::new(EvalStage)]
}

/// Scores `req.input` (predictions) against option `gt`.
pub struct EvalStage;

impl Stage for EvalStage {
    fn info(&self) -> StageInfo {
        StageInfo {
            name: "eval".into(),
            kind: StageKind::Eval,
            output: OutputKind::File,
            needs_gaussians: false,
            description: "Score a folder of predicted images against ground truth (matched by \
                          file stem): PSNR, SSIM (Deblur-NeRF and Gaussian-11), LPIPS-Alex; \
                          writes metrics.json"
                .into(),
            options: [OptionSpec::required(
                "gt",
                OptionKind::Path,
                "folder of ground-truth images (png/jpg), matched to predictions by file stem \
                 (a render named with its folder, test_r_0, matches r_0 in a folder named test)",
            )]
            .into_iter()
            .chain(metric_options())
            .collect(),
        }
    }

    fn run(&self, req: &StageRequest, ctx: &dyn Context) -> Result<Value, StageError> {
        let opts = eval_options(req)?;
        let gt = req
            .options
            .get_path("gt")
            .ok_or_else(|| StageError::Options("eval needs option 'gt'".into()))?;
        let report =
            evaluate_dirs(&req.input, &gt, &opts, &CtxObserver(ctx)).map_err(stage_error)?;
        if let Some(note) = &report.lpips.note
            && opts.lpips != LpipsMode::Off
        {
            ctx.warn(note);
        }
        let json = report.to_json();
        write_json_atomic(&req.output, &json).map_err(stage_error)?;
        Ok(json)
    }
}

/// The options that choose the metrics, shared with `eval-scene`.
pub fn metric_options() -> Vec<OptionSpec> {
    vec![
        OptionSpec::string(
            "lpips",
            "auto",
            "auto: LPIPS when its weights are installed (scripts/lpips/fetch-weights.sh); \
             require: fail without them; off: skip LPIPS",
        )
        .one_of(&["auto", "require", "off"]),
        OptionSpec::bool("vgg", false, "also report LPIPS-VGG (about 25x slower)"),
        OptionSpec::optional(
            "lpips_weights",
            OptionKind::Path,
            "folder holding alex.safetensors/vgg.safetensors (default: \
             $COCOG_LPIPS_WEIGHTS, else the user cache folder cocog/lpips)",
        ),
        OptionSpec::int("threads", 0, "LPIPS worker threads; 0 = all cores"),
    ]
}

/// The metric options (`lpips`, `vgg`, `threads`, `lpips_weights`) of a request; shared with
/// `eval-scene`, which scores renders the same way.
pub fn eval_options(req: &StageRequest) -> Result<EvalOptions, StageError> {
    let o = &req.options;
    let lpips = match o.get_str("lpips").unwrap_or("auto") {
        "auto" => LpipsMode::Auto,
        "require" => LpipsMode::Require,
        "off" => LpipsMode::Off,
        other => {
            return Err(StageError::Options(format!(
                "stage 'eval' option 'lpips': expected auto, require or off, got {other:?}"
            )));
        }
    };
    let threads = o.get_i64("threads").unwrap_or(0);
    let threads = usize::try_from(threads).map_err(|_| {
        StageError::Options(format!(
            "stage 'eval' option 'threads': expected 0 or more, got {threads}"
        ))
    })?;
    Ok(EvalOptions {
        lpips,
        vgg: o.get_bool("vgg").unwrap_or(false),
        threads,
        weights_dir: o.get_path("lpips_weights"),
    })
}

/// Bad images and folders are the user's input; everything else keeps its own type.
pub fn stage_error(e: MetricsError) -> StageError {
    match e {
        MetricsError::Cancelled => StageError::Cancelled,
        MetricsError::Io { path, source } | MetricsError::Write { path, source } => {
            StageError::io(path, source)
        }
        MetricsError::Decode { .. }
        | MetricsError::Unsupported { .. }
        | MetricsError::SizeMismatch { .. }
        | MetricsError::Pairing { .. }
        | MetricsError::TooSmall { .. } => StageError::Input(e.to_string()),
        MetricsError::Weights { .. } | MetricsError::WeightsNotFound { .. } => StageError::other(e),
    }
}

/// Reports scoring progress and cancellation through a stage context.
pub struct CtxObserver<'a>(pub &'a dyn Context);

impl Observer for CtxObserver<'_> {
    fn progress(&self, done: usize, total: usize) {
        self.0.progress("score images", done as u64, total as u64);
    }

    fn cancelled(&self) -> bool {
        self.0.cancelled()
    }
}
