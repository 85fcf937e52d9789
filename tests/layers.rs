//! The layer order of docs/design.md, read from the `crate::` paths of the library's non-test
//! code: a module uses only modules of lower layers, with no exceptions.

use std::path::{Path, PathBuf};

/// The library's top-level modules by layer, lowest first. Modules of one layer do not use each
/// other. Layer 0 is usable from every layer.
const LAYERS: &[&[&str]] = &[
    &["units", "seed", "stats", "types", "spreadsheet", "outfile"],
    &["special"],
    &["physics", "optimize"],
    &["invert", "db"],
    &["rows"],
    &["zones"],
    &["field"],
    &["export", "recordings", "forward"],
    &["report"],
    &["diagnose"],
    &["change"],
    &["batch"],
    &["locate"],
    &["synth"],
    &["bench"],
];

fn layer_of(module: &str) -> Option<usize> {
    LAYERS.iter().position(|l| l.contains(&module))
}

/// Whether `user` may use `used` by the layer order.
fn allowed_by_layers(user: &str, used: &str) -> Option<bool> {
    let (lu, ld) = (layer_of(user)?, layer_of(used)?);
    Some(ld == 0 || ld < lu)
}

/// The top-level modules named by `crate::NAME` or `crate::{NAME, …}` in the code (not the
/// comments) of a file's lines before its `#[cfg(test)]`.
fn crate_paths(text: &str) -> Vec<String> {
    let mut code = String::new();
    for line in text.lines() {
        if line.trim_start().starts_with("#[cfg(test)]") {
            break;
        }
        code.push_str(line.split("//").next().unwrap_or(""));
        code.push('\n');
    }
    let ident = |s: &str| -> String {
        s.trim_start()
            .chars()
            .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
            .collect()
    };
    let mut out = Vec::new();
    for (at, _) in code.match_indices("crate::") {
        let rest = &code[at + 7..];
        let mut names = vec![ident(rest)];
        if let Some(group) = rest.strip_prefix('{') {
            // The first name of each top-level item of the group.
            let mut depth = 0;
            let mut item_start = true;
            for (k, c) in group.char_indices() {
                match c {
                    '{' => depth += 1,
                    '}' if depth == 0 => break,
                    '}' => depth -= 1,
                    ',' if depth == 0 => item_start = true,
                    c if item_start && !c.is_whitespace() => {
                        names.push(ident(&group[k..]));
                        item_start = false;
                    }
                    _ => {}
                }
            }
        }
        for name in names {
            if !name.is_empty() && name != "self" && !out.contains(&name) {
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
fn the_library_follows_the_layer_order() {
    let (breaks, unplaced) = violations();
    assert!(
        unplaced.is_empty(),
        "modules not in LAYERS (place them in tests/layers.rs and docs/design.md):\n{}",
        unplaced.join("\n")
    );
    let found: Vec<String> = breaks
        .iter()
        .map(|(f, m)| format!("{f} uses crate::{m}"))
        .collect();
    assert!(
        found.is_empty(),
        "against the layer order of docs/design.md:\n{}",
        found.join("\n")
    );
}

#[test]
fn the_order_reads_paths_in_code_not_in_comments_or_tests() {
    let text = "use crate::physics::Pipe; // see crate::batch\n\
                let s = crate::batch::segment_seed(1, \"a\");\n\
                #[cfg(test)]\n\
                use crate::report::x;";
    assert_eq!(crate_paths(text), ["physics", "batch"]);
    let grouped = "use crate::{\n    db::{self, Database},\n    units::sig,\n};";
    assert_eq!(crate_paths(grouped), ["db", "units"]);
    assert_eq!(allowed_by_layers("invert", "physics"), Some(true));
    assert_eq!(allowed_by_layers("physics", "invert"), Some(false));
    assert_eq!(allowed_by_layers("export", "report"), Some(false));
    assert_eq!(allowed_by_layers("synth", "batch"), Some(true));
    assert_eq!(allowed_by_layers("batch", "synth"), Some(false));
    assert_eq!(allowed_by_layers("zones", "field"), Some(false));
    assert_eq!(allowed_by_layers("field", "zones"), Some(true));
    assert_eq!(allowed_by_layers("db", "spreadsheet"), Some(true));
    assert_eq!(allowed_by_layers("db", "units"), Some(true));
    assert_eq!(allowed_by_layers("db", "nowhere"), None);
}
