//! The two CNN operations LPIPS needs — convolution (+bias, +ReLU) and max-pooling — on HWC
//! activations.
//!
//! Activations are kept pixel-major (HWC) so that the im2col step copies whole channel vectors
//! and the kernel can stay in the flax HWIO layout it ships in: with patch rows ordered
//! (ky, kx, cin), an HWIO kernel *is* the row-major `[K × Cout]` matrix, and the product
//! `patches[P × K] · kernel[K × Cout]` lands directly in HWC output. Each thread owns a contiguous
//! band of output pixels, so no synchronisation is needed beyond the scope join.

/// A feature map, `data[(y*w + x)*c + ch]`.
#[derive(Debug, Clone, PartialEq)]
pub struct Tensor {
    pub h: usize,
    pub w: usize,
    pub c: usize,
    pub data: Vec<f32>,
}

/// Shape and hyper-parameters of one convolution; `kernel` is HWIO `[kh, kw, cin, cout]`.
pub struct Conv<'a> {
    pub kernel: &'a [f32],
    pub bias: &'a [f32],
    pub k: usize,
    pub stride: usize,
    pub pad: usize,
    pub cout: usize,
}

/// Output side of a convolution or pooling window, or `None` when the window does not fit.
pub fn out_len(input: usize, k: usize, stride: usize, pad: usize) -> Option<usize> {
    (input + 2 * pad).checked_sub(k).map(|d| d / stride + 1)
}

/// Patch rows per gemm call. Every call re-packs the whole `K × Cout` kernel, so a call must
/// cover enough rows (≥ 256) to amortise that; the cap keeps a thread's patch block near 4 MB.
fn block_rows(kdim: usize) -> usize {
    ((1 << 20) / kdim).clamp(256, 4096)
}

/// `relu(conv(x) + bias)` with `threads` worker threads. The caller guarantees the shapes (the
/// weights loader validated them) and that the window fits.
pub fn conv_relu(x: &Tensor, conv: &Conv<'_>, threads: usize) -> Tensor {
    let cin = x.c;
    let kdim = conv.k * conv.k * cin;
    debug_assert_eq!(conv.kernel.len(), kdim * conv.cout);
    debug_assert_eq!(conv.bias.len(), conv.cout);
    let oh = out_len(x.h, conv.k, conv.stride, conv.pad).expect("conv window fits");
    let ow = out_len(x.w, conv.k, conv.stride, conv.pad).expect("conv window fits");
    let pixels = oh * ow;
    let mut out = vec![0.0f32; pixels * conv.cout];
    let per_thread = pixels.div_ceil(threads.max(1)).max(1);
    let block = block_rows(kdim);

    std::thread::scope(|s| {
        for (band, out_band) in out.chunks_mut(per_thread * conv.cout).enumerate() {
            s.spawn(move || {
                let first = band * per_thread;
                let count = out_band.len() / conv.cout;
                let mut patches = vec![0.0f32; block.min(count) * kdim];
                let mut done = 0;
                while done < count {
                    let rows = block.min(count - done);
                    let patch = &mut patches[..rows * kdim];
                    im2row(x, conv, ow, first + done, patch);
                    let dst = &mut out_band[done * conv.cout..(done + rows) * conv.cout];
                    for px in dst.chunks_exact_mut(conv.cout) {
                        px.copy_from_slice(conv.bias);
                    }
                    // SAFETY: `patch` is rows×kdim, `kernel` kdim×cout and `dst` rows×cout, all
                    // row-major and contiguous, matching the strides passed; `dst` is exclusively
                    // borrowed by this thread and does not alias the inputs.
                    unsafe {
                        matrixmultiply::sgemm(
                            rows,
                            kdim,
                            conv.cout,
                            1.0,
                            patch.as_ptr(),
                            kdim as isize,
                            1,
                            conv.kernel.as_ptr(),
                            conv.cout as isize,
                            1,
                            1.0,
                            dst.as_mut_ptr(),
                            conv.cout as isize,
                            1,
                        );
                    }
                    for v in dst.iter_mut() {
                        *v = v.max(0.0);
                    }
                    done += rows;
                }
            });
        }
    });
    Tensor {
        h: oh,
        w: ow,
        c: conv.cout,
        data: out,
    }
}

/// Fills `patch` with the receptive fields of output pixels `first..first+rows` (row-major over
/// the output), zero where the window hangs over the padding.
fn im2row(x: &Tensor, conv: &Conv<'_>, ow: usize, first: usize, patch: &mut [f32]) {
    let (k, cin) = (conv.k, x.c);
    let kdim = k * k * cin;
    for (r, row) in patch.chunks_exact_mut(kdim).enumerate() {
        let (oy, ox) = ((first + r) / ow, (first + r) % ow);
        for ky in 0..k {
            let iy = (oy * conv.stride + ky) as isize - conv.pad as isize;
            let dst_row = &mut row[ky * k * cin..(ky + 1) * k * cin];
            if iy < 0 || iy >= x.h as isize {
                dst_row.fill(0.0);
                continue;
            }
            let src_row = &x.data[iy as usize * x.w * cin..(iy as usize + 1) * x.w * cin];
            for kx in 0..k {
                let ix = (ox * conv.stride + kx) as isize - conv.pad as isize;
                let dst = &mut dst_row[kx * cin..(kx + 1) * cin];
                if ix < 0 || ix >= x.w as isize {
                    dst.fill(0.0);
                } else {
                    let ix = ix as usize;
                    dst.copy_from_slice(&src_row[ix * cin..(ix + 1) * cin]);
                }
            }
        }
    }
}

