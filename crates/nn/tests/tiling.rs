//! Tiled inference against untiled inference with real networks: a frame
//! that fits in one tile is restored exactly as a whole; a tiled frame
//! differs from the whole-frame result only smoothly, with no step along the
//! tile borders (a hard cut between the same tiles shows one).

use ndarray::{s, Array3, ArrayView3};
use pgrf_nn::backend::Cpu;
use pgrf_nn::infer::image::{frame_plan, reflect_pad, EDGE_MARGIN};
use pgrf_nn::infer::start::start_noise;
use pgrf_nn::infer::{restore_image, ImageOptions, Restore, Restorer, SamplerChoice};
use pgrf_nn::weights::{NoiseSource, WeightMeta};
use pgrf_nn::Architecture;
use pgrf_nn::{SidUnetConfig, Sr3Config};

/// Scales every weight: burn's default initialisation shrinks activations
/// layer by layer, so an untrained deep U-Net barely looks at its input;
/// scaled up, its output depends on the context the way a trained one does.
struct Scale(f32);
impl burn::module::ModuleMapper<Cpu> for Scale {
    fn map_float<const D: usize>(
        &mut self,
        param: burn::module::Param<burn::tensor::Tensor<Cpu, D>>,
    ) -> burn::module::Param<burn::tensor::Tensor<Cpu, D>> {
        let k = self.0;
        param.map(|t| t * k)
    }
}

fn restorer(arch: Architecture, scale: f32) -> Restorer<Cpu> {
    let device = Default::default();
    let net = arch.init_seeded::<Cpu>(&device, 5).unwrap();
    let net = burn::module::Module::map(net, &mut Scale(scale));
    let meta = WeightMeta::new(arch, NoiseSource::default());
    Restorer::new(net, meta, SamplerChoice::default(), 0.5, device).unwrap()
}

fn scene(h: usize, w: usize) -> Array3<f32> {
    Array3::from_shape_fn((4, h, w), |(c, i, j)| {
        let (y, x) = (i as f32, j as f32);
        let smooth = 0.3 + 0.2 * (x / 23.0 + c as f32).sin() * (y / 17.0).cos();
        let edge = if (x - 70.0).abs() + (y - 40.0).abs() < 25.0 {
            0.3
        } else {
            0.0
        };
        let grain = (((i * 131 + j * 71 + c * 29) % 97) as f32 / 97.0 - 0.5) * 0.1;
        (smooth + edge + grain).clamp(0.0, 1.0)
    })
}

/// Second difference of `e`'s column means at each inner column x (mean
/// over planes of |m(x+1) - 2 m(x) + m(x-1)|): a step between two columns
/// is a spike here, a smooth difference between tiled and whole-frame
/// results is not, and pixel noise averages out in the column means.
fn column_kinks(e: &Array3<f32>) -> Vec<f64> {
    let (c, h, w) = e.dim();
    let mean = |k: usize, x: usize| (0..h).map(|y| e[[k, y, x]] as f64).sum::<f64>() / h as f64;
    let mut out = vec![0.0; w];
    for (x, o) in out.iter_mut().enumerate().take(w - 1).skip(1) {
        *o = (0..c)
            .map(|k| (mean(k, x + 1) - 2.0 * mean(k, x) + mean(k, x - 1)).abs())
            .sum::<f64>()
            / c as f64;
    }
    out
}

