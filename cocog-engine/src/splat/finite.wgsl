// Whether x is neither infinite nor NaN. A bit test, because fast-math style compilers may fold
// `x == x`. The projection and the tile test share it (one module holds both).
fn finite(x: f32) -> bool {
    return (bitcast<u32>(x) & 0x7f800000u) != 0x7f800000u;
}
