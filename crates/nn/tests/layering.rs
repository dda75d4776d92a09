//! pgrf-nn's top-level modules form no loop (issue 52): each uses only
//! modules below it, so the networks (`arch`) can be read, tested and
//! reused without the training settings, the data pipeline, the flow or
//! the losses above them. Read from the source: every `crate::MODULE` a
//! module's code names (comments and `#[cfg(test)]` code left out).

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// The code of a source file without its comments and test module.
fn code(text: &str) -> String {
    let text = match text.find("#[cfg(test)]") {
        Some(i) => &text[..i],
        None => text,
    };
    text.lines()
        .filter(|l| !l.trim_start().starts_with("//"))
        .collect::<Vec<_>>()
        .join("\n")
}

/// Each top-level module of `src` and the top-level modules its code uses.
fn uses(src: &Path) -> BTreeMap<String, BTreeSet<String>> {
    let mut deps: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    let mut stack = vec![src.to_path_buf()];
    while let Some(dir) = stack.pop() {
        for e in std::fs::read_dir(&dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
                continue;
            }
            let rel = p.strip_prefix(src).unwrap().to_string_lossy().into_owned();
            if !rel.ends_with(".rs") || rel == "lib.rs" || rel.ends_with("tests.rs") {
                continue;
            }
            let top = rel
                .split('/')
                .next()
                .unwrap()
                .trim_end_matches(".rs")
                .to_string();
            let text = code(&std::fs::read_to_string(&p).unwrap());
            let set = deps.entry(top.clone()).or_default();
            for part in text.split("crate::").skip(1) {
                let name: String = part
                    .chars()
                    .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                    .collect();
                if !name.is_empty() && name != top {
                    set.insert(name);
                }
            }
        }
    }
    deps
}

/// A module reachable from itself, with the path that closes the loop.
fn a_loop(deps: &BTreeMap<String, BTreeSet<String>>) -> Option<Vec<String>> {
    for start in deps.keys() {
        let mut stack = vec![vec![start.clone()]];
        let mut seen = BTreeSet::new();
        while let Some(path) = stack.pop() {
            let last = path.last().unwrap();
            for next in deps.get(last).into_iter().flatten() {
                if next == start {
                    let mut p = path.clone();
                    p.push(next.clone());
                    return Some(p);
                }
                if seen.insert(next.clone()) {
                    let mut p = path.clone();
                    p.push(next.clone());
                    stack.push(p);
                }
            }
        }
    }
    None
}

#[test]
fn the_modules_form_no_loop_and_the_networks_use_none_above_them() {
    let deps = uses(&Path::new(env!("CARGO_MANIFEST_DIR")).join("src"));
    assert!(deps.len() > 10, "read {} modules", deps.len());
    if let Some(l) = a_loop(&deps) {
        panic!("modules in a loop: {}", l.join(" -> "));
    }
    let arch = &deps["arch"];
    for above in [
        "config", "data", "flow", "loss", "step", "apply", "train", "infer", "interop",
    ] {
        assert!(!arch.contains(above), "arch uses {above}: {arch:?}");
    }
}

/// The check itself finds a loop when there is one.
#[test]
fn a_loop_is_found() {
    let mut deps: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    deps.entry("a".into()).or_default().insert("b".into());
    deps.entry("b".into()).or_default().insert("c".into());
    deps.entry("c".into()).or_default().insert("a".into());
    assert_eq!(a_loop(&deps).map(|p| p.len()), Some(4));
    deps.get_mut("c").unwrap().clear();
    assert_eq!(a_loop(&deps), None);
}
