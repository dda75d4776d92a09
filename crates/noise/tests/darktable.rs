//! `--profile darktable:"MAKER MODEL"`: a camera of darktable's
//! noiseprofiles.json as a Poisson-Gaussian profile. The fixture is in
//! darktable's exact format (format version 0, makers with models with
//! profiles, `comment`s, a `"skip": true` entry, ISOs out of order). pgrf's
//! photosite variance is 12.9 (a x + b) of darktable's green channel,
//! interpolated linearly in ISO as darktable does, stated on a nominal
//! 14-bit scale (white - black = 16383 DN).

use ndarray::Array3;
use pgrf_noise::darktable::{self, NoiseProfiles};
use pgrf_noise::pair::{PairSpec, RatioSpec};
use pgrf_noise::{CameraProfile, ModelKind};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

const FIXTURE: &str = r#"{
  "version": 0,
  "noiseprofiles": [
    {
      "maker": "Testmaker",
      "models": [
        {
          "comment": "three ISOs, listed out of order, and two skipped entries",
          "model": "TM-1",
          "profiles": [
            {"name": "TM-1 iso 400", "iso": 400, "a": [3.0e-05, 2.0e-05, 2.5e-05], "b": [1.0e-07, 2.0e-07, 1.5e-07]},
            {"name": "TM-1 iso 100", "iso": 100, "a": [8.0e-06, 5.0e-06, 6.0e-06], "b": [4.0e-08, 5.0e-08, 6.0e-08]},
            {"name": "TM-1 iso 1600", "iso": 1600, "a": [1.2e-04, 8.0e-05, 1.0e-04], "b": [5.0e-07, 6.0e-07, 7.0e-07]},
            {"skip": true, "name": "TM-1 iso 400", "iso": 400, "a": [1.0e-03, 1.0e-03, 1.0e-03], "b": [1.0e-05, 1.0e-05, 1.0e-05]},
            {"skip": true, "name": "TM-1 iso 6400", "iso": 6400, "a": [4.0e-04, 3.0e-04, 3.5e-04], "b": [2.0e-06, 2.0e-06, 2.0e-06]}
          ]
        },
        {
          "comment": "a second model of the same maker",
          "model": "TM-2",
          "profiles": [
            {"name": "TM-2 iso 200", "iso": 200, "a": [1.0e-05, 1.0e-05, 1.0e-05], "b": [1.0e-07, 1.0e-07, 1.0e-07]},
            {"name": "TM-2 iso 800", "iso": 800, "a": [4.0e-05, 4.0e-05, 4.0e-05], "b": [3.0e-07, 3.0e-07, 3.0e-07]}
          ]
        }
      ]
    },
    {
      "maker": "Othermaker",
      "models": [
        {
          "comment": "ISO 200 measured twice, a negative green b and a negative blue a, as darktable's own file has",
          "model": "OM 5",
          "profiles": [
            {"name": "OM 5 iso 200", "iso": 200, "a": [2.0e-05, 1.0e-05, -3.0e-06], "b": [1.0e-07, -4.0e-07, 2.0e-06]},
            {"name": "OM 5 iso 200", "iso": 200, "a": [2.0e-05, 3.0e-05, -3.0e-06], "b": [1.0e-07, -2.0e-07, 2.0e-06]},
            {"name": "OM 5 iso 400", "iso": 400, "a": [4.0e-05, 4.0e-05, 0.0], "b": [1.0e-07, 1.0e-07, 0.0]}
          ]
        }
      ]
    }
  ]
}
"#;

/// The fixture, written once per test process; every test that loads
/// through `CameraProfile::load` names it.
fn fixture() -> &'static Path {
    static PATH: OnceLock<PathBuf> = OnceLock::new();
    let p = PATH.get_or_init(|| {
        let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("pgrf-darktable");
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("noiseprofiles.json");
        std::fs::write(&p, FIXTURE).unwrap();
        p
    });
    p
}

fn load(camera: &str) -> CameraProfile {
    CameraProfile::load(&format!("darktable:{camera}"), Some(fixture())).unwrap()
}

fn close(got: f64, want: f64, rel: f64) -> bool {
    (got - want).abs() <= rel * want.abs()
}

