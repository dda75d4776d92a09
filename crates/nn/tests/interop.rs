//! PyTorch checkpoints of the SID U-Net in, pgrf's networks out, against
//! numbers PyTorch computed: `tests/reference/sid_unet_torch.py write`
//! built `UNetSeeInDark` at width 2 (seeded), saved it in each checkpoint
//! shape the field uses and ran it on a fixed packed input; the files are
//! in `tests/data/sid_unet/`. No Python runs here.

use burn::tensor::{Tensor, TensorData};
use pgrf_nn::backend::Cpu;
use pgrf_nn::interop::{self, Source};
use pgrf_nn::weights;
use pgrf_nn::Net;
use pgrf_nn::{model, Architecture};
use std::path::{Path, PathBuf};

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/sid_unet")
        .join(name)
}

fn f32s(name: &str) -> Vec<f32> {
    std::fs::read(data(name))
        .unwrap()
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
        .collect()
}

/// pgrf's SID U-Net with the imported weights on the reference input; the
/// largest difference from PyTorch's output.
fn max_diff_from_pytorch(bytes: &[u8], scratch: &Path) -> f32 {
    let device = Default::default();
    std::fs::write(scratch, bytes).unwrap();
    let (net, meta) = model::load::<Cpu>(scratch, &device).unwrap();
    assert!(matches!(meta.arch, Architecture::SidUnet(_)));
    let Net::Spc(net) = net else {
        panic!("not a SID U-Net")
    };
    let input =
        Tensor::<Cpu, 4>::from_data(TensorData::new(f32s("input.f32"), [1, 4, 32, 48]), &device);
    let out: Vec<f32> = net.forward(input).into_data().to_vec().unwrap();
    let want = f32s("output.f32");
    assert_eq!(out.len(), want.len());
    out.iter()
        .zip(&want)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f32::max)
}

/// Every checkpoint shape the published repositories use imports to the
/// same network, which reproduces PyTorch's output to 1e-5.
#[test]
fn every_checkpoint_shape_imports_and_matches_pytorch() {
    let scratch =
        std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("pgrf-interop.safetensors");
    let mut first = None;
    for (file, nesting) in [
        ("plain.pth", ""),
        ("nested_state_dict.pth", "state_dict."),
        ("nested_netG.pth", "netG."),
        ("nested_model.pth", "model."),
        ("module_prefix.pth", "module."),
        ("plain.safetensors", ""),
        ("eld_legacy.pth", "netG."),
        ("led_params.pth", "params."),
    ] {
        let imported = interop::import_sid(&data(file), Some(Source::Pmn), None)
            .unwrap_or_else(|e| panic!("{file}: {e}"));
        let from = imported.meta.imported.as_ref().unwrap();
        assert_eq!(from.nesting, nesting, "{file}");
        assert_eq!(from.repository.as_deref(), Some("pmn"));
        // The tensors are the same whatever the container.
        match &first {
            None => first = Some(imported.tensors.clone()),
            Some(f) => assert!(
                f == &imported.tensors,
                "{file}: other tensors than plain.pth"
            ),
        }
        let d = max_diff_from_pytorch(&imported.encode().unwrap(), &scratch);
        assert!(d < 1e-5, "{file}: max |pgrf - PyTorch| = {d}");
        eprintln!("{file}: max |pgrf - PyTorch| = {d:.2e}");
    }
    // LED's file holds the network twice: 'params' by default, the other by --key.
    let led = interop::import_sid(
        &data("led_params.pth"),
        Some(Source::Led),
        Some("params_ema"),
    )
    .unwrap();
    let from = led.meta.imported.unwrap();
    assert_eq!(
        (from.nesting.as_str(), from.also_under.len()),
        ("params_ema.", 0)
    );
    let dflt = interop::import_sid(&data("led_params.pth"), None, None).unwrap();
    assert_eq!(dflt.meta.imported.unwrap().also_under, ["params_ema"]);
    let e = interop::import_sid(&data("led_params.pth"), None, Some("netG"))
        .err()
        .unwrap();
    assert!(
        e.to_string()
            .contains("found under: 'params', 'params_ema'"),
        "{e}"
    );
    let _ = std::fs::remove_file(&scratch);
}

