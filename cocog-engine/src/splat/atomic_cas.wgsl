// Float add emulated on the u32 bit pattern, for adapters without float atomics.
@group(0) @binding(9) var<storage, read_write> v_proj: array<atomic<u32>>;

fn add_grad(i: u32, v: f32) {
    var old = atomicLoad(&v_proj[i]);
    loop {
        let r = atomicCompareExchangeWeak(&v_proj[i], old, bitcast<u32>(bitcast<f32>(old) + v));
        if (r.exchanged) {
            break;
        }
        old = r.old_value;
    }
}
