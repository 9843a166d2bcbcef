//! Recording F and the compositing into a training step (see conv.wgsl, norm.wgsl,
//! blend.wgsl). Every per-step buffer comes from the caller's `Workspace`.

use super::conv_gemm::{ConvGemm, ConvLayer, MapSize, NO_BIAS};
use super::conv_tile::ConvTile;
use super::conv_winograd::ConvWinograd;
use super::layout::{CompositorConfig, CompositorLayout, IN_EPS};
use super::precision::MapPrecision;
use crate::core::{Bind, GpuBuffer, GpuContext, Kernel, Recorder, Workspace, shader};
use crate::prims::AddInto;

/// Values a workgroup of norm.wgsl's element kernels takes (256 invocations, PER_INVOCATION each).
const NORM_ELEMENTS_PER_GROUP: u32 = 1024;

/// How the renders are weighted.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CompositeMode {
    /// Equal weights: before F starts (method.md §5), or a plain mean at render time.
    Uniform,
    /// F's per-pixel softmax weights.
    Learned,
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct ConvU {
    images: u32,
    cin: u32,
    cout: u32,
    k: u32,
    height: u32,
    width: u32,
    w_off: u32,
    bias_off: u32,
    pad: u32,
    per_part: u32,
    parts: u32,
    image0: u32,
}

impl ConvU {
    /// conv.wgsl's and conv_first.wgsl's uniform for `layer` on `size`, its weight gradient
    /// split into ranges of `per_part` positions, `parts` of them.
    fn new(layer: ConvLayer, size: MapSize, (per_part, parts): (u32, u32)) -> Self {
        let (cin, cout, k, w_off, bias_off) = layer;
        Self {
            images: size.images,
            cin,
            cout,
            k,
            height: size.height,
            width: size.width,
            w_off,
            bias_off,
            pad: 0,
            per_part,
            parts,
            image0: size.image0,
        }
    }
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct NormU {
    planes: u32,
    size: u32,
    eps: f32,
    pad: u32,
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct BlendU {
    images: u32,
    pixels: u32,
    uniform_weights: u32,
    pad: u32,
}

/// How F's wide convolutions run their forwards and input gradients (their weight gradients are
/// implicit GEMMs but with `Winograd`, the default).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ConvPath {
    /// Implicit GEMMs: the im2col matrix gathered while a tile loads (conv_gemm.rs).
    Gemm,
    /// Spatially tiled direct convolutions: a block's input patch staged once per slice of
    /// channels (conv_tile.rs). As fast as the GEMMs on lavapipe; unmeasured on a GPU.
    Tiled,
    /// The wide 3×3 layer's forward, input and weight gradients by Winograd's F(2×2, 3×3)
    /// (conv_winograd.rs): 2.25× fewer multiply-adds than the implicit GEMMs; the first
    /// (5×5) layer's forward and weight gradient by kernels of their own (conv_first*.wgsl).
    /// The default. Passes summing fewer channels than a slice stay implicit GEMMs.
    Winograd,
    /// The implicit GEMMs on cooperative matrices (tensor cores) with f16 operands, where the
    /// context enabled them (`COCOG_COOPERATIVE_MATRIX=1`), else `Gemm`. Experimental:
    /// checked against f64 on an H200, where at 400×300 it was slower than `Winograd`.
    Coop,
}

impl ConvPath {
    /// `Winograd` unless `COCOG_F_CONV` says `gemm`, `tiled` or `coop`: a switch for timing
    /// the paths against each other on a GPU (`cocog bench --method cocog --kernels`).
    /// Winograd is the default because it was the fastest on every adapter timed: on an H200
    /// the cocog step at 400×300 took 20.3 ms against 24.3 on tensor cores (their fastest
    /// layout) and 33.5 as implicit GEMMs, and on lavapipe F's 3×3 passes ran 1.8–2.1× faster.
    pub fn from_env() -> Self {
        crate::core::env_choice(
            "COCOG_F_CONV",
            &[
                ("gemm", ConvPath::Gemm),
                ("tiled", ConvPath::Tiled),
                ("winograd", ConvPath::Winograd),
                ("coop", ConvPath::Coop),
            ],
            "Winograd it is",
            ConvPath::Winograd,
        )
    }
}

/// A forward's results and what its backward replays.
#[derive(Debug)]
pub struct CompositeOutput {
    /// The composite, rgba, one image.
    pub blend: GpuBuffer,
    /// Per render and pixel, its weight.
    pub weights: GpuBuffer,
    pub mode: CompositeMode,
    width: u32,
    height: u32,
    images: u32,
    /// Renders F ran at once (`Compositor::chunk`); with fewer than `images`, the layers
    /// hold the last chunk's maps and the backward recomputes each chunk's.
    chunk: u32,
    /// Per layer: pre-activation, normalised output, statistics (learned mode only).
    layers: Option<[Layer; 2]>,
}

impl CompositeOutput {
    /// F's stored maps z1, y1, z2, y2 (`[image][channel][y][x]`, in the compositor's
    /// `MapPrecision`) of the last chunk of renders, in learned mode: tests compare them with
    /// the reference layer by layer.
    pub fn stored_maps(&self) -> Option<[&GpuBuffer; 4]> {
        self.layers
            .as_ref()
            .map(|[l1, l2]| [&l1.0, &l1.1, &l2.0, &l2.1])
    }
}

/// Gradients of the renders (rgba, the renders' layout) and of F's parameters (zero in
/// uniform mode).
#[derive(Debug)]
pub struct CompositeGrads {
    pub v_renders: GpuBuffer,
    pub v_params: GpuBuffer,
}

#[derive(Debug)]
pub struct Compositor {
    config: CompositorConfig,
    /// How the forward maps (each layer's pre-activation and normalised output) are stored.
    precision: MapPrecision,
    /// The C-channel layers as implicit GEMMs.
    gemm: ConvGemm,
    /// Their forwards and input gradients spatially tiled, with `ConvPath::Tiled`.
    tile: Option<ConvTile>,
    /// Their 3×3 forwards and input gradients by Winograd, with `ConvPath::Winograd`.
    winograd: Option<ConvWinograd>,
    /// With `ConvPath::Winograd`, the first (5×5, rgb) layer's forward and weight gradient.
    first: Option<FirstLayer>,
    /// The one-channel head's forward and weight gradient, direct: a 64-row GEMM tile would
    /// compute 63 rows for nothing.
    conv: Kernel,
    head_input_grad: Kernel,
    conv_weight_parts: Kernel,
    conv_weight_sum: Kernel,
    norm_stats: Kernel,
    norm_apply: Kernel,
    norm_grad_stats: Kernel,
    norm_backward: Kernel,
    blend: Kernel,
    blend_backward: Kernel,
    accumulate: AddInto,
    /// Largest buffer binding to plan F's maps for; the device's unless a test lowers it.
    binding_limit: Option<u64>,
}

/// One layer's (pre-activation, normalised output, per-plane statistics).
type Layer = (GpuBuffer, GpuBuffer, GpuBuffer);

impl Compositor {
    /// F with the convolution path `ConvPath::from_env` picks, storing its maps in the device's
    /// `MapPrecision`.
    pub fn new(ctx: &GpuContext, config: CompositorConfig) -> Self {
        Self::with_options(
            ctx,
            config,
            ConvPath::from_env(),
            MapPrecision::for_device(ctx),
        )
    }

