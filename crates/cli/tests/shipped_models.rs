//! The built-in models and the training configuration type share one
//! description: `models/NAME.toml` is the `pgrf train --config` file each
//! shipped weight file was trained with, and it must describe exactly the
//! network, noise and run the file's own record says.

use pgrf_nn::weights::{read_meta, WeightMeta};
use pgrf_nn::{Method, TrainConfig};
use std::path::PathBuf;

fn models() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../models")
}

/// `models/NAME.toml`, parsed.
fn config(name: &str) -> TrainConfig {
    let text = std::fs::read_to_string(models().join(format!("{name}.toml"))).unwrap();
    TrainConfig::from_toml(&text).unwrap()
}

/// Checks `models/NAME.toml` against `models/NAME.safetensors` and returns
/// the file's record.
fn check(name: &str, method: Method) -> WeightMeta {
    let cfg = config(name);
    let meta = read_meta(&models().join(format!("{name}.safetensors"))).unwrap();
    assert_eq!(meta.arch.method(), method);
    // The architecture the config builds is the file's, field for field.
    let arch = cfg.architecture(method).unwrap();
    assert_eq!(
        serde_json::to_value(&arch).unwrap(),
        serde_json::to_value(&meta.arch).unwrap(),
        "{name}: architecture"
    );
    let noise = &meta.noise;
    assert_eq!(noise.profile.as_deref(), Some(cfg.profile.as_str()));
    assert_eq!(noise.model, cfg.noise);
    assert_eq!(noise.iso, cfg.iso);
    assert_eq!(noise.ratio, [cfg.ratio_min, cfg.ratio_max]);
    let t = meta
        .training
        .as_ref()
        .expect("shipped files record their training");
    assert_eq!(
        (t.steps, t.batch, t.patch, t.seed, t.data.as_str()),
        (cfg.steps, cfg.batch, cfg.patch, cfg.seed, cfg.data.as_str()),
        "{name}: run"
    );
    meta
}

#[test]
fn spc_config_describes_the_shipped_denoiser() {
    let meta = check("spc", Method::Spc);
    // Its second stage started from the first stage's weights, which
    // spc_base.toml trained: same network, its steps behind them.
    let base = config("spc_base");
    assert_eq!(
        serde_json::to_value(base.architecture(Method::Spc).unwrap()).unwrap(),
        serde_json::to_value(&meta.arch).unwrap()
    );
    let from = meta
        .training
        .and_then(|t| t.started_from)
        .expect("a fine-tuned file");
    assert_eq!(
        (from.file.as_str(), from.steps),
        ("spc.safetensors", base.steps)
    );
    assert!(from.seconds > 3600.0, "{}", from.seconds);
}

#[test]
fn pgrf_config_describes_the_shipped_flow_model() {
    check("pgrf", Method::Pgrf);
}

/// The check can fail: a config with another width is not the shipped file.
#[test]
fn a_different_config_is_caught() {
    let text = std::fs::read_to_string(models().join("spc.toml")).unwrap();
    let cfg = TrainConfig::from_toml(&text.replace("width = 16", "width = 8")).unwrap();
    let meta = read_meta(&models().join("spc.safetensors")).unwrap();
    assert_ne!(
        serde_json::to_value(cfg.architecture(Method::Spc).unwrap()).unwrap(),
        serde_json::to_value(&meta.arch).unwrap()
    );
}
