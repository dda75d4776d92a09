//! The built-in models and the training configuration type share one
//! description: `models/NAME.toml` is the `pgrf train --config` file each
//! shipped weight file was trained with, and it must describe exactly the
//! network, noise and run the file's own record says; the stages before it
//! are `models/*.toml` too, with their logs in `models/logs`.

use pgrf_nn::weights::{read_meta, WeightMeta};
use pgrf_nn::{Architecture, Method, TrainConfig};
use serde_json::Value;
use std::path::PathBuf;

/// Seconds of training behind each shipped file's last stage, as its
/// record carries them (the stages' logs sum to the same within a second).
const SPC_SECONDS: f64 = 13_097.8;
const D2_SECONDS: f64 = 29_198.8;
const PGRF_SECONDS: f64 = 36_229.6;

fn models() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../models")
}

/// `models/NAME.toml`, parsed.
fn config(name: &str) -> TrainConfig {
    let text = std::fs::read_to_string(models().join(format!("{name}.toml"))).unwrap();
    TrainConfig::from_toml(&text).unwrap()
}

/// The steps stage `name` ran: the last step of `models/logs/NAME.log.csv`
/// (a stage stopped early ran fewer than its configuration asks).
fn steps_run(name: &str) -> u64 {
    let log = std::fs::read_to_string(models().join(format!("logs/{name}.log.csv"))).unwrap();
    let last = log.lines().last().unwrap();
    last.split(',').next().unwrap().parse().unwrap()
}

/// The network's description without its input planes and convention: a
/// noise-aware stage widens the first layer of the blind network it starts
/// from (`--init`), and a stage may keep the values below black the stages
/// before it clamped; nothing else changes.
fn body(arch: &impl serde::Serialize) -> Value {
    fn strip(v: &mut Value) {
        if let Value::Object(m) = v {
            m.remove("in_channels");
            m.remove("conditioning");
            m.remove("keep_below_black");
            m.values_mut().for_each(strip);
        }
    }
    let mut v = serde_json::to_value(arch).unwrap();
    strip(&mut v);
    v
}

/// The network `cfg` builds (a prior's path is the repository root's, as
/// the run's).
fn architecture(cfg: &TrainConfig, method: Method) -> Architecture {
    let mut at_root = cfg.clone();
    at_root.prior = cfg.prior.as_ref().map(|p| models().join("..").join(p));
    at_root.architecture(method).unwrap()
}

/// A flow that corrects a prior's restoration: its field alone.
fn field(arch: Architecture) -> Architecture {
    match arch {
        Architecture::Sr3Prior(p) => Architecture::Sr3(p.flow),
        a => a,
    }
}

/// Checks `models/NAME.toml` against `models/NAME.safetensors` and returns
/// the file's record.
fn check(name: &str, method: Method) -> WeightMeta {
    let cfg = config(name);
    let meta = read_meta(&models().join(format!("{name}.safetensors"))).unwrap();
    assert_eq!(meta.arch.method(), method);
    // The architecture the config builds is the file's, field for field.
    let arch = architecture(&cfg, method);
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
        (t.batch, t.patch, t.seed, t.data.as_str()),
        (cfg.batch, cfg.patch, cfg.seed, cfg.data.as_str()),
        "{name}: run"
    );
    assert_eq!(t.steps, steps_run(name), "{name}: steps of its log");
    assert!(t.steps <= cfg.steps);
    // The record keeps the whole configuration, which is this file's.
    assert_eq!(
        t.config.as_ref(),
        Some(&cfg),
        "{name}: recorded configuration"
    );
    meta
}