    /// `MapPrecision::F16` needs a device created with `SHADER_F16` (`GpuContext::shader_f16`).
    pub fn with_options(
        ctx: &GpuContext,
        config: CompositorConfig,
        path: ConvPath,
        precision: MapPrecision,
    ) -> Self {
        let with_maps = |label: &str, source: &str| {
            shader(ctx, label, &format!("{}{source}", precision.prelude()))
        };
        let conv = with_maps(
            "compositor conv",
            &format!(
                "const HEAD_ROWS: u32 = {HEAD_ROWS}u;\n{}{}",
                include_str!("conv_common.wgsl"),
                include_str!("conv.wgsl")
            ),
        );
        let norm = with_maps(
            "compositor norm",
            &format!(
                "const PER_INVOCATION: u32 = {}u;\n{}",
                NORM_ELEMENTS_PER_GROUP / 256,
                include_str!("norm.wgsl")
            ),
        );
        let blend = shader(ctx, "compositor blend", include_str!("blend.wgsl"));
        Self {
            config,
            precision,
            gemm: ConvGemm::new(ctx, config.channels, precision, path == ConvPath::Coop),
            tile: (path == ConvPath::Tiled).then(|| ConvTile::new(ctx, precision)),
            winograd: (path == ConvPath::Winograd && ConvWinograd::fits(ctx, config.channels))
                .then(|| ConvWinograd::new(ctx, precision)),
            first: (path == ConvPath::Winograd).then(|| {
                let m = with_maps(
                    "compositor first layer",
                    &format!(
                        "const SLICE: u32 = {}u;\nconst COLUMNS: u32 = {}u;\n{}{}",
                        FirstLayer::SLICE,
                        FirstLayer::COLUMNS,
                        include_str!("conv_common.wgsl"),
                        include_str!("conv_first.wgsl")
                    ),
                );
                let f = with_maps(
                    "compositor first layer forward",
                    &format!(
                        "{}{}",
                        include_str!("conv_common.wgsl"),
                        include_str!("conv_first_forward.wgsl")
                    ),
                );
                FirstLayer {
                    forward: Kernel::labelled(
                        ctx,
                        &f,
                        "first_forward",
                        "conv first forward (direct)",
                    ),
                    direct: direct_first_forward(ctx),
                    weight_part: Kernel::labelled(
                        ctx,
                        &m,
                        "first_weight_part",
                        "conv first weight grad",
                    ),
                    weight_sum: Kernel::labelled(
                        ctx,
                        &m,
                        "first_weight_sum",
                        "conv first weight grad (sum)",
                    ),
                }
            }),
            conv: Kernel::new(ctx, &conv, "conv_forward"),
            head_input_grad: Kernel::labelled(
                ctx,
                &conv,
                "head_input_grad",
                "conv head input grad",
            ),
            conv_weight_parts: Kernel::labelled(
                ctx,
                &conv,
                "head_weight_grad_part",
                "conv head weight grad",
            ),
            conv_weight_sum: Kernel::new(ctx, &conv, "conv_weight_grad_sum"),
            norm_stats: Kernel::new(ctx, &norm, "norm_stats"),
            norm_apply: Kernel::new(ctx, &norm, "norm_apply"),
            norm_grad_stats: Kernel::new(ctx, &norm, "norm_grad_stats"),
            norm_backward: Kernel::new(ctx, &norm, "norm_backward"),
            blend: Kernel::new(ctx, &blend, "blend_forward"),
            blend_backward: Kernel::new(ctx, &blend, "blend_backward"),
            accumulate: AddInto::new(ctx),
            binding_limit: None,
        }
    }