/// At a measured ISO, K = 12.9 a 16383 and sigma = sqrt(12.9 b) 16383 from
/// the green entry that is not skipped; between measured ISOs a and b are
/// linear in ISO (darktable's rule, not pgrf's log-ISO one); outside them
/// the ISO is refused, the skipped ISO 6400 included.
#[test]
fn green_numbers_convert_at_measured_and_interpolated_isos() {
    let p = load("Testmaker TM-1");
    // ISO 400: a 2e-5, b 2e-7 (the skipped entry's 1e-3 is ignored).
    let c = p.params_at_iso(400).unwrap();
    assert!(close(c.k, 4.226814, 1e-9), "K {}", c.k);
    assert!(
        close(c.sigma_gauss, 26.314995, 1e-7),
        "sigma {}",
        c.sigma_gauss
    );
    // ISO 100, listed second in the file.
    let c = p.params_at_iso(100).unwrap();
    assert!(close(c.k, 1.0567035, 1e-9) && close(c.sigma_gauss, 13.157497, 1e-7));
    // ISO 1000, halfway in ISO between 400 and 1600: a 5e-5, b 4e-7. (pgrf's
    // own log-ISO rule would give a = 2e-5 + 0.661 x 6e-5 = 5.97e-5.)
    let c = p.params_at_iso(1000).unwrap();
    assert!(close(c.k, 10.567035, 1e-5), "K {}", c.k);
    assert!(
        close(c.sigma_gauss, 37.215022, 1e-5),
        "sigma {}",
        c.sigma_gauss
    );
    // ISO 1301: t = 901 / 1200, a = 2e-5 + t 6e-5.
    let t = 901.0 / 1200.0;
    let k = 12.9 * (2e-5 + t * 6e-5) * 16383.0;
    assert!(close(p.params_at_iso(1301).unwrap().k, k, 1e-5));
    for iso in [50, 6400] {
        let e = p.params_at_iso(iso).unwrap_err().to_string();
        assert!(e.contains("100..=1600"), "{e}");
    }
    let v = pgrf_noise::pg_profile::view(&p);
    assert_eq!(v.dn_range, 16383.0);
    assert_eq!(v.black, None);
    assert!(close(v.k_range.0, 1.0567035, 1e-9) && close(v.k_range.1, 16.907256, 1e-9));
    for says in [
        "noiseprofiles.json",
        "format version 0",
        "Testmaker TM-1",
        "measured at ISO 100, 400, 1600",
        "no row noise, no fixed pattern, no heavy-tailed (Tukey) read noise",
    ] {
        assert!(v.source.contains(says), "{says}: {}", v.source);
    }
    assert_eq!(v.name, "darktable:Testmaker TM-1");
}

/// Case, repeated spaces and a leftover pair of quotes do not matter.
#[test]
fn cameras_are_found_by_maker_and_model_in_any_case() {
    let want = load("Testmaker TM-1").params_at_iso(400).unwrap();
    for name in ["testmaker   tm-1", "\"TESTMAKER TM-1\"", " Testmaker TM-1 "] {
        assert_eq!(load(name).params_at_iso(400).unwrap(), want, "{name}");
    }
    assert!(close(
        load("Testmaker TM-2").params_at_iso(800).unwrap().k,
        12.9 * 4e-5 * 16383.0,
        1e-9
    ));
}