/// The full-width network's names and shapes, as PyTorch lists them.
#[test]
fn the_full_width_table_is_pytorchs() {
    let text = std::fs::read_to_string(data("full_width_shapes.json")).unwrap();
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    let list = v["state_dict"].as_array().unwrap();
    let ours = interop::sid_names::torch_shapes(32, 4, 4);
    assert_eq!(list.len(), ours.len());
    for (entry, (name, shape)) in list.iter().zip(&ours) {
        assert_eq!(entry[0].as_str().unwrap(), name);
        let s: Vec<usize> = entry[1]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_u64().unwrap() as usize)
            .collect();
        assert_eq!(&s, shape, "{name}");
    }
    assert_eq!(v["total_params"].as_u64(), Some(7_760_484));
}

/// Each bad file: one line naming what is wrong.
#[test]
fn bad_checkpoints_are_refused_with_the_reason() {
    for (file, says) in [
        ("other_arch.pth", "no conv1_1.weight"),
        ("truncated.pth", "truncated.pth"),
        ("malicious.pth", "os.system"),
        ("missing_key.pth", "conv10_1.bias is missing"),
        ("non_tensor.pth", "conv10_1.bias"),
        (
            "shape_mismatch.pth",
            "conv1_1.weight has shape [2, 4, 3, 4]",
        ),
    ] {
        let e = match interop::import_sid(&data(file), None, None) {
            Ok(_) => panic!("{file} was accepted"),
            Err(e) => e.to_string(),
        };
        assert!(e.contains(says), "{file}: {e}");
        assert!(!e.contains('\n'), "{file}: not one line: {e}");
        eprintln!("{file}: {e}");
    }
}

/// The blind SPC built in until 2026-11-27 (residual, width 16;
/// `tests/data/sid_unet/blind_spc.safetensors`, the `models/spc.safetensors`
/// of commit 0c462fb, kept as this fixture's weights) exported as `.pth`: PyTorch
/// loads it strictly into UNetSeeInDark and, adding the input as the
/// residual network does, computes `spc_torch_output.f32` on the reference
/// input (`sid_unet_torch.py check spc.pth input.f32 --residual --save`);
/// pgrf's own forward must agree to 1e-5. Re-importing the export gives
/// the same tensors, and exporting those again the same bytes. When
/// weights change, regenerate the fixture that way.
#[test]
fn a_trained_spc_exports_to_what_pytorch_computes() {
    let model = data("blind_spc.safetensors");
    let (meta, tensors) = weights::read(&model).unwrap();
    let device = Default::default();
    let (net, _) = model::load::<Cpu>(&model, &device).unwrap();
    let Net::Spc(net) = net else {
        panic!("not a SID U-Net")
    };
    let input =
        Tensor::<Cpu, 4>::from_data(TensorData::new(f32s("input.f32"), [1, 4, 32, 48]), &device);
    let out: Vec<f32> = net.forward(input).into_data().to_vec().unwrap();
    let torch = f32s("spc_torch_output.f32");
    let d = out
        .iter()
        .zip(&torch)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    assert!(
        d < 1e-5,
        "max |pgrf - PyTorch| = {d} (blind_spc.safetensors changed? regenerate spc_torch_output.f32)"
    );
    eprintln!("blind SPC: max |pgrf - PyTorch| = {d:.2e}");

    let pth = interop::export(&meta, &tensors, true).unwrap();
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("pgrf-export");
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("spc.pth");
    std::fs::write(&file, &pth.bytes).unwrap();
    let back = interop::import_sid(&file, None, None).unwrap();
    assert_eq!(back.tensors, tensors);
    let mut meta2 = back.meta.clone();
    meta2.arch = meta.arch.clone();
    let again = interop::export(&meta2, &back.tensors, true).unwrap();
    assert!(
        again.bytes == pth.bytes,
        "export -> import -> export changed the bytes"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