    /// With `ConvPath::Winograd`, whether the first layer's forward runs as its own direct
    /// kernel (`true`) or as an implicit GEMM; `COCOG_F_FIRST` picks it otherwise.
    pub fn with_direct_first_forward(mut self, direct: bool) -> Self {
        if let Some(first) = &mut self.first {
            first.direct = direct;
        }
        self
    }

    pub fn precision(&self) -> MapPrecision {
        self.precision
    }

    /// Whether the wide 3×3 layer's passes run by Winograd (fewer products than the
    /// convolution's own, which `cocog bench` counts).
    pub fn runs_winograd(&self) -> bool {
        let [_, c2, _] = self.convs();
        self.winograd_for(c2, false).is_some()
    }

    /// How F's convolutions run, in words, from the kernels this compositor built and the
    /// passes that use them (not from the switches that asked: Winograd serves only a 3×3
    /// layer summing `ConvWinograd::MIN_SUMMED` channels or more, and tensor cores give way to
    /// the f32 tiles where none were enabled).
    pub fn describe(&self) -> String {
        let wide = if self.runs_winograd() {
            "3×3 layer by Winograd F(2×2, 3×3)".to_owned()
        } else if self.tile.is_some() {
            "tiled convolutions (COCOG_F_CONV=tiled)".to_owned()
        } else if let Some(b) = self.gemm.coop_block() {
            format!(
                "implicit GEMMs on tensor cores (COCOG_F_CONV=coop, block {})",
                b.name().unwrap_or("unnamed")
            )
        } else {
            "implicit GEMMs".to_owned()
        };
        match &self.first {
            Some(f) if f.direct => format!("{wide}, the first layer's forward direct"),
            Some(_) => format!("{wide}, the first layer's forward as an implicit GEMM"),
            None => wide,
        }
    }

    /// Plans F's maps for bindings of at most `bytes` (tests reach the chunked path with it).
    pub fn with_binding_limit(mut self, bytes: u64) -> Self {
        self.set_binding_limit(bytes);
        self
    }

    pub fn set_binding_limit(&mut self, bytes: u64) {
        self.binding_limit = Some(bytes);
    }