/// Synthesised with the Poisson-Gaussian model on flat frames at three
/// levels (ratio 1) at an interpolated ISO, the sample variance is
/// 12.9 (a x + b) of the file's green numbers at that ISO, within 3
/// standard errors (var sqrt(2 / (n - 1))). The ELD and pgrf models give
/// the same plus their 1-DN quantisation step's 1/12 DN^2: their
/// near-Gaussian read noise has the same standard deviation.
#[test]
fn synthesised_frames_have_the_variance_the_file_states() {
    let p = load("Testmaker TM-1");
    let (a, b) = (5e-5, 4e-7); // green at ISO 1000
    for (m, kind) in [ModelKind::PoissonGaussian, ModelKind::Eld, ModelKind::Pgrf]
        .into_iter()
        .enumerate()
    {
        let mut spec = PairSpec::new(p.clone(), kind);
        spec.iso = Some(1000);
        spec.ratio = RatioSpec::Fixed(1.0);
        let quant = if kind == ModelKind::PoissonGaussian {
            0.0
        } else {
            1.0 / 12.0 / 16383f64.powi(2)
        };
        for (i, x) in [0.05f32, 0.2, 0.5].into_iter().enumerate() {
            let clean = Array3::from_elem((4, 96, 96), x);
            let pair = spec
                .synthesize(clean.view(), [0, 0, 1, 1], 70 + 10 * m as u64 + i as u64)
                .unwrap();
            let v: Vec<f64> = pair.noisy.iter().map(|&v| v as f64).collect();
            let n = v.len() as f64;
            let mean = v.iter().sum::<f64>() / n;
            let var = v.iter().map(|s| (s - mean).powi(2)).sum::<f64>() / (n - 1.0);
            let want = 12.9 * (a * x as f64 + b) + quant;
            let se = want * (2.0 / (n - 1.0)).sqrt();
            assert!(
                (var - want).abs() < 3.0 * se,
                "{kind:?} x {x}: variance {var:.5e}, the file says {want:.5e} (3 SE {:.1e})",
                3.0 * se
            );
        }
    }
}

/// What darktable's own file holds: a green b < 0 (the fit resolved no read
/// noise: 0 is used, and the source says so), a negative blue a (ignored:
/// only green is used), an ISO measured twice (averaged).
#[test]
fn real_file_quirks_are_taken_as_darktable_takes_them() {
    let p = load("Othermaker OM 5");
    let c = p.params_at_iso(200).unwrap();
    // a = (1e-5 + 3e-5) / 2, b = (-4e-7 - 2e-7) / 2 < 0.
    assert!(close(c.k, 4.226814, 1e-9), "K {}", c.k);
    assert_eq!(c.sigma_gauss, 0.0);
    // Halfway to ISO 400 b is still < 0 (-3e-7 + 0.5 x 4e-7 = -1e-7).
    assert_eq!(p.params_at_iso(300).unwrap().sigma_gauss, 0.0);
    let c = p.params_at_iso(400).unwrap();
    assert!(close(
        c.sigma_gauss,
        (12.9f64 * 1e-7).sqrt() * 16383.0,
        1e-9
    ));
    let src = pgrf_noise::pg_profile::view(&p).source;
    assert!(
        src.contains("b < 0 at ISO 200") && src.contains("ISO 200 (2x)"),
        "{src}"
    );
    let db = NoiseProfiles::read(fixture()).unwrap();
    let m = db.find("othermaker om 5").unwrap().measured();
    assert_eq!((m[0].iso, m[0].entries), (200, 2));
    assert_eq!(db.cameras.len(), 3);
    assert_eq!(db.find("Testmaker TM-1").unwrap().isos(), [100, 400, 1600]);
}