fn check(r: &dyn Restore, name: &str) {
    // 56 rows: one row of tiles of 64 once mirrored by the edge margin.
    let (h, w) = (56, 176);
    let x = scene(h, w);
    let whole_opts = ImageOptions {
        tile: 1024,
        overlap: 16,
        seed: 3,
        noise: None,
    };
    let whole = restore_image(r, x.view(), &whole_opts, &pgrf_core::NoProgress).unwrap();
    // One tile is the untiled network output itself (to 1e-5), on the frame
    // mirrored by the edge margin (the start fields likewise) and cut back.
    let m = EDGE_MARGIN;
    let xp = reflect_pad(x.view(), m, 0, 0);
    let x0s: Vec<Array3<f32>> = (0..r.samples() as u64)
        .map(|k| reflect_pad(start_noise(3, k, 4, h, w).view(), m, 0, 0))
        .collect();
    let views: Vec<ArrayView3<f32>> = x0s.iter().map(|a| a.view()).collect();
    let crop = s![.., m..m + h, m..m + w];
    let direct = r
        .restore(xp.view(), &views, None)
        .unwrap()
        .slice(crop)
        .mapv(|v| v.clamp(0.0, 1.0));
    let d = (&whole - &direct)
        .iter()
        .fold(0.0f32, |m, v| m.max(v.abs()));
    assert!(d <= 1e-5, "{name}: one tile differs from untiled by {d}");

    // Tiles of 64 with overlap 16: four columns of tiles, the last flush.
    let opts = ImageOptions {
        tile: 64,
        overlap: 16,
        seed: 3,
        noise: None,
    };
    // The tiles of the mirrored frame, as restore_image cuts them.
    let plan = frame_plan(r, h, w, &opts).unwrap();
    assert!(plan.cols.count() >= 3, "{name}");
    let tiled = restore_image(r, x.view(), &opts, &pgrf_core::NoProgress).unwrap();
    // The same tiles averaged with equal weights where they overlap: the
    // common naive blend, which steps wherever a tile begins or ends.
    let (hp, wp) = (h + 2 * m, w + 2 * m);
    let mut sum = Array3::<f32>::zeros((4, hp, wp));
    let mut count = ndarray::Array2::<f32>::zeros((hp, wp));
    for t in plan.tiles() {
        let sl = s![.., t.y..t.y + t.h, t.x..t.x + t.w];
        let xv: Vec<ArrayView3<f32>> = x0s.iter().map(|a| a.slice(sl)).collect();
        let out = r
            .restore(xp.slice(sl), &xv, None)
            .unwrap()
            .mapv(|v| v.clamp(0.0, 1.0));
        let mut dst = sum.slice_mut(sl);
        dst += &out;
        let mut c = count.slice_mut(s![t.y..t.y + t.h, t.x..t.x + t.w]);
        c += 1.0;
    }
    let naive = (&sum / &count.insert_axis(ndarray::Axis(0)))
        .slice(crop)
        .to_owned();
    let e_soft = &tiled - &whole;
    let e_naive = &naive - &whole;
    let soft = column_kinks(&e_soft);
    let avg = column_kinks(&e_naive);
    // Columns where a tile begins or ends (and their neighbours), and the
    // rest; the plan's columns are the mirrored frame's, m before the frame.
    let mut edge = vec![false; w];
    for k in 1..plan.cols.count() {
        for c in [plan.cols.starts[k], plan.cols.starts[k - 1] + plan.cols.len] {
            let c = c.saturating_sub(m);
            let from = c.saturating_sub(1);
            for flag in edge.iter_mut().take(c + 1).skip(from) {
                *flag = true;
            }
        }
    }
    let max_where = |v: &[f64], at_edge: bool| {
        v.iter()
            .zip(&edge)
            .filter(|(_, e)| **e == at_edge)
            .fold(0.0f64, |m, (x, _)| m.max(*x))
    };
    let (soft_edge, naive_edge) = (max_where(&soft, true), max_where(&avg, true));
    let soft_rest = max_where(&soft, false);
    let mean_abs = e_soft.iter().map(|v| v.abs() as f64).sum::<f64>() / e_soft.len() as f64;
    eprintln!(
        "{name}: mean |tiled - whole| {mean_abs:.2e}; largest column kink at tile edges: pgrf blend {soft_edge:.2e}, equal-weight average {naive_edge:.2e}; elsewhere (pgrf) {soft_rest:.2e}"
    );
    // The equal-weight average steps at the tile edges; pgrf's blend does not:
    // its kinks there are no larger than anywhere else in the frame.
    assert!(
        naive_edge > 2.0 * soft_rest,
        "{name}: the test shows no step to remove"
    );
    assert!(
        soft_edge <= soft_rest,
        "{name}: kink {soft_edge} at an edge vs {soft_rest} elsewhere"
    );
}

#[test]
fn sid_unet_tiles_blend_without_seams() {
    let r = restorer(
        Architecture::SidUnet(SidUnetConfig::new().with_width(8)),
        2.0,
    );
    check(&r, "SID U-Net");
}

/// A small SR3 (three levels, attention at the last) for the flow tests.
fn small_sr3() -> Architecture {
    Architecture::Sr3(
        Sr3Config::new()
            .with_inner_channels(8)
            .with_channel_mults(vec![1, 2, 2])
            .with_res_blocks(1)
            .with_attn_levels(vec![2])
            .with_norm_groups(4),
    )
}