    /// Renders F runs at once: all `images`, or as many as one binding holds of a layer's
    /// maps (at least one; a render whose maps outgrow a binding is refused before training).
    fn chunk(&self, ctx: &GpuContext, pixels: u64, images: u32) -> u32 {
        let limit = self.binding_limit.unwrap_or_else(|| ctx.binding_limit());
        self.config.renders_per_chunk(limit, pixels, images)
    }

    /// Both layers' buffers for `images` renders.
    fn layer_buffers(
        &self,
        ws: &mut Workspace,
        ctx: &GpuContext,
        pixels: u64,
        images: u32,
    ) -> [Layer; 2] {
        // map_bytes counts f32 values; the stored maps take the precision's size.
        let maps = self.config.map_bytes(pixels, images) / 4 * self.precision.bytes();
        let stats = u64::from(images * self.config.channels) * 8;
        [
            (
                ws.buffer(ctx, "compositor z1", maps),
                ws.buffer(ctx, "compositor y1", maps),
                ws.buffer(ctx, "compositor stats1", stats),
            ),
            (
                ws.buffer(ctx, "compositor z2", maps),
                ws.buffer(ctx, "compositor y2", maps),
                ws.buffer(ctx, "compositor stats2", stats),
            ),
        ]
    }

    /// F's two normalised layers for `size.images` renders from render `size.image0`, into
    /// `layers` (which hold those renders alone).
    fn trunk_forward(
        &self,
        rec: &mut Recorder,
        ws: &mut Workspace,
        params: &dyn Bind,
        renders: &dyn Bind,
        [l1, l2]: &[Layer; 2],
        size: MapSize,
    ) {
        let [c1, c2, _] = self.convs();
        let planes = size.images * self.config.channels;
        let pixels = size.width * size.height;
        let local = MapSize { image0: 0, ..size };
        self.conv(rec, ws, c1, size, params, renders, &l1.0, true);
        self.relu_norm(rec, l1, planes, pixels);
        self.conv(rec, ws, c2, local, params, &l1.1, &l2.0, false);
        self.relu_norm(rec, l2, planes, pixels);
    }

    pub fn layout(&self) -> CompositorLayout {
        self.config.layout()
    }

    /// Fresh parameters (PyTorch's Conv2d initialisation), deterministic in `seed`.
    pub fn init_params(&self, seed: u64) -> Vec<f32> {
        self.layout().init(seed)
    }

    /// (in, out, kernel, weight offset, bias offset) of F's three convolutions.
    fn convs(&self) -> [ConvLayer; 3] {
        let l = self.layout();
        let c = l.channels as u32;
        [
            (3, c, 5, l.conv1_w as u32, l.conv1_b as u32),
            (c, c, 3, l.conv2_w as u32, l.conv2_b as u32),
            (c, 1, 3, l.head_w as u32, NO_BIAS),
        ]
    }

    fn conv_uniform(
        rec: &mut Recorder,
        layer: ConvLayer,
        size: MapSize,
    ) -> crate::core::UniformSlot {
        // The forward's: no weight-gradient split.
        rec.uniform(&ConvU::new(layer, size, (0, 0)))
    }

    /// Records F (in learned mode) and the composite of `images` rgba renders of `w`×`h`.
    pub fn encode_forward(
        &self,
        rec: &mut Recorder,
        ws: &mut Workspace,
        params: &wgpu::Buffer,
        renders: &wgpu::Buffer,
        w: u32,
        h: u32,
        images: u32,
        mode: CompositeMode,
    ) -> CompositeOutput {
        let ctx = rec.ctx();
        let pixels = u64::from(w * h);
        let blend = ws.buffer(ctx, "composite blend", pixels * 16);
        let weights = ws.buffer(ctx, "composite weights", pixels * u64::from(images) * 4);
        let logits = ws.buffer(ctx, "composite logits", pixels * u64::from(images) * 4);
        let chunk = self.chunk(ctx, pixels, images);
        let layers = (mode == CompositeMode::Learned).then(|| {
            let head = self.convs()[2];
            let layers = self.layer_buffers(ws, ctx, pixels, chunk);
            for size in chunks(w, h, images, chunk) {
                self.trunk_forward(rec, ws, params, renders, &layers, size);
                self.conv_forward(rec, head, params, &layers[1].1, &logits, size);
            }
            layers
        });
        let u = rec.uniform(&BlendU {
            images,
            pixels: w * h,
            uniform_weights: u32::from(mode == CompositeMode::Uniform),
            pad: 0,
        });
        // Uniform mode reads no logits; the renders stand in for the binding.
        let logits_in: &dyn Bind = if layers.is_some() { &logits } else { renders };
        self.blend.dispatch_1d(
            rec,
            &[
                (0, &u),
                (1, renders),
                (2, logits_in),
                (3, &weights),
                (4, &blend),
            ],
            (w * h).div_ceil(256),
        );
        CompositeOutput {
            blend,
            weights,
            mode,
            width: w,
            height: h,
            images,
            chunk,
            layers,
        }
    }