/// Max-pooling with a `k×k` window and stride `stride`, no padding, floor rounding (PyTorch's
/// `MaxPool2d` defaults and flax's `VALID`).
pub fn max_pool(x: &Tensor, k: usize, stride: usize) -> Tensor {
    let oh = out_len(x.h, k, stride, 0).expect("pool window fits");
    let ow = out_len(x.w, k, stride, 0).expect("pool window fits");
    let c = x.c;
    let mut data = vec![f32::NEG_INFINITY; oh * ow * c];
    for oy in 0..oh {
        for ox in 0..ow {
            let dst = &mut data[(oy * ow + ox) * c..(oy * ow + ox + 1) * c];
            for ky in 0..k {
                for kx in 0..k {
                    let (iy, ix) = (oy * stride + ky, ox * stride + kx);
                    let src = &x.data[(iy * x.w + ix) * c..(iy * x.w + ix + 1) * c];
                    for (d, &s) in dst.iter_mut().zip(src) {
                        *d = d.max(s);
                    }
                }
            }
        }
    }
    Tensor {
        h: oh,
        w: ow,
        c,
        data,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small deterministic pseudo-random sequence (no dependency needed for test data).
    fn noise(n: usize, seed: u64) -> Vec<f32> {
        let mut s = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (0..n)
            .map(|_| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                ((s >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
            })
            .collect()
    }

    /// Direct six-loop convolution in f64: the independent reference for the im2col + gemm path.
    fn conv_direct(x: &Tensor, conv: &Conv<'_>) -> Vec<f64> {
        let oh = out_len(x.h, conv.k, conv.stride, conv.pad).unwrap();
        let ow = out_len(x.w, conv.k, conv.stride, conv.pad).unwrap();
        let mut out = Vec::new();
        for oy in 0..oh {
            for ox in 0..ow {
                for co in 0..conv.cout {
                    let mut acc = f64::from(conv.bias[co]);
                    for ky in 0..conv.k {
                        for kx in 0..conv.k {
                            let iy = (oy * conv.stride + ky) as isize - conv.pad as isize;
                            let ix = (ox * conv.stride + kx) as isize - conv.pad as isize;
                            if iy < 0 || ix < 0 || iy >= x.h as isize || ix >= x.w as isize {
                                continue;
                            }
                            for ci in 0..x.c {
                                let xv = x.data[(iy as usize * x.w + ix as usize) * x.c + ci];
                                let kv =
                                    conv.kernel[((ky * conv.k + kx) * x.c + ci) * conv.cout + co];
                                acc += f64::from(xv) * f64::from(kv);
                            }
                        }
                    }
                    out.push(acc.max(0.0));
                }
            }
        }
        out
    }

    #[test]
    fn gemm_convolution_matches_direct_loops() {
        for (h, w, cin, cout, k, stride, pad, threads) in [
            (23, 31, 3, 8, 11, 4, 2, 2),
            (9, 7, 5, 6, 5, 1, 2, 3),
            (6, 6, 4, 3, 3, 1, 1, 1),
            (40, 45, 16, 7, 3, 1, 1, 4),
        ] {
            let x = Tensor {
                h,
                w,
                c: cin,
                data: noise(h * w * cin, 1),
            };
            let kernel = noise(k * k * cin * cout, 2);
            let bias = noise(cout, 3);
            let conv = Conv {
                kernel: &kernel,
                bias: &bias,
                k,
                stride,
                pad,
                cout,
            };
            let got = conv_relu(&x, &conv, threads);
            let want = conv_direct(&x, &conv);
            assert_eq!(got.data.len(), want.len());
            for (i, (g, w)) in got.data.iter().zip(&want).enumerate() {
                assert!(
                    (f64::from(*g) - w).abs() < 1e-4,
                    "k{k} s{stride} [{i}]: {g} vs {w}"
                );
            }
        }
    }

    #[test]
    fn max_pool_picks_window_maxima_with_floor_rounding() {
        let x = Tensor {
            h: 5,
            w: 6,
            c: 2,
            data: noise(60, 9),
        };
        let p = max_pool(&x, 3, 2);
        assert_eq!((p.h, p.w, p.c), (2, 2, 2));
        for oy in 0..2 {
            for ox in 0..2 {
                for ch in 0..2 {
                    let mut m = f32::NEG_INFINITY;
                    for y in oy * 2..oy * 2 + 3 {
                        for xx in ox * 2..ox * 2 + 3 {
                            m = m.max(x.data[(y * 6 + xx) * 2 + ch]);
                        }
                    }
                    assert_eq!(p.data[(oy * 2 + ox) * 2 + ch], m);
                }
            }
        }
    }

    #[test]
    fn out_len_follows_the_floor_formula() {
        assert_eq!(out_len(300, 11, 4, 2), Some(74));
        assert_eq!(out_len(74, 3, 2, 0), Some(36));
        assert_eq!(out_len(2, 3, 2, 0), None);
    }
}
