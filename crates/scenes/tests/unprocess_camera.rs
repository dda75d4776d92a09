//! Unprocessing into a real camera's space: the Canon 550D DNG's own colour
//! matrix, white balance, CFA phase and levels.

mod common;

use pgrf_raw::{decode_file, render_preview, LevelOverrides, PreviewOptions};
use pgrf_scenes::photo::Photo;
use pgrf_scenes::unprocess::{unprocess, CameraSpace};

#[test]
#[cfg_attr(not(shared_data), ignore = "needs ../shared/data")]
fn a_photo_unprocessed_into_the_550d_previews_as_itself() {
    let data = common::data_dir();
    let cam = decode_file(
        &data.join("raw/canon550d_colorchart.dng"),
        &LevelOverrides::default(),
    )
    .unwrap();
    let space = CameraSpace::of(&cam).unwrap();
    assert_eq!(space.cfa, cam.cfa);
    let (w, h) = (80, 60);
    let mut rgb = Vec::with_capacity(w * h * 3);
    for r in 0..h {
        for c in 0..w {
            let (fc, fr) = (c as f32, r as f32);
            rgb.push(0.35 + 0.25 * (fc / 11.0).sin() * (fr / 17.0).cos());
            rgb.push(0.40 + 0.20 * (fr / 9.0).sin());
            rgb.push(0.30 + 0.20 * ((fc + fr) / 13.0).cos());
        }
    }
    let photo = Photo {
        width: w,
        height: h,
        rgb,
    };
    let frame = unprocess(&photo, &space, 1.0).unwrap();
    assert_eq!(
        (frame.cfa, frame.white, frame.black),
        (cam.cfa, cam.white, cam.black)
    );
    let back = render_preview(&frame, &PreviewOptions::default()).unwrap();
    let (mut se, mut n) = (0.0f64, 0usize);
    for r in 4..h - 4 {
        for c in 4..w - 4 {
            for k in 0..3 {
                let i = (r * w + c) * 3 + k;
                se += ((back.rgb[i] - photo.rgb[i]) as f64).powi(2);
                n += 1;
            }
        }
    }
    let psnr = 10.0 * (n as f64 / se).log10();
    assert!(psnr > 40.0, "{psnr:.2} dB");
}