    /// The Winograd kernels where they pay for a 3×3 pass: one that sums fewer channels than a
    /// staged slice (the head's input gradient sums one) would multiply zeros.
    fn winograd_for(
        &self,
        (cin, cout, ks, _, _): ConvLayer,
        input_grad: bool,
    ) -> Option<&ConvWinograd> {
        let summed = if input_grad { cout } else { cin };
        self.winograd
            .as_ref()
            .filter(|_| ks == 3 && summed >= ConvWinograd::MIN_SUMMED)
    }

    /// A wide layer's forward on the chosen path.
    #[allow(clippy::too_many_arguments)]
    fn conv(
        &self,
        rec: &mut Recorder,
        ws: &mut Workspace,
        layer: ConvLayer,
        size: MapSize,
        params: &dyn Bind,
        input: &dyn Bind,
        output: &dyn Bind,
        rgba: bool,
    ) {
        if let Some(w) = self.winograd_for(layer, false).filter(|_| !rgba) {
            return w.forward(rec, ws, layer, size, params, input, output);
        }
        if let Some(first) = self.first.as_ref().filter(|f| rgba && f.direct) {
            return first.forward(rec, layer, size, params, input, output);
        }
        match &self.tile {
            Some(t) => t.forward(rec, layer, size, params, input, output, rgba),
            None => self
                .gemm
                .forward(rec, ws, layer, size, params, input, output, rgba),
        }
    }

    /// A layer's input gradient on the chosen path.
    #[allow(clippy::too_many_arguments)]
    fn conv_input_grad(
        &self,
        rec: &mut Recorder,
        ws: &mut Workspace,
        layer: ConvLayer,
        size: MapSize,
        params: &dyn Bind,
        v_out: &dyn Bind,
        v_in: &dyn Bind,
    ) {
        if let Some(w) = self.winograd_for(layer, true) {
            return w.input_grad(rec, ws, layer, size, params, v_out, v_in);
        }
        match &self.tile {
            Some(t) => t.input_grad(rec, layer, size, params, v_out, v_in),
            None => self
                .gemm
                .input_grad(rec, ws, layer, size, params, v_out, v_in),
        }
    }

    /// The head's forward, one thread per output value, into the logits of renders
    /// `size.image0`.. .
    fn conv_forward(
        &self,
        rec: &mut Recorder,
        layer: ConvLayer,
        params: &dyn Bind,
        input: &dyn Bind,
        output: &dyn Bind,
        size: MapSize,
    ) {
        assert!(
            layer.1 == 1 && layer.2 == 3,
            "conv.wgsl's forward takes F's 3×3 one-channel head, not {layer:?}"
        );
        let u = Self::conv_uniform(rec, layer, size);
        let total = size.images * size.width * size.height;
        self.conv.dispatch_1d(
            rec,
            &[(0, &u), (1, params), (2, input), (3, output)],
            total.div_ceil(256),
        );
    }

    /// The head's input gradient (the gradient of y2) for renders `size.image0`.. from every
    /// render's logit gradient, into the chunk's maps.
    fn head_input_grad(
        &self,
        rec: &mut Recorder,
        layer: ConvLayer,
        size: MapSize,
        params: &dyn Bind,
        v_logits: &dyn Bind,
        v_in: &dyn Bind,
    ) {
        assert!(
            layer.1 == 1 && layer.2 == 3,
            "conv.wgsl's input gradient takes F's 3×3 one-channel head, not {layer:?}"
        );
        let u = Self::conv_uniform(rec, layer, size);
        self.head_input_grad.dispatch_1d(
            rec,
            &[(0, &u), (1, params), (4, v_logits), (5, v_in)],
            (size.images * size.width * size.height).div_ceil(256),
        );
    }

    fn norm_uniform(rec: &mut Recorder, planes: u32, size: u32) -> crate::core::UniformSlot {
        rec.uniform(&NormU {
            planes,
            size,
            eps: IN_EPS as f32,
            pad: 0,
        })
    }

