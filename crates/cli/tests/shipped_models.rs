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
    assert_eq!(noise.calibrated_dark_level, cfg.calibrated_dark_level);
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

/// A fine-tuned file's earlier stages, `earlier` (config names, oldest
/// first): each builds the shipped network, the last one's output is the
/// file the record says the run started from (also the `init` the shipped
/// config names), and their steps sum to the steps the record carries.
/// Returns the seconds behind the starting point.
fn check_stages(name: &str, meta: &WeightMeta, earlier: &[&str], method: Method) -> f64 {
    let from = meta
        .training
        .as_ref()
        .and_then(|t| t.started_from.as_ref())
        .expect("a fine-tuned file");
    let mut steps = 0;
    for stage in earlier {
        let cfg = config(stage);
        assert_eq!(
            serde_json::to_value(cfg.architecture(method).unwrap()).unwrap(),
            serde_json::to_value(&meta.arch).unwrap(),
            "{stage}: architecture"
        );
        steps += cfg.steps;
    }
    let init = config(name)
        .init
        .expect("a fine-tuning config names its init");
    assert_eq!(
        init.file_name().and_then(|n| n.to_str()),
        Some(from.file.as_str())
    );
    assert_eq!(from.steps, steps, "{name}: steps before this stage");
    from.seconds
}

#[test]
fn spc_config_describes_the_shipped_denoiser() {
    let meta = check("spc", Method::Spc);
    // Its third stage started from the second stage's output, which started
    // from the first's: 20,000 + 9,000 steps, 6,942 + 5,242 s.
    let seconds = check_stages("spc", &meta, &["spc_base", "spc_stage2"], Method::Spc);
    assert!((seconds - 12_184.0).abs() < 1.0, "{seconds}");
    assert!(meta.noise.calibrated_dark_level);
}

#[test]
fn pgrf_config_describes_the_shipped_flow_model() {
    let meta = check("pgrf", Method::Pgrf);
    // Its fourth stage started from the third stage's output, each stage
    // from the one before: 20,000 + 12,000 + 3,000 steps, 5,664 + 3,610 +
    // 3,622 s; it drew its training times from U(0, 0.5).
    let stages = ["pgrf_base", "pgrf_stage2", "pgrf_stage3"];
    let seconds = check_stages("pgrf", &meta, &stages, Method::Pgrf);
    assert!((seconds - 12_896.0).abs() < 1.0, "{seconds}");
    let t = meta.training.as_ref().unwrap();
    assert_eq!(t.config.as_ref().unwrap().time_max, 0.5);
    assert!(meta.noise.calibrated_dark_level);
    assert!(meta.t2.is_some(), "searched");
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
