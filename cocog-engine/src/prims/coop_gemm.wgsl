// C = A·B on cooperative matrices (tensor cores): A (M×K) and B (K×N) in f16, row-major, C
// (M×N) in f32, row-major. Experimental: only where the adapter offers 16×16×16 f16→f32 and the
// engine was asked to enable wgpu's cooperative-matrix feature (see coop_gemm.rs). M and N are
// multiples of 64, K of 32, and subgroups are 32 wide, so a workgroup of 128 threads is four
// subgroups, each computing a 32×32 quarter of the workgroup's 64×64 block of C from f16 slices
// staged in workgroup memory.

struct Dims {
    m: u32,
    n: u32,
    k: u32,
    pad: u32,
}

@group(0) @binding(0) var<uniform> dims: Dims;
@group(0) @binding(1) var<storage, read> a: array<f16>;
@group(0) @binding(2) var<storage, read> b: array<f16>;
@group(0) @binding(3) var<storage, read_write> c: array<f32>;

const BK: u32 = 32u;
// [64 rows of A][BK] and [BK][64 columns of B].
var<workgroup> slice_a: array<f16, 2048>;
var<workgroup> slice_b: array<f16, 2048>;

@compute @workgroup_size(128)
fn coop_gemm(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let m0 = wg.y * 64u;
    let n0 = wg.x * 64u;
    // Subgroups are 32 wide (the context checks) and taken to hold consecutive invocations,
    // as on NVIDIA; Vulkan does not promise that layout, so the f64 test is the check.
    let sub = lid / 32u;
    let sm = (sub / 2u) * 32u;
    let sn = (sub % 2u) * 32u;
    var c00 = coop_mat16x16<f32, C>();
    var c01 = coop_mat16x16<f32, C>();
    var c10 = coop_mat16x16<f32, C>();
    var c11 = coop_mat16x16<f32, C>();
    for (var k0 = 0u; k0 < dims.k; k0 += BK) {
        for (var e = lid; e < 64u * BK; e += 128u) {
            slice_a[e] = a[(m0 + e / BK) * dims.k + k0 + e % BK];
            slice_b[e] = b[(k0 + e / 64u) * dims.n + n0 + e % 64u];
        }
        // A shader with cooperative matrices is emitted under the Vulkan memory model, where
        // naga 30's plain workgroup loads and stores are not formally ordered by this barrier
        // across invocations; drivers order them in practice, and the f64 test checks.
        workgroupBarrier();
        for (var kk = 0u; kk < BK; kk += 16u) {
            let a0 = coopLoadT<coop_mat16x16<f16, A>>(&slice_a[sm * BK + kk], BK);
            let a1 = coopLoadT<coop_mat16x16<f16, A>>(&slice_a[(sm + 16u) * BK + kk], BK);
            let b0 = coopLoadT<coop_mat16x16<f16, B>>(&slice_b[kk * 64u + sn], 64u);
            let b1 = coopLoadT<coop_mat16x16<f16, B>>(&slice_b[kk * 64u + sn + 16u], 64u);
            c00 = coopMultiplyAdd(a0, b0, c00);
            c01 = coopMultiplyAdd(a0, b1, c01);
            c10 = coopMultiplyAdd(a1, b0, c10);
            c11 = coopMultiplyAdd(a1, b1, c11);
        }
        workgroupBarrier();
    }
    // naga 30 emits no expression inside a coopStore call's arguments: bind them first.
    let row = dims.n;
    let at00 = (m0 + sm) * row + n0 + sn;
    let at01 = at00 + 16u;
    let at10 = at00 + 16u * row;
    let at11 = at10 + 16u;
    coopStoreT(c00, &c[at00], row);
    coopStoreT(c01, &c[at01], row);
    coopStoreT(c10, &c[at10], row);
    coopStoreT(c11, &c[at11], row);
}