    fn relu_norm(
        &self,
        rec: &mut Recorder,
        l: &(GpuBuffer, GpuBuffer, GpuBuffer),
        planes: u32,
        size: u32,
    ) {
        let u = Self::norm_uniform(rec, planes, size);
        self.norm_stats
            .dispatch_1d(rec, &[(0, &u), (1, &l.0), (3, &l.2)], planes);
        self.norm_apply.dispatch_1d(
            rec,
            &[(0, &u), (1, &l.0), (2, &l.1), (3, &l.2)],
            (planes * size).div_ceil(NORM_ELEMENTS_PER_GROUP),
        );
    }

    /// Records the adjoint: the renders' gradient and (learned mode) F's parameter gradient.
    pub fn encode_backward(
        &self,
        rec: &mut Recorder,
        ws: &mut Workspace,
        params: &wgpu::Buffer,
        renders: &wgpu::Buffer,
        out: &CompositeOutput,
        v_blend: &wgpu::Buffer,
    ) -> CompositeGrads {
        let ctx = rec.ctx();
        let (w, h, images) = (out.width, out.height, out.images);
        let pixels = u64::from(w * h);
        let c = self.config.channels;
        let v_renders = ws.buffer(ctx, "composite v renders", pixels * u64::from(images) * 16);
        let v_logits = ws.buffer(ctx, "composite v logits", pixels * u64::from(images) * 4);
        let v_params = ws.zeroed(rec, "compositor v params", self.layout().len as u64 * 4);
        let u = rec.uniform(&BlendU {
            images,
            pixels: w * h,
            uniform_weights: u32::from(out.mode == CompositeMode::Uniform),
            pad: 0,
        });
        self.blend_backward.dispatch_1d(
            rec,
            &[
                (0, &u),
                (1, renders),
                (3, &out.weights),
                (4, &out.blend),
                (5, v_blend),
                (6, &v_renders),
                (7, &v_logits),
            ],
            (w * h).div_ceil(256),
        );
        if let Some(layers) = &out.layers {
            let chunk = out.chunk;
            let maps = self.config.map_bytes(pixels, chunk);
            let v_y = ws.buffer(ctx, "compositor v y", maps);
            let v_z = ws.buffer(ctx, "compositor v z", maps);
            let grad_stats = ws.buffer(ctx, "compositor grad stats", u64::from(chunk * c) * 8);
            let chunked = chunk < images;
            let bytes = self.layout().len as u64 * 4;
            for size in chunks(w, h, images, chunk) {
                // Each chunk writes its whole gradient, then adds it to the view's.
                let target = if chunked {
                    self.trunk_forward(rec, ws, params, renders, layers, size);
                    ws.zeroed(rec, "compositor v params chunk", bytes)
                } else {
                    v_params.clone()
                };
                let scratch = (&v_y, &v_z, &grad_stats);
                self.chunk_backward(
                    rec, ws, params, renders, layers, &v_logits, scratch, &target, size,
                );
                if chunked {
                    let n = self.layout().len as u32;
                    self.accumulate.encode(rec, &target, &v_params, n);
                }
            }
        }
        CompositeGrads {
            v_renders,
            v_params,
        }
    }

    /// F's parameter gradient (into `v_params`, every entry written) from renders
    /// `size.image0`.. whose layers are `layers`, given every render's logit gradient.
    #[allow(clippy::too_many_arguments)]
    fn chunk_backward(
        &self,
        rec: &mut Recorder,
        ws: &mut Workspace,
        params: &wgpu::Buffer,
        renders: &wgpu::Buffer,
        [l1, l2]: &[Layer; 2],
        v_logits: &GpuBuffer,
        (v_y, v_z, grad_stats): (&GpuBuffer, &GpuBuffer, &GpuBuffer),
        v_params: &GpuBuffer,
        size: MapSize,
    ) {
        let [c1, c2, head] = self.convs();
        let planes = size.images * self.config.channels;
        let pixels = size.width * size.height;
        let local = MapSize { image0: 0, ..size };
        let g = &self.gemm;
        // head: weights, then the gradient of its input y2.
        self.weight_grads(rec, ws, head, &l2.1, v_logits, v_params, size);
        self.head_input_grad(rec, head, size, params, v_logits, v_y);
        self.relu_norm_backward(rec, l2, v_y, v_z, grad_stats, planes, pixels);
        match self.winograd_for(c2, false) {
            Some(w) => w.weight_grad(rec, ws, c2, local, &l1.1, v_z, v_params),
            None => g.weight_grad(rec, ws, c2, local, &l1.1, v_z, v_params, false),
        }
        self.conv_input_grad(rec, ws, c2, local, params, v_z, v_y);
        self.relu_norm_backward(rec, l1, v_y, v_z, grad_stats, planes, pixels);
        match &self.first {
            Some(first) => first.weight_grad(rec, ws, c1, size, renders, v_z, v_params),
            None => g.weight_grad(rec, ws, c1, size, renders, v_z, v_params, true),
        }
    }