/// A fine-tuned file's earlier stages, `earlier` (config names, oldest
/// first): each builds the shipped network (less its input planes), the
/// last one's output is the file the record says the run started from (also
/// the `init` the shipped config names), and the steps their logs end at sum
/// to the steps the record carries. Returns the seconds behind the starting
/// point.
fn check_stages(name: &str, meta: &WeightMeta, earlier: &[&str], method: Method) -> f64 {
    let from = meta
        .training
        .as_ref()
        .and_then(|t| t.started_from.as_ref())
        .expect("a fine-tuned file");
    // A flow that corrects a prior's restoration has the earlier stages'
    // field inside it (and an earlier stage may have corrected another
    // prior's).
    let shipped = field(meta.arch.clone());
    let mut steps = 0;
    for stage in earlier {
        let cfg = config(stage);
        assert_eq!(
            body(&field(architecture(&cfg, method))),
            body(&shipped),
            "{stage}: architecture"
        );
        let ran = steps_run(stage);
        assert!(ran <= cfg.steps, "{stage}: {ran} steps of {}", cfg.steps);
        steps += ran;
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
    // Issue 51's lever 1: one run from seeded weights (no init, so no
    // earlier stages), 40,000 steps, values below black kept.
    let t = meta.training.as_ref().unwrap();
    assert!(t.started_from.is_none(), "{:?}", t.started_from);
    assert!((t.seconds - SPC_SECONDS).abs() < 1.0, "{}", t.seconds);
    assert!(config("spc").init.is_none());
    assert!(meta.arch.conditioning().needs_level());
    assert!(meta.arch.keeps_below_black());
    assert!(!meta.noise.calibrated_dark_level);
    assert_eq!(t.config.as_ref().unwrap().calibrated_share, 0.3);
}

/// D2, the SPC built in before it (`models/next/spc_d2.safetensors`, the
/// prior of the flow stage `pgrf_on_d2`): its record and its stages are
/// still described by `models/spc_d2.toml`.
#[test]
fn d2_config_describes_the_spc_built_in_before() {
    let name = "spc_d2";
    let cfg = config(name);
    let meta = read_meta(&models().join("next/spc_d2.safetensors")).unwrap();
    assert_eq!(
        meta.training.as_ref().and_then(|t| t.config.as_ref()),
        Some(&cfg)
    );
    assert_eq!(meta.training.as_ref().unwrap().steps, steps_run(name));
    // D2 started from D (8,000 steps, 2,822 s), which started from the SPC
    // built in before it: three noise-aware stages on the blind built-in
    // SPC's three, 20,000 + 9,000 + 6,000 + 5,000 + 6,000 steps, 6,942 +
    // 5,242 + 3,453 + 5,401 + 5,338 s.
    let stages = [
        "spc_base",
        "spc_stage2",
        "spc_blind",
        "spc_noise2",
        "spc_noise3",
        "spc_clamp_log",
    ];
    let seconds = check_stages(name, &meta, &stages, Method::Spc);
    assert!((seconds - D2_SECONDS).abs() < 1.0, "{seconds}");
}

#[test]
fn pgrf_config_describes_the_shipped_flow_model() {
    let meta = check("pgrf", Method::Pgrf);
    // Four blind stages (20,000 + 12,000 + 3,000 + 2,000 steps), the
    // noise-aware ones (1,725 (stopped) + 2,000 + 477 (stopped) + 2,394
    // (stopped) steps), issue 51's lever 5 (6,000 steps: the last one's
    // field correcting D2's restoration), then this stage: that field
    // correcting the built-in SPC's.
    let stages = [
        "pgrf_base",
        "pgrf_stage2",
        "pgrf_stage3",
        "pgrf_blind",
        "pgrf_noise2",
        "pgrf_noise3",
        "pgrf_noise4",
        "pgrf_noise5",
        "pgrf_on_d2",
    ];
    let seconds = check_stages("pgrf", &meta, &stages, Method::Pgrf);
    assert!((seconds - PGRF_SECONDS).abs() < 1.0, "{seconds}");
    let t = meta.training.as_ref().unwrap();
    let cfg = t.config.as_ref().unwrap();
    assert_eq!((cfg.time_max, cfg.window), (0.5, Some(128)));
    assert!(meta.arch.conditioning().needs_level());
    assert!(meta.t2.is_some(), "searched");
    // Its prior is the built-in SPC, byte for byte, whose network it
    // carries.
    let prior = models()
        .join("..")
        .join(cfg.prior.as_ref().expect("a prior"));
    assert_eq!(
        std::fs::read(prior).unwrap(),
        std::fs::read(models().join("spc.safetensors")).unwrap()
    );
    let Architecture::Sr3Prior(p) = &meta.arch else {
        panic!("{:?}", meta.arch)
    };
    let spc = read_meta(&models().join("spc.safetensors")).unwrap().arch;
    assert_eq!(
        serde_json::to_value(Architecture::SidUnet(p.prior.clone())).unwrap(),
        serde_json::to_value(spc).unwrap()
    );
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
    // Nor is a stage list that leaves one out.
    assert_ne!(steps_run("spc_clamp_log"), 0);
}

/// The `models/...` files a text names (`.toml` and `.safetensors`), in
/// order of appearance.
fn model_paths(text: &str) -> Vec<&str> {
    let allowed = |c: char| c.is_ascii_alphanumeric() || "_/.-".contains(c);
    let mut found = Vec::new();
    for (at, _) in text.match_indices("models/") {
        // A path starts here, not inside a longer one (`runs/models/...`).
        if text[..at].chars().next_back().is_some_and(allowed) {
            continue;
        }
        let len = text[at..]
            .find(|c: char| !allowed(c))
            .unwrap_or(text.len() - at);
        let path = text[at..at + len].trim_end_matches('.');
        if path.ends_with(".toml") || path.ends_with(".safetensors") {
            found.push(path);
        }
    }
    found
}

/// The scripts that run the shipped models or their recipes on another
/// machine (bench/gpu.sh on a lent GPU, the measures) name files that
/// exist: a renamed recipe otherwise surfaces only there, minutes of a
/// lent device later (bench/gpu.sh named a moved recipe until the 21st
/// session).
#[test]
fn bench_scripts_name_existing_model_files() {
    let root = models().join("..");
    let mut checked = 0;
    for entry in std::fs::read_dir(root.join("bench")).unwrap() {
        let path = entry.unwrap().path();
        let Some(ext) = path.extension().and_then(|e| e.to_str()) else {
            continue;
        };
        if ext != "sh" && ext != "py" {
            continue;
        }
        let text = std::fs::read_to_string(&path).unwrap();
        for name in model_paths(&text) {
            assert!(
                root.join(name).is_file(),
                "{} names {name}, which does not exist",
                path.display()
            );
            checked += 1;
        }
    }
    // bench/gpu.sh alone names the SPC's recipe and weights.
    assert!(checked >= 3, "only {checked} model paths found in bench/");
    assert_eq!(
        model_paths("a models/spc.toml, runs/models/x.toml `models/next/a.safetensors`."),
        ["models/spc.toml", "models/next/a.safetensors"]
    );
}
