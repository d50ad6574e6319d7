//! ARCHITECTURE.md names only what exists: every backticked path is a file or folder of the
//! repository, and every backticked type (CamelCase, optionally `Type::item`) is found in the
//! sources. A map that drifts from the code fails here.

use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Build outputs the map may name; they are not in a clone.
const BUILT: &[&str] = &["dist/"];

/// Every file and folder name under `dir`.
fn names(dir: &Path, out: &mut Vec<String>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        out.push(e.file_name().to_string_lossy().into_owned());
        if e.path().is_dir() {
            names(&e.path(), out);
        }
    }
}

fn sources(dir: &Path, out: &mut Vec<String>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let p = e.path();
        if p.is_dir() {
            sources(&p, out);
        } else if p
            .extension()
            .is_some_and(|x| x == "rs" || x == "wgsl" || x == "mjs")
        {
            out.push(std::fs::read_to_string(&p).unwrap_or_default());
        }
    }
}

/// Backticked spans of a Markdown text (code fences skipped).
fn backticked(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut in_fence = false;
    for line in text.lines() {
        if line.trim_start().starts_with("```") {
            in_fence = !in_fence;
            continue;
        }
        if in_fence {
            continue;
        }
        let mut parts = line.split('`');
        parts.next();
        while let Some(code) = parts.next() {
            out.push(code.to_owned());
            parts.next();
        }
    }
    out
}

fn is_path(s: &str) -> bool {
    !s.contains(' ')
        && !s.contains('*')
        && !s.contains('{')
        && !s.starts_with('?')
        && (s.contains('/')
            || [".rs", ".wgsl", ".md", ".mjs", ".toml"]
                .iter()
                .any(|e| s.ends_with(e)))
}

fn is_type(s: &str) -> bool {
    let head = s.split("::").next().unwrap_or("");
    head.chars().next().is_some_and(|c| c.is_ascii_uppercase())
        && head.chars().all(|c| c.is_ascii_alphanumeric())
        && head.chars().any(|c| c.is_ascii_lowercase())
        && s.split("::")
            .all(|p| p.chars().all(|c| c.is_ascii_alphanumeric() || c == '_'))
}

#[test]
fn every_path_and_type_in_architecture_md_exists() {
    let root = root();
    let text = std::fs::read_to_string(root.join("ARCHITECTURE.md")).expect("ARCHITECTURE.md");
    let mut code = Vec::new();
    for dir in ["src", "tests", "shaders", "xtask"] {
        sources(&root.join(dir), &mut code);
    }
    let mut tree = Vec::new();
    for dir in ["src", "tests", "shaders", "web", "docs", "xtask", "scripts"] {
        names(&root.join(dir), &mut tree);
    }
    let mut missing = Vec::new();
    let (mut paths, mut types) = (0, 0);
    for span in backticked(&text) {
        let span = span.trim().trim_end_matches("()").to_owned();
        if is_path(&span) {
            paths += 1;
            let p = span.trim_end_matches('/');
            let candidates = [
                root.join(p),
                root.join("src").join(p),
                root.join("shaders").join(p),
            ];
            // A bare name in a paragraph about its folder: some file or folder of that name.
            let bare = !p.contains('/') && tree.iter().any(|n| n == p);
            if !BUILT.contains(&span.as_str()) && !bare && !candidates.iter().any(|c| c.exists()) {
                missing.push(format!("path `{span}`"));
            }
        } else if is_type(&span) {
            types += 1;
            // Every segment must be declared or used somewhere in the sources.
            for part in span.split("::") {
                if !code.iter().any(|c| c.contains(part)) {
                    missing.push(format!("name `{span}` ({part})"));
                    break;
                }
            }
        }
    }
    println!("ARCHITECTURE.md: {paths} paths and {types} types checked");
    assert!(
        paths > 20 && types > 20,
        "too few names found: the parser broke"
    );
    assert!(
        missing.is_empty(),
        "ARCHITECTURE.md names what does not exist: {missing:#?}"
    );
}
