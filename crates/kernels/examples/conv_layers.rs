//! Times pgrf's convolution kernels on the SID U-Net's 3x3 layer shapes
//! (batch 2, 128 x 128 packed input): forward, weight gradient and input
//! gradient per layer, in GFLOP/s, to show which shapes fall short.
//! `RAYON_NUM_THREADS=2 cargo run --release -p pgrf-kernels --example conv_layers`
#![allow(unsafe_code)]
use pgrf_kernels::conv::ConvGeom;
use pgrf_kernels::conv_backward::{conv2d_input_grad, conv2d_weight_grad};
use pgrf_kernels::conv_forward::conv2d_forward;
use std::time::Instant;

fn median_ms(mut f: impl FnMut(), reps: usize) -> f64 {
    f();
    let mut t: Vec<f64> = (0..reps)
        .map(|_| {
            let s = Instant::now();
            f();
            s.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[reps / 2]
}

fn main() {
    // (ci, co, side) of the U-Net w32's 3x3 convolutions, encoder then decoder.
    let layers = [
        (4, 32, 128),
        (32, 32, 128),
        (32, 64, 64),
        (64, 64, 64),
        (64, 128, 32),
        (128, 128, 32),
        (128, 256, 16),
        (256, 256, 16),
        (256, 512, 8),
        (512, 512, 8),
        (512, 256, 16),
        (256, 256, 16),
        (256, 128, 32),
        (128, 128, 32),
        (128, 64, 64),
        (64, 64, 64),
        (64, 32, 128),
        (32, 32, 128),
    ];
    let (mut tf, mut tw, mut tx, mut total) = (0.0, 0.0, 0.0, 0.0);
    println!("ci   co  side   fwd ms  GF/s   dW ms  GF/s   dX ms  GF/s");
    for (ci, co, side) in layers {
        let g = ConvGeom {
            n: 2,
            ci,
            h: side,
            w: side,
            kh: 3,
            kw: 3,
            stride: [1, 1],
            pad: [1, 1],
        };
        let x: Vec<f32> = (0..2 * ci * side * side)
            .map(|i| ((i * 7919) % 1000) as f32 * 1e-3)
            .collect();
        let w: Vec<f32> = (0..co * ci * 9)
            .map(|i| ((i * 104729) % 1000) as f32 * 1e-3 - 0.5)
            .collect();
        let dy: Vec<f32> = (0..2 * co * side * side)
            .map(|i| ((i * 31) % 1000) as f32 * 1e-3)
            .collect();
        let b = vec![0.1f32; co];
        let mut out = vec![0.0f32; dy.len()];
        let mut dw = vec![0.0f32; w.len()];
        let mut dx = vec![0.0f32; x.len()];
        let gflop = 2.0 * (2 * ci * co * 9 * side * side) as f64 * 1e-9;
        let f = median_ms(
            || conv2d_forward(&x, &g, &w, co, Some(&b), None, &mut out),
            9,
        );
        let dwt = median_ms(|| conv2d_weight_grad(&x, &g, &dy, co, &mut dw), 9);
        let dxt = median_ms(|| conv2d_input_grad(&dy, &g, &w, co, &mut dx), 9);
        println!(
            "{ci:4} {co:4} {side:4} {f:8.2} {:5.0} {dwt:7.2} {:5.0} {dxt:7.2} {:5.0}",
            gflop / f * 1e3,
            gflop / dwt * 1e3,
            gflop / dxt * 1e3
        );
        (tf, tw, tx, total) = (tf + f, tw + dwt, tx + dxt, total + gflop);
    }
    // The same gemm on one large square product, parallel over the pool:
    // the ceiling the convolutions' tiles are measured against.
    let side = 1536;
    let a: Vec<f32> = (0..side * side)
        .map(|i| ((i * 7) % 100) as f32 * 1e-2)
        .collect();
    let mut c = vec![0.0f32; side * side];
    let threads = rayon::current_num_threads();
    let t = median_ms(
        || {
            // SAFETY: a, a and c are side x side row-major buffers.
            unsafe {
                gemm::gemm(
                    side,
                    side,
                    side,
                    c.as_mut_ptr(),
                    1,
                    side as isize,
                    false,
                    a.as_ptr(),
                    1,
                    side as isize,
                    a.as_ptr(),
                    1,
                    side as isize,
                    1.0,
                    1.0,
                    false,
                    false,
                    false,
                    gemm::Parallelism::Rayon(threads),
                )
            }
        },
        5,
    );
    let gf = 2.0 * (side as f64).powi(3) * 1e-9 / t * 1e3;
    println!("gemm {side}^3 product: {t:.1} ms, {gf:.0} GFLOP/s");
    println!(
        "total {total:.2} GFLOP each: forward {tf:.1} ms ({:.0} GFLOP/s), weight grad {tw:.1} ms ({:.0}), input grad {tx:.1} ms ({:.0})",
        total / tf * 1e3,
        total / tw * 1e3,
        total / tx * 1e3
    );
}