#[test]
fn flow_model_tiles_blend_without_seams() {
    let r = restorer(small_sr3(), 1.0);
    check(&r, "SR3 two-stage");
}

/// PSNR (dB, peak 1) of `a` against `b`: 10 log10(1 / MSE), the MSE in f64.
fn psnr(a: &Array3<f32>, b: &Array3<f32>) -> f64 {
    assert_eq!(a.dim(), b.dim());
    let mse = a
        .iter()
        .zip(b)
        .map(|(x, y)| (*x as f64 - *y as f64).powi(2))
        .sum::<f64>()
        / a.len() as f64;
    -10.0 * mse.log10()
}

/// Issue 36, item 6: a flow network whose GroupNorm and attention take
/// their statistics over windows of its training crop on the frame's grid
/// gives a frame the same result whatever the tiling (>= 45 dB PSNR between
/// tiles of 4 and 5 windows and one tile: only the convolutions' context at
/// the blended tile borders differs), where the same network normalising
/// each tile whole differs between the same tilings by far more. The frame
/// (230 x 300) is not a whole number of windows (32), so the padding to
/// the grid is exercised too.
#[test]
fn a_windowed_flow_model_does_not_depend_on_the_tiling() {
    let arch = small_sr3();
    let (h, w) = (230, 300);
    let x = scene(h, w);
    let run = |r: &dyn Restore, tile: usize| {
        let opts = ImageOptions {
            tile,
            overlap: 64,
            seed: 3,
            noise: None,
        };
        restore_image(r, x.view(), &opts, &pgrf_core::NoProgress).unwrap()
    };
    assert!(
        restorer(arch.clone(), 1.0).with_window(10).is_err(),
        "10 is not a multiple of the network's 4"
    );
    let windowed = restorer(arch.clone(), 1.0).with_window(32).unwrap();
    assert_eq!((windowed.window(), windowed.side_multiple()), (32, 32));
    let whole_tiles = restorer(arch, 1.0).with_window(0).unwrap();
    let mut worst = (f64::INFINITY, f64::INFINITY);
    let base = (run(&windowed, 1024), run(&whole_tiles, 1024));
    for tile in [128, 160] {
        let a = psnr(&run(&windowed, tile), &base.0);
        let b = psnr(&run(&whole_tiles, tile), &base.1);
        eprintln!("tiles of {tile} against one tile: windowed {a:.1} dB, whole tiles {b:.1} dB");
        worst = (worst.0.min(a), worst.1.min(b));
    }
    assert!(
        worst.0 >= 45.0,
        "windowed: {:.1} dB between tilings",
        worst.0
    );
    assert!(
        worst.1 < worst.0 - 10.0,
        "whole-tile statistics should depend on the tiling: {:.1} dB",
        worst.1
    );
}

/// The tiling's `kernels` is the operations the restoration runs (the
/// configuration, not a process-wide switch): the same seeded SR3 on the
/// same input through burn's operations and through pgrf's gives the same
/// image to float rounding (1e-4) but not bit for bit (they sum in
/// different orders), so the choice did reach the network; and the run
/// leaves this thread's operations as they were.
#[test]
fn the_tilings_kernels_choose_the_operations() {
    use pgrf_nn::infer::{restore_packed, Tiling};
    use pgrf_nn::ops::{kernels, Kernels};
    let r = restorer(small_sr3(), 1.0);
    let input = scene(64, 96);
    let run = |k: Kernels| {
        let tiling = Tiling {
            tile: None,
            overlap: None,
            seed: 3,
            device: pgrf_nn::DeviceKind::Cpu,
            kernels: k,
        };
        restore_packed(&r, input.view(), None, &tiling, &pgrf_core::NoProgress)
            .unwrap()
            .output
    };
    let (p, b) = (run(Kernels::Pgrf), run(Kernels::Burn));
    assert_eq!(kernels(), Kernels::Pgrf);
    let worst = p
        .iter()
        .zip(&b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0f32, f32::max);
    println!("burn against pgrf: largest difference {worst:e}");
    assert!(
        worst > 0.0,
        "the two runs are bit for bit equal: the choice did not reach them"
    );
    assert!(worst < 1e-4, "burn and pgrf differ by {worst}");
}
