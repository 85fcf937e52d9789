//! The documents and the code agree: every equation the code cites is written out in
//! docs/model.md, every section it cites exists there, src/ comments carry no segment ids,
//! network seeds or issue numbers, README.md stays a short manual, and every relative link of
//! the documents leads to a file.

use std::path::{Path, PathBuf};

/// Words before a `§` that mark a section of an outside document (a standard, a book, a
/// paper, a test-vector note), not of docs/model.md.
const EXTERNAL_SECTION_MARKERS: &[&str] = &[
    "12-128r18",
    "RFC",
    "Numerical Recipes",
    "Golub",
    "Random Data",
    "Rasmussen",
    "its §",
    "limits.md",
];

/// Longest README.md, in lines.
const README_MAX_LINES: usize = 300;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Every `.rs` file under `dir`, sorted.
fn rust_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap_or_else(|e| panic!("{}: {e}", d.display())) {
            let path = entry.expect("directory entry").path();
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

/// A line's comment text (from `//` on), with its line number, for every line of src/ that
/// has one. A `//` inside a string literal (a URL) is taken as a comment too, which only makes
/// the checks stricter.
fn src_comments() -> Vec<(String, usize, String)> {
    let mut out = Vec::new();
    for path in rust_files(&root().join("src")) {
        let name = path.strip_prefix(root()).unwrap().display().to_string();
        for (i, line) in read(&path).lines().enumerate() {
            if let Some(at) = line.find("//") {
                out.push((name.clone(), i + 1, line[at..].to_string()));
            }
        }
    }
    out
}

/// The numbers n of the tokens `P<n>` in `text` (a `P` not preceded by a letter, digit or `_`,
/// followed by digits not followed by a letter or digit).
fn equation_citations(text: &str) -> Vec<u32> {
    let b = text.as_bytes();
    let mut out = Vec::new();
    for i in 0..b.len() {
        if b[i] != b'P' || (i > 0 && (b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_')) {
            continue;
        }
        let digits = b[i + 1..].iter().take_while(|c| c.is_ascii_digit()).count();
        let end = i + 1 + digits;
        if digits == 0 || (end < b.len() && (b[end].is_ascii_alphanumeric() || b[end] == b'_')) {
            continue;
        }
        out.push(text[i + 1..end].parse().expect("digits"));
    }
    out
}

/// Whether docs/model.md has the anchor of `P<n>` followed, within its next four lines, by a
/// line that labels the equation `(P<n>)` and states a relation.
fn has_equation(model: &[&str], n: u32) -> bool {
    let anchor = format!("<a id=\"P{n}\"></a>");
    let label = format!("(P{n})");
    model.iter().enumerate().any(|(i, line)| {
        line.trim() == anchor
            && model[i + 1..(i + 5).min(model.len())].iter().any(|l| {
                l.contains(&label) && l.contains(['=', '≈', '<', '>', '→', '←', '~', '≤', '≥', '∝'])
            })
    })
}

/// The section numbers of docs/model.md's headings (`## 7. Inversion` → "7",
/// `### 7.10 What ...` → "7.10").
fn model_sections(model: &str) -> Vec<String> {
    model
        .lines()
        .filter(|l| l.starts_with('#'))
        .filter_map(|l| {
            let title = l.trim_start_matches('#').trim_start();
            let number: String = title
                .chars()
                .take_while(|c| c.is_ascii_digit() || *c == '.')
                .collect();
            let number = number.trim_end_matches('.').to_string();
            (!number.is_empty()).then_some(number)
        })
        .collect()
}

/// The section numbers cited by `§` in `text` with the 80 characters before each.
fn section_citations(text: &str) -> Vec<(String, String)> {
    let mut out = Vec::new();
    for (at, _) in text.match_indices('§') {
        let after = text[at + '§'.len_utf8()..].trim_start();
        let number: String = after
            .chars()
            .take_while(|c| c.is_ascii_digit() || *c == '.')
            .collect();
        let number = number.trim_end_matches('.').to_string();
        if number.is_empty() {
            continue;
        }
        let mut from = at.saturating_sub(80);
        while !text.is_char_boundary(from) {
            from -= 1;
        }
        out.push((number, text[from..at + '§'.len_utf8()].to_string()));
    }
    out
}

#[test]
fn every_equation_the_code_cites_is_written_out_in_the_model() {
    let model = read(&root().join("docs/model.md"));
    let lines: Vec<&str> = model.lines().collect();
    let mut missing = Vec::new();
    for (file, line, comment) in src_comments() {
        for n in equation_citations(&comment) {
            if !has_equation(&lines, n) {
                missing.push(format!("{file}:{line}: P{n}"));
            }
        }
    }
    assert!(
        missing.is_empty(),
        "no anchor with its equation in docs/model.md:\n{}",
        missing.join("\n")
    );
}

#[test]
fn the_open_works_equations_are_written_out_too() {
    // The soil field (P78–P83), leak location (P84–P87), honest errors (P88–P89) and the
    // pooled group test (P90–P91).
    let model = read(&root().join("docs/model.md"));
    let lines: Vec<&str> = model.lines().collect();
    let missing: Vec<u32> = (78..=91).filter(|&n| !has_equation(&lines, n)).collect();
    assert!(missing.is_empty(), "{missing:?}");
}

#[test]
fn every_section_the_code_cites_is_a_section_of_the_model() {
    let model = read(&root().join("docs/model.md"));
    let sections = model_sections(&model);
    let mut unresolved = Vec::new();
    for path in rust_files(&root().join("src")) {
        // Whole-file text, so that a source named on the line before its `§` counts.
        let text: String = read(&path)
            .lines()
            .map(|l| l.find("//").map_or("", |at| &l[at..]))
            .collect::<Vec<_>>()
            .join("\n");
        for (number, before) in section_citations(&text) {
            let external = EXTERNAL_SECTION_MARKERS.iter().any(|m| before.contains(m));
            if !external && !sections.contains(&number) {
                unresolved.push(format!("{}: §{number} ({before})", path.display()));
            }
        }
    }
    assert!(
        unresolved.is_empty(),
        "not a section of docs/model.md:\n{}",
        unresolved.join("\n")
    );
}

/// The titles `T` of the citations `docs/search.md, "T"` in `text`, whose comment markers
/// (`//`, `///`, `//!`) and line breaks are already folded into single spaces.
fn search_citations(text: &str) -> Vec<String> {
    const CITE: &str = "docs/search.md, \"";
    let mut out = Vec::new();
    let mut rest = text;
    while let Some(at) = rest.find(CITE) {
        rest = &rest[at + CITE.len()..];
        let end = rest.find('"').unwrap_or(rest.len());
        out.push(rest[..end].to_string());
        rest = &rest[end..];
    }
    out
}

/// The comments of a source file as one line: each comment's text after its markers, joined
/// by single spaces, so that a citation broken across lines reads whole.
fn folded_comments(source: &str) -> String {
    source
        .lines()
        .filter_map(|l| {
            l.find("//")
                .map(|at| l[at..].trim_start_matches(['/', '!']))
        })
        .flat_map(str::split_whitespace)
        .collect::<Vec<_>>()
        .join(" ")
}

#[test]
fn every_search_section_the_code_cites_is_a_heading_of_docs_search() {
    let doc = read(&root().join("docs/search.md"));
    let headings: Vec<&str> = doc
        .lines()
        .filter_map(|l| l.strip_prefix("## ").or_else(|| l.strip_prefix("### ")))
        .collect();
    let mut cited = 0;
    let mut unresolved = Vec::new();
    for path in rust_files(&root().join("src")) {
        for title in search_citations(&folded_comments(&read(&path))) {
            cited += 1;
            if !headings.contains(&title.as_str()) {
                unresolved.push(format!("{}: \"{title}\"", path.display()));
            }
        }
    }
    assert!(cited >= 5, "only {cited} citations of docs/search.md found");
    assert!(
        unresolved.is_empty(),
        "not a heading of docs/search.md:\n{}",
        unresolved.join("\n")
    );
    // The parser reads a citation broken across comment lines, and only the title.
    let folded = folded_comments(
        "/// as measured (evidence:\n    /// docs/search.md, \"The DE\n/// runs\").",
    );
    assert_eq!(search_citations(&folded), ["The DE runs"]);
}

/// Whether `text` holds `WM` followed by four or more digits (the synthetic networks' segment
/// ids).
fn has_segment_id(text: &str) -> bool {
    text.match_indices("WM").any(|(at, _)| {
        text[at + 2..]
            .chars()
            .take_while(char::is_ascii_digit)
            .count()
            >= 4
    })
}

/// Whether `text` holds a number of exactly six digits standing alone (a network seed): not
/// part of a longer number, a decimal (`651409.903`, `3.841459`) or a grouped one.
fn has_six_digit_number(text: &str) -> bool {
    let b = text.as_bytes();
    let mut i = 0;
    while i < b.len() {
        if b[i].is_ascii_digit() {
            let start = i;
            while i < b.len() && b[i].is_ascii_digit() {
                i += 1;
            }
            let before = start.checked_sub(1).map(|j| b[j]);
            let decimal_after =
                i + 1 < b.len() && matches!(b[i], b'.' | b',') && b[i + 1].is_ascii_digit();
            let joined_before = matches!(before, Some(c) if c == b'.' || c == b',' || c.is_ascii_alphabetic() || c == b'_');
            let joined_after = i < b.len() && (b[i].is_ascii_alphabetic() || b[i] == b'_');
            if i - start == 6 && !decimal_after && !joined_before && !joined_after {
                return true;
            }
        } else {
            i += 1;
        }
    }
    false
}

/// Whether `text` refers to an issue by number (`issue 12`, `Issues 3`, `issue #4`) or to a
/// specification clause such as `spec C2`.
fn has_issue_or_spec_reference(text: &str) -> bool {
    let lower = text.to_lowercase();
    let issue = ["issue ", "issues ", "issue #"].iter().any(|w| {
        lower.match_indices(w).any(|(at, _)| {
            let next = lower[at + w.len()..].trim_start_matches('#');
            next.starts_with(|c: char| c.is_ascii_digit())
        })
    });
    let spec = text.match_indices("spec ").any(|(at, _)| {
        let rest = &text[at + 5..];
        let mut c = rest.chars();
        matches!((c.next(), c.next()), (Some(a), Some(d)) if a.is_ascii_uppercase() && d.is_ascii_digit())
    });
    issue || spec
}

#[test]
fn src_comments_name_no_segment_seed_or_issue() {
    let bad: Vec<String> = src_comments()
        .into_iter()
        .filter(|(_, _, c)| {
            has_segment_id(c) || has_six_digit_number(c) || has_issue_or_spec_reference(c)
        })
        .map(|(f, l, c)| format!("{f}:{l}: {}", c.trim()))
        .collect();
    assert!(
        bad.is_empty(),
        "history belongs in CHANGELOG.md:\n{}",
        bad.join("\n")
    );
}

#[test]
fn the_checks_of_src_comments_catch_what_they_are_for() {
    assert!(has_segment_id("/// on WM10084 of the bench network"));
    assert!(!has_segment_id("/// WM stands for water main"));
    assert!(has_six_digit_number("// `bench --network-seed 848752`"));
    assert!(!has_six_digit_number("/// E 651409.903, N 313177.270"));
    assert!(!has_six_digit_number(
        "/// χ²₁ at 3.841459: 0.05; 1234567 and 12,345"
    ));
    assert!(has_issue_or_spec_reference("/// (issue 12)"));
    assert!(has_issue_or_spec_reference("/// Issues 3 and 4"));
    assert!(has_issue_or_spec_reference("//! units (spec C2)"));
    assert!(!has_issue_or_spec_reference(
        "/// an issue of precision; spec. sheet"
    ));
    assert_eq!(
        equation_citations("/// eqs. P13–P23 and (P44), not P4x or MP3"),
        [13, 23, 44]
    );
    let cited = section_citations("/// model §7.10 and §8 E7; RFC 7946 §11.2");
    let numbers: Vec<&str> = cited.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(numbers, ["7.10", "8", "11.2"]);
    assert!(cited[2].1.contains("RFC"));
}

#[test]
fn fit_algorithm_versions_history_lives_in_the_changelog() {
    let fit = read(&root().join("src/types.rs"));
    let lines: Vec<&str> = fit.lines().collect();
    let at = lines
        .iter()
        .position(|l| l.starts_with("pub const FIT_ALGORITHM_VERSION"))
        .expect("FIT_ALGORITHM_VERSION in src/types.rs");
    let doc = lines[..at]
        .iter()
        .rev()
        .take_while(|l| l.starts_with("///"))
        .count();
    assert!((1..=5).contains(&doc), "its doc comment has {doc} lines");
    let changelog = read(&root().join("CHANGELOG.md"));
    let value = lines[at].split('=').nth(1).expect("a value");
    let version: String = value.chars().filter(char::is_ascii_digit).collect();
    assert!(
        changelog.contains(&format!("## Fit algorithm {version} ")),
        "CHANGELOG.md has no entry for fit algorithm {version}"
    );
}

#[test]
fn the_readme_is_a_short_manual() {
    let lines = read(&root().join("README.md")).lines().count();
    assert!(lines <= README_MAX_LINES, "README.md has {lines} lines");
}

/// The README says what to install before the first command (issue 64): the Rust version of
/// Cargo.toml's `rust-version`, a C compiler for the bundled SQLite, the optional tools of the
/// ignored tests (every one the tests name), and how to put `pipewave` on the PATH.
#[test]
fn the_readme_says_what_to_install_first() {
    let readme = read(&root().join("README.md"));
    let start = readme
        .find("## Before you start")
        .expect("README.md has a section Before you start");
    let first_command = readme
        .find("cargo run --release -- run sample_network")
        .unwrap();
    assert!(
        start < first_command,
        "Before you start comes after the first command"
    );
    let section = &readme[start..];
    let section = &section[..section[3..].find("\n## ").map_or(section.len(), |i| i + 3)];
    let cargo = read(&root().join("Cargo.toml"));
    let version = cargo
        .lines()
        .find_map(|l| l.strip_prefix("rust-version = "))
        .unwrap()
        .trim_matches('"');
    assert!(section.contains(&format!("Rust {version}")), "{section}");
    for needed in ["C compiler", "SQLite", "cargo install --path ."] {
        assert!(section.contains(needed), "{needed} missing: {section}");
    }
    for test in rust_files(&root().join("tests")) {
        for line in read(&test).lines() {
            if let Some(tool) = line
                .trim()
                .strip_prefix("#[ignore = \"needs ")
                .and_then(|t| t.strip_suffix("\"]"))
            {
                assert!(
                    section.contains(tool),
                    "the ignored tests need {tool}: {section}"
                );
            }
        }
    }
}

/// The relative link targets of a Markdown text (`](target)`), without their `#fragment`.
fn relative_links(markdown: &str) -> Vec<String> {
    markdown
        .match_indices("](")
        .filter_map(|(at, _)| {
            let rest = &markdown[at + 2..];
            let target = &rest[..rest.find(')')?];
            let path = target.split('#').next().unwrap_or("");
            let external = target.contains("://") || target.starts_with("mailto:");
            (!external && !path.is_empty()).then(|| path.to_string())
        })
        .collect()
}

#[test]
fn every_relative_link_of_the_documents_leads_to_a_file() {
    let root = root();
    let mut documents = vec![
        root.join("README.md"),
        root.join("CHANGELOG.md"),
        root.join("CONTRIBUTING.md"),
    ];
    for entry in std::fs::read_dir(root.join("docs")).expect("docs/") {
        let path = entry.expect("entry").path();
        if path.extension().is_some_and(|x| x == "md") {
            documents.push(path);
        }
    }
    let mut dead = Vec::new();
    for doc in &documents {
        for link in relative_links(&read(doc)) {
            let target = doc.parent().expect("a folder").join(&link);
            let normal = normalise(&target, &root);
            if !target.exists() {
                dead.push(format!("{}: {link} ({normal})", doc.display()));
            }
        }
    }
    assert!(dead.is_empty(), "links to no file:\n{}", dead.join("\n"));
    assert_eq!(
        relative_links("[a](docs/x.md#y) [b](https://e.org) [c](#z)"),
        ["docs/x.md"]
    );
}

/// `path` relative to `root`, with `..` and `.` resolved, `/`-separated.
fn normalise(path: &Path, root: &Path) -> String {
    let mut parts: Vec<String> = Vec::new();
    for c in path.strip_prefix(root).unwrap_or(path).components() {
        match c {
            std::path::Component::ParentDir => {
                parts.pop();
            }
            std::path::Component::Normal(p) => parts.push(p.to_string_lossy().into_owned()),
            _ => {}
        }
    }
    parts.join("/")
}