/// Each refusal is one line naming what is wrong.
#[test]
fn bad_files_and_names_are_refused_in_one_line() {
    let one_line = |e: String, says: &[&str]| {
        assert!(!e.contains('\n'), "{e}");
        for s in says {
            assert!(e.contains(s), "{s}: {e}");
        }
    };
    // An unknown camera: the three closest names.
    let e = CameraProfile::load("darktable:Testmaker TM-3", Some(fixture()))
        .unwrap_err()
        .to_string();
    one_line(
        e,
        &[
            "no such camera",
            "closest: \"Testmaker TM-1\", \"Testmaker TM-2\", \"Othermaker OM 5\"",
        ],
    );
    // No file where it was named, and none in the places searched.
    let missing = Path::new("/nonexistent/pgrf/noiseprofiles.json");
    let e = NoiseProfiles::read(missing).unwrap_err().to_string();
    one_line(e, &["/nonexistent/pgrf/noiseprofiles.json"]);
    let places = [
        PathBuf::from("/nonexistent/a/noiseprofiles.json"),
        PathBuf::from("/nonexistent/b/noiseprofiles.json"),
    ];
    let e = darktable::locate_in(&places).unwrap_err().to_string();
    one_line(
        e,
        &[
            "/nonexistent/a/noiseprofiles.json, /nonexistent/b/noiseprofiles.json",
            "--darktable-profiles",
        ],
    );
    // Damaged files: the entry is named.
    let parse = |text: String| {
        NoiseProfiles::parse(&text, Path::new("np.json"))
            .and_then(|db| db.profile("Testmaker TM-1"))
            .unwrap_err()
            .to_string()
    };
    let short_a = FIXTURE.replacen(
        "\"a\": [8.0e-06, 5.0e-06, 6.0e-06]",
        "\"a\": [8.0e-06, 5.0e-06]",
        1,
    );
    one_line(
        parse(short_a),
        &[
            "np.json",
            "Testmaker TM-1, entry 2 of 5 (\"TM-1 iso 100\")",
            "`a` has 2 values",
        ],
    );
    let no_iso = FIXTURE.replacen("\"iso\": 800, ", "", 1);
    one_line(
        parse(no_iso),
        &[
            "Testmaker TM-2, entry 2 of 2 (\"TM-2 iso 800\")",
            "missing `iso`",
        ],
    );
    let text_b = FIXTURE.replacen(
        "[4.0e-08, 5.0e-08, 6.0e-08]",
        "[4.0e-08, \"x\", 6.0e-08]",
        1,
    );
    one_line(parse(text_b), &["TM-1 iso 100", "`b[1]` is not a number"]);
    // JSON has no NaN: such a file is not JSON.
    let nan = FIXTURE.replacen("5.0e-08, 6.0e-08", "NaN, 6.0e-08", 1);
    one_line(parse(nan), &["np.json", "invalid JSON", "line 12"]);
    // A negative green slope, which darktable's own tool refuses.
    let neg = FIXTURE.replacen("2.0e-05, 2.5e-05", "-2.0e-05, 2.5e-05", 1);
    one_line(
        parse(neg),
        &[
            "darktable:Testmaker TM-1",
            "green a = -0.00002 at ISO 400",
            "a > 0",
        ],
    );
    let v1 = FIXTURE.replacen("\"version\": 0", "\"version\": 1", 1);
    one_line(parse(v1), &["format version 1", "version 0"]);
    let skipped = FIXTURE.replace("{\"name\": \"TM-2", "{\"skip\": true, \"name\": \"TM-2");
    let e = NoiseProfiles::parse(&skipped, Path::new("np.json"))
        .and_then(|db| db.profile("Testmaker TM-2"))
        .unwrap_err()
        .to_string();
    one_line(e, &["marked \"skip\""]);
}

fn export(maker: &str, model: &str, iso: u32, s: f64, o: f64) -> darktable::Export {
    darktable::Export {
        maker: maker.into(),
        model: model.into(),
        iso,
        s,
        o,
        comment: "a test calibration".into(),
    }
}

/// What `pgrf calibrate` exports is darktable's format and reads back as the
/// noise it states: a = S / 12.9 and b = O / 12.9 for red, green and blue,
/// and `--profile darktable:` of that file gives S and O again (K = S 16383,
/// sigma = sqrt(O) 16383 on the nominal scale).
#[test]
fn an_exported_entry_reads_back_as_the_calibrated_noise() {
    let (s, o) = (9.678370e-5, 1.818743e-7);
    let text = export("Sony", "ILCE-7SM2", 1600, s, o).file().unwrap();
    let path = Path::new("exported.json");
    let file = NoiseProfiles::parse(&text, path).unwrap();
    assert_eq!(file.version, 0);
    assert_eq!(file.cameras.len(), 1);
    let cam = file.find("Sony ILCE-7SM2").unwrap();
    assert_eq!(cam.comment.as_deref(), Some("a test calibration"));
    let e = &cam.entries[0];
    assert_eq!(
        (e.name.as_str(), e.iso, e.skip),
        ("Sony ILCE-7SM2 iso 1600", 1600, false)
    );
    for ch in 0..3 {
        assert!(close(e.a[ch], s / 12.9, 1e-15) && close(e.b[ch], o / 12.9, 1e-15));
    }
    let p = file
        .profile("Sony ILCE-7SM2")
        .unwrap()
        .params_at_iso(1600)
        .unwrap();
    assert!(close(p.k, s * 16383.0, 1e-12), "K {}", p.k);
    assert!(
        close(p.sigma_gauss, o.sqrt() * 16383.0, 1e-12),
        "sigma {}",
        p.sigma_gauss
    );
    // darktable's keys and nothing else, as its own tool writes them.
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    let entry = &v["noiseprofiles"][0]["models"][0]["profiles"][0];
    let mut keys: Vec<&str> = entry
        .as_object()
        .unwrap()
        .keys()
        .map(|k| k.as_str())
        .collect();
    keys.sort_unstable();
    assert_eq!(keys, ["a", "b", "iso", "name"]);
}

