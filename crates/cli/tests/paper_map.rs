//! PAPER.md names, for every equation and algorithm, one function and the
//! file that holds it. This keeps the map true as code moves: each row's
//! function must be defined in its file.

use std::path::PathBuf;

#[test]
fn every_paper_row_names_a_function_defined_in_its_file() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    let text = std::fs::read_to_string(root.join("PAPER.md")).unwrap();
    let mut rows = 0;
    for line in text.lines().filter(|l| l.starts_with('|')) {
        // Cells: paper | what | `function` | `file`.
        let cells: Vec<&str> = line.split(" | ").collect();
        let (Some(func), Some(file)) = (cells.get(cells.len().wrapping_sub(2)), cells.last())
        else {
            continue;
        };
        let (func, file) = (
            func.trim().trim_matches('`'),
            file.trim_end_matches('|').trim(),
        );
        let file = file.trim_matches('`');
        if !file.starts_with("crates/") || !func.contains("::") {
            continue;
        }
        let name = func.rsplit("::").next().unwrap();
        let src = std::fs::read_to_string(root.join(file))
            .unwrap_or_else(|e| panic!("PAPER.md names {file}: {e}"));
        let defined = [
            format!("fn {name}("),
            format!("fn {name}<"),
            format!("struct {name}"),
        ]
        .iter()
        .any(|pat| src.contains(pat.as_str()));
        assert!(defined, "PAPER.md: {func} is not defined in {file}");
        rows += 1;
    }
    // The map covers the noise model, calibration, flow, algorithms and
    // ablations: far more than a handful of rows.
    assert!(rows >= 30, "only {rows} rows read from PAPER.md");
}