    /// The head's weight gradient: partial sums over blocks of `HEAD_ROWS` rows × 64 columns,
    /// then one fixed-order sum per weight (conv.wgsl).
    fn weight_grads(
        &self,
        rec: &mut Recorder,
        ws: &mut Workspace,
        layer: ConvLayer,
        input: &dyn Bind,
        v_out: &dyn Bind,
        v_params: &dyn Bind,
        size: MapSize,
    ) {
        let (cin, cout, k, _, bias) = layer;
        assert!(
            cout == 1 && k == 3 && bias == NO_BIAS,
            "conv.wgsl's weight gradient takes F's 3×3 one-channel head, not {layer:?}"
        );
        let count = cin * 9;
        let (row_blocks, col_blocks) = (size.height.div_ceil(HEAD_ROWS), size.width.div_ceil(64));
        let parts = size.images * row_blocks * col_blocks;
        let u = rec.uniform(&ConvU::new(layer, size, (0, parts)));
        let partials = ws.buffer(
            rec.ctx(),
            "compositor head partials",
            u64::from(parts) * u64::from(count) * 4,
        );
        self.conv_weight_parts.dispatch(
            rec,
            &[(0, &u), (2, input), (4, v_out), (7, &partials)],
            [col_blocks, row_blocks, size.images * cin],
        );
        self.conv_weight_sum
            .dispatch_1d(rec, &[(0, &u), (6, v_params), (7, &partials)], count);
    }

    fn relu_norm_backward(
        &self,
        rec: &mut Recorder,
        l: &(GpuBuffer, GpuBuffer, GpuBuffer),
        v_y: &wgpu::Buffer,
        v_z: &wgpu::Buffer,
        grad_stats: &wgpu::Buffer,
        planes: u32,
        size: u32,
    ) {
        let u = Self::norm_uniform(rec, planes, size);
        self.norm_grad_stats.dispatch_1d(
            rec,
            &[(0, &u), (2, &l.1), (4, v_y), (6, grad_stats)],
            planes,
        );
        self.norm_backward.dispatch_1d(
            rec,
            &[
                (0, &u),
                (1, &l.0),
                (2, &l.1),
                (3, &l.2),
                (4, v_y),
                (5, v_z),
                (6, grad_stats),
            ],
            (planes * size).div_ceil(NORM_ELEMENTS_PER_GROUP),
        );
    }
}

/// F's first layer (5×5, rgb → C): its forward as conv_first_forward.wgsl computes it, its
/// weight gradient as conv_first.wgsl does.
#[derive(Debug)]
struct FirstLayer {
    forward: Kernel,
    /// Whether `forward` runs it, else the implicit GEMM does.
    direct: bool,
    weight_part: Kernel,
    weight_sum: Kernel,
}

impl FirstLayer {
    /// Output channels per workgroup of the direct forward, and its block of pixels.
    const FORWARD_CHANNELS: u32 = 32;
    const FORWARD_BLOCK: (u32, u32) = (32, 4);

    /// The layer's output channels; its kernels take F's 5×5 rgb layer alone.
    fn checked(layer: ConvLayer) -> u32 {
        let (cin, cout, k, _, _) = layer;
        assert!(
            cin == 3 && k == 5,
            "conv_first*.wgsl take F's 5×5 rgb layer, not {layer:?}"
        );
        cout
    }

    /// The layer's forward into `z` (the chunk's maps) from renders `size.image0`.. .
    fn forward(
        &self,
        rec: &mut Recorder,
        layer: ConvLayer,
        size: MapSize,
        params: &dyn Bind,
        renders: &dyn Bind,
        z: &dyn Bind,
    ) {
        let cout = Self::checked(layer);
        let u = Compositor::conv_uniform(rec, layer, size);
        let (bw, bh) = Self::FORWARD_BLOCK;
        self.forward.dispatch(
            rec,
            &[(0, &u), (1, params), (2, renders), (3, z)],
            [
                size.width.div_ceil(bw),
                size.height.div_ceil(bh),
                size.images * cout.div_ceil(Self::FORWARD_CHANNELS),
            ],
        );
    }

