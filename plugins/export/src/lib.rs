//! The `export` stage: writes a scene's Gaussians to one file, `.ply` (INRIA 3DGS, every viewer
//! reads it), `.glb` (glTF `KHR_gaussian_splatting`, the standards-track alternative) or `.spz`
//! (Niantic's compressed format: at SH 3, 65 bytes a Gaussian before gzip against the PLY's 248).

use cocog_formats::glb::write_glb;
use cocog_formats::ply::{read_splats, write_splats};
use cocog_formats::spz::write_spz;
use cocog_pipeline::{
    Context, OptionSpec, OutputKind, Scene, Stage, StageError, StageInfo, StageKind, StageRequest,
};
use serde_json::{Value, json};

pub struct Export;

/// The signed world axis closest to `up`, as Brush's `Vertical axis:` PLY comment spells it.
pub fn axis_name(up: [f64; 3]) -> String {
    let (i, v) = up
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
        .expect("three components");
    format!("{}{}", if *v < 0.0 { "-" } else { "" }, ["x", "y", "z"][i])
}

impl Stage for Export {
    fn info(&self) -> StageInfo {
        StageInfo {
            name: "export".to_owned(),
            kind: StageKind::Export,
            output: OutputKind::File,
            needs_gaussians: true,
            description: "Write the scene's Gaussians as an INRIA 3DGS .ply, a glTF KHR_gaussian_splatting .glb or a Niantic .spz".to_owned(),
            options: vec![OptionSpec::string("format", "ply", "ply | glb | spz").one_of(&["ply", "glb", "spz"])],
        }
    }

    fn run(&self, req: &StageRequest, ctx: &dyn Context) -> Result<Value, StageError> {
        let format = req.options.get_str("format").unwrap_or("ply");
        if !matches!(format, "ply" | "glb" | "spz") {
            return Err(StageError::Options(format!(
                "export: option 'format' must be ply, glb or spz, got {format:?}"
            )));
        }
        let scene = Scene::load(&req.input)?;
        let stored = scene.gaussians.as_deref().ok_or_else(|| {
            StageError::Input(format!("{}: field `gaussians`: the scene has no trained Gaussians to export (run train first)", req.input.join("scene.json").display()))
        })?;
        let path = Scene::resolve(&req.input, stored);
        let splats = read_splats(&path).map_err(|e| StageError::Input(e.to_string()))?;
        // A viewer shows an empty file as a blank scene without saying why.
        if splats.is_empty() {
            return Err(StageError::Input(format!(
                "{}: holds no Gaussians, so there is nothing to export",
                path.display()
            )));
        }
        let result = match format {
            "ply" => write_splats(&req.output, &splats, scene.up.map(axis_name).as_deref()),
            "spz" => write_spz(&req.output, &splats),
            _ => write_glb(&req.output, &splats),
        };
        result.map_err(|e| StageError::Input(e.to_string()))?;
        ctx.info(&format!(
            "export: wrote {} Gaussians (SH degree {}) as {format}",
            splats.len(),
            splats.sh_degree
        ));
        Ok(json!({"format": format, "gaussians": splats.len(), "sh_degree": splats.sh_degree}))
    }
}

/// The export stage, for the CLI to register.
pub fn stages() -> Vec<Box<dyn Stage>> {
    vec![Box::new(Export)]
}