/// Merging into a darktable file keeps every other camera and entry, adds
/// the maker and model where missing, keeps the entries sorted by ISO and
/// replaces the camera's entries at the same ISO (skipped ones too).
#[test]
fn merging_keeps_the_file_and_replaces_the_same_iso() {
    let path = Path::new("noiseprofiles.json");
    let before = NoiseProfiles::parse(FIXTURE, path).unwrap();
    // A new ISO of a camera the file has: inserted between 100 and 1600.
    let (text, replaced) = export("Testmaker", "TM-1", 800, 4e-4, 2e-6)
        .merge_into(Some(FIXTURE), path)
        .unwrap();
    assert_eq!(replaced, 0);
    let after = NoiseProfiles::parse(&text, path).unwrap();
    assert_eq!(after.cameras.len(), before.cameras.len());
    let tm1 = after.find("Testmaker TM-1").unwrap();
    assert_eq!(tm1.entries.len(), 6);
    assert_eq!(tm1.isos(), [100, 400, 800, 1600]);
    assert_eq!(
        after.find("Othermaker OM 5").unwrap(),
        before.find("Othermaker OM 5").unwrap()
    );
    assert_eq!(
        after.find("Testmaker TM-2").unwrap(),
        before.find("Testmaker TM-2").unwrap()
    );
    // ISO 400 again: the entry and the skipped one at 400 both go.
    let (text, replaced) = export("Testmaker", "TM-1", 400, 1e-4, 1e-6)
        .merge_into(Some(&text), path)
        .unwrap();
    assert_eq!(replaced, 2);
    let tm1 = NoiseProfiles::parse(&text, path).unwrap();
    let tm1 = tm1.find("Testmaker TM-1").unwrap();
    let at400: Vec<_> = tm1.entries.iter().filter(|e| e.iso == 400).collect();
    assert_eq!(at400.len(), 1);
    assert!(close(at400[0].a[1], 1e-4 / 12.9, 1e-15));
    // A camera the file lacks, under a maker it has and one it lacks.
    let (text, _) = export("Testmaker", "TM-9", 100, 1e-5, 0.0)
        .merge_into(Some(FIXTURE), path)
        .unwrap();
    let (text, _) = export("Newmaker", "NM 1", 3200, 2e-4, 1e-6)
        .merge_into(Some(&text), path)
        .unwrap();
    let f = NoiseProfiles::parse(&text, path).unwrap();
    assert_eq!(f.cameras.len(), before.cameras.len() + 2);
    assert_eq!(f.find("Testmaker TM-9").unwrap().maker, "Testmaker");
    assert_eq!(f.find("Newmaker NM 1").unwrap().isos(), [3200]);
}

/// Numbers darktable cannot use, a camera without a name, no ISO and a
/// file darktable would refuse: one line each, nothing produced.
#[test]
fn exports_darktable_cannot_use_are_refused() {
    let path = Path::new("noiseprofiles.json");
    for (e, says) in [
        (export("Sony", "ILCE-7SM2", 1600, 0.0, 1e-7), "S > 0"),
        (export("Sony", "ILCE-7SM2", 1600, f64::NAN, 1e-7), "S > 0"),
        (export("Sony", "ILCE-7SM2", 1600, 1e-4, -1e-9), "O >= 0"),
        (export("Sony", "  ", 1600, 1e-4, 1e-7), "name no camera"),
        (export("Sony", "ILCE-7SM2", 0, 1e-4, 1e-7), "no ISO"),
    ] {
        let err = e.file().unwrap_err().to_string();
        assert!(err.contains(says) && !err.contains('\n'), "{says}: {err}");
    }
    let broken = r#"{"version": 0, "noiseprofiles": [{"maker": "x"}]}"#;
    let err = export("Sony", "ILCE-7SM2", 1600, 1e-4, 1e-7)
        .merge_into(Some(broken), path)
        .unwrap_err()
        .to_string();
    assert!(err.contains("`models` is missing"), "{err}");
}
