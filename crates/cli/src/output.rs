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
