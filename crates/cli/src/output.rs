//! Checks on where a command will write, made before any work starts, so a
//! typo in a path costs a second rather than a finished run.

use anyhow::{bail, Result};
use std::path::Path;

/// `p`'s folder must exist (commands write into folders, they do not make them).
pub fn require_parent_dir(p: &Path) -> Result<()> {
    if let Some(dir) = p.parent().filter(|d| !d.as_os_str().is_empty()) {
        if !dir.is_dir() {
            bail!("{}: folder {} does not exist", p.display(), dir.display());
        }
    }
    Ok(())
}

/// Whether `a` and `b` name the same existing file (links and `..`
/// resolved); false when either does not exist.
pub fn same_file(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(x), Ok(y)) => x == y,
        _ => false,
    }
}

/// `p` made absolute with its folder resolved, for comparing outputs that
/// do not exist yet.
fn resolved(p: &Path) -> std::path::PathBuf {
    let dir = p
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    match (dir.canonicalize(), p.file_name()) {
        (Ok(d), Some(name)) => d.join(name),
        _ => p.to_path_buf(),
    }
}

/// Every check on a command's outputs, before any work: each output's
/// folder exists, no output is an existing folder, names one of `inputs`,
/// or is named twice. `outputs` pairs each path with the flag that gave it.
pub fn check_outputs(outputs: &[(&str, &Path)], inputs: &[&Path]) -> Result<()> {
    for (k, (flag, out)) in outputs.iter().enumerate() {
        require_parent_dir(out).map_err(|e| anyhow::anyhow!("{flag} {e}"))?;
        if out.is_dir() {
            bail!("{flag} {} is a folder; give a file name", out.display());
        }
        if let Some(input) = inputs.iter().find(|i| same_file(out, i)) {
            bail!(
                "{flag} {} is the input {}; write the result elsewhere",
                out.display(),
                input.display()
            );
        }
        if let Some((other, _)) = outputs[..k]
            .iter()
            .find(|(_, o)| resolved(o) == resolved(out))
        {
            bail!(
                "{flag} and {other} both name {}; give two different files",
                out.display()
            );
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outputs_may_not_name_inputs_folders_or_each_other() {
        let d = std::env::temp_dir().join(format!("pgrf-output-test-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        let input = d.join("in.dng");
        std::fs::write(&input, b"raw").unwrap();
        let fresh = d.join("out.dng");
        let ok = check_outputs(&[("-o", &fresh), ("--png", &d.join("out.png"))], &[&input]);
        assert!(ok.is_ok(), "{ok:?}");
        // The input itself, also through another spelling of its path.
        let other = d.join(".").join("in.dng");
        let e = check_outputs(&[("-o", &other)], &[&input])
            .unwrap_err()
            .to_string();
        assert!(e.contains("is the input"), "{e}");
        let e = check_outputs(&[("-o", &d)], &[]).unwrap_err().to_string();
        assert!(e.contains("is a folder"), "{e}");
        let e = check_outputs(&[("-o", &fresh), ("--png", &d.join("./out.dng"))], &[])
            .unwrap_err()
            .to_string();
        assert!(e.contains("both name"), "{e}");
        let e = check_outputs(&[("-o", &d.join("no/such/x.dng"))], &[])
            .unwrap_err()
            .to_string();
        assert!(e.contains("does not exist"), "{e}");
        std::fs::remove_dir_all(&d).unwrap();
    }
}
