//! Every equation tag the code cites (`T(5)`, `V(13)`, …) resolves to a heading of
//! `docs/equations.md`, so a reader of the repository alone can look each one up.

use std::collections::BTreeSet;
use std::fs;
use std::path::{Path, PathBuf};

/// The trees whose sources may cite equations.
const TREES: [&str; 3] = ["src", "tools", "host-tests"];

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("host-tests sits in the repository").to_path_buf()
}

/// The `.rs` files below `dir`, skipping build output.
fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = fs::read_dir(dir) else { return };
    for entry in entries.flatten() {
        let path = entry.path();
        if path.is_dir() {
            if path.file_name().is_some_and(|n| n != "target") {
                rust_files(&path, out);
            }
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The tags `T(n)` / `V(n)` in `text`: the letter not preceded by a letter, digit or `_`, one or
/// more digits inside the parentheses.
fn tags(text: &str) -> Vec<String> {
    let b = text.as_bytes();
    let mut found = Vec::new();
    for i in 0..b.len() {
        if !matches!(b[i], b'T' | b'V') || b.get(i + 1) != Some(&b'(') {
            continue;
        }
        if i > 0 && (b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_') {
            continue;
        }
        let digits = b[i + 2..].iter().take_while(|c| c.is_ascii_digit()).count();
        if digits > 0 && b.get(i + 2 + digits) == Some(&b')') {
            found.push(text[i..i + 3 + digits].to_string());
        }
    }
    found
}

/// The tags that head a section of `docs/equations.md` (`### T(5)`).
fn headings(md: &str) -> BTreeSet<String> {
    md.lines()
        .filter_map(|l| l.strip_prefix("### "))
        .filter(|h| tags(h).len() == 1 && tags(h)[0] == h.trim())
        .map(|h| h.trim().to_string())
        .collect()
}

#[test]
fn the_tag_scanner_finds_tags_and_only_tags() {
    assert_eq!(tags("T(5)/T(6), V(13)–V(17) and V(2)."), ["T(5)", "T(6)", "V(13)", "V(17)", "V(2)"]);
    assert!(tags("LUT(3) T(n) V() XV(2) a_T(1) T(1").is_empty());
    assert_eq!(
        headings("### T(1)\n## T(2)\n### V(13)\n### T(3)–T(4)\n"),
        BTreeSet::from(["T(1)".into(), "V(13)".into()])
    );
}

#[test]
fn every_equation_tag_in_the_code_has_a_heading_in_docs_equations_md() {
    let root = root();
    let md = fs::read_to_string(root.join("docs/equations.md")).expect("docs/equations.md exists");
    let have = headings(&md);
    let mut files = Vec::new();
    for tree in TREES {
        rust_files(&root.join(tree), &mut files);
    }
    assert!(files.len() > 50, "the scan found only {} source files under {TREES:?}", files.len());
    let mut cited = BTreeSet::new();
    let mut missing = Vec::new();
    for file in &files {
        let text = fs::read_to_string(file).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
        for (n, line) in text.lines().enumerate() {
            for tag in tags(line) {
                if !have.contains(&tag) {
                    missing.push(format!("{}:{}: {tag}", file.strip_prefix(&root).unwrap_or(file).display(), n + 1));
                }
                cited.insert(tag);
            }
        }
    }
    assert!(
        missing.is_empty(),
        "equation tags without a `### TAG` heading in docs/equations.md:\n{}",
        missing.join("\n")
    );
    // The code cites most of the temperature and the vibration equations; a scan that found
    // few of them is broken rather than clean.
    assert!(cited.len() >= 20, "only {} distinct tags found: {cited:?}", cited.len());
}