    /// Pixels of a staged slice and columns of the result (75 weights and the bias), which
    /// conv_first.wgsl is compiled with, and output channels per workgroup (its 16 × 4 layout
    /// of invocations).
    const SLICE: u32 = 16;
    const COLUMNS: u32 = 76;
    const BLOCK: u32 = 64;

    /// The layer's weight and bias gradients from its output's gradient `v_out` (the chunk's
    /// maps) and renders `size.image0`.., written into `v_params`.
    #[allow(clippy::too_many_arguments)]
    fn weight_grad(
        &self,
        rec: &mut Recorder,
        ws: &mut Workspace,
        layer: ConvLayer,
        size: MapSize,
        renders: &dyn Bind,
        v_out: &dyn Bind,
        v_params: &dyn Bind,
    ) {
        let cout = Self::checked(layer);
        // Its ranges whole slices.
        let positions = size.images * size.width * size.height;
        let per_part = weight_grad_split(positions).0.next_multiple_of(Self::SLICE);
        let parts = positions.div_ceil(per_part).max(1);
        let u = rec.uniform(&ConvU::new(layer, size, (per_part, parts)));
        let partials = ws.buffer(
            rec.ctx(),
            "compositor first-layer partials",
            u64::from(parts * cout * Self::COLUMNS) * 4,
        );
        self.weight_part.dispatch(
            rec,
            &[(0, &u), (2, renders), (4, v_out), (7, &partials)],
            [parts, 1, cout.div_ceil(Self::BLOCK)],
        );
        self.weight_sum.dispatch_1d(
            rec,
            &[(0, &u), (6, v_params), (7, &partials)],
            cout * Self::COLUMNS,
        );
    }
}

/// Rows of a block of the head's weight gradient: each invocation walks this many down its
/// column, paying the window's first six loads and the block's tree once for them. On lavapipe
/// (dev-table at 100×75, six renders of 64 channels) the gradient took 46, 28 and 21 ms with 16,
/// 32 and 64 rows, against 55 ms one invocation per (weight, range); 32 still gives a 100×75
/// frame's six renders some 2300 workgroups to spread over a GPU.
const HEAD_ROWS: u32 = 32;

/// The first layer's weight-gradient split of `positions` (image, pixel) pairs: positions per
/// range and ranges. Ranges of at least `MIN_PART` positions amortise a thread's start; at most
/// `MAX_PARTS` of them keep the per-weight sums short.
fn weight_grad_split(positions: u32) -> (u32, u32) {
    const MIN_PART: u32 = 256;
    const MAX_PARTS: u32 = 1024;
    let per_part = positions.div_ceil(MAX_PARTS).max(MIN_PART);
    (per_part, positions.div_ceil(per_part).max(1))
}

/// The maps of each chunk of at most `chunk` of `images` renders of `w`×`h`.
fn chunks(w: u32, h: u32, images: u32, chunk: u32) -> impl Iterator<Item = MapSize> {
    let chunk = chunk.max(1);
    (0..images)
        .step_by(chunk as usize)
        .map(move |image0| MapSize {
            width: w,
            height: h,
            images: chunk.min(images - image0),
            image0,
        })
}

/// Whether F's first layer's forward (under `ConvPath::Winograd`) runs as its own direct
/// kernel: `COCOG_F_FIRST=direct` or `gemm` where set, else direct on a GPU and the implicit
/// GEMM on a CPU adapter. The GEMM's im2col tile pays a division, a bounds test and a gather
/// per element (about 2 % of an H200's f32 rate); the direct kernel broadcasts its weights
/// from workgroup memory. On an H100 (2026-11-28, six renders) it took 0.660 ms at 400×300
/// against the GEMM's 1.140 (the cocog step 16.4 against 17.0 ms) and 0.075 against 0.091 at
/// 100×75. On lavapipe it is the slower (120 against 81 ms at 100×75). One pixel per
/// invocation with its 75 inputs in a local array took 5.5 ms at 400×300 on an H200, so this
/// one keeps its sums in named variables.
pub fn direct_first_forward(ctx: &GpuContext) -> bool {
    crate::core::env_choice(
        "COCOG_F_FIRST",
        &[("gemm", false), ("direct", true)],
        "the adapter's default stays",
        !ctx.is_cpu(),
    )
}
