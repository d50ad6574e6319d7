//! ARCHITECTURE.md names only what exists, and its checked invariants hold.
//!
//! - Every backticked path is a file or folder of the repository, every backticked type
//!   (CamelCase, optionally `Type::item`) is found in the sources, and every backticked
//!   `module::item` (lower case, with `::`) names a module of src/ and an item defined in it.
//! - Every `Invariant:` of ARCHITECTURE.md marked "(checked)" is one of the `RULES` below, and
//!   every rule is stated there; the rules are enforced by scanning the code of src/ (comments,
//!   strings and character literals blanked, so only code counts).
//!
//! A map that drifts from the code fails here. Std only: no parser, a small lexer.

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

fn architecture_md() -> String {
    std::fs::read_to_string(root().join("ARCHITECTURE.md")).expect("ARCHITECTURE.md")
}

#[test]
fn every_path_and_type_in_architecture_md_exists() {
    let root = root();
    let text = architecture_md();
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

// ---------------------------------------------------------------------------------------------
// The code of src/, without comments, strings and character literals.

/// One Rust file of src/: its path from the repository root (with `/`), its code with comments,
/// strings and character literals blanked (newlines kept, so offsets give line numbers), the
/// same with `#[cfg(test)]` items blanked too, and its module path (`src/a/b.rs` is `a::b`).
struct RustFile {
    rel: String,
    original: String,
    code: Vec<char>,
    non_test: Vec<char>,
    module: Vec<String>,
}

fn is_ident(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_'
}

/// `src` with comments, string literals (plain, byte, raw) and character literals replaced by
/// spaces; newlines are kept. Lifetimes and labels stay code.
fn blank_non_code(src: &str) -> Vec<char> {
    let s: Vec<char> = src.chars().collect();
    let mut out = s.clone();
    let blank = |out: &mut Vec<char>, from: usize, to: usize| {
        for c in out.iter_mut().take(to.min(s.len())).skip(from) {
            if *c != '\n' {
                *c = ' ';
            }
        }
    };
    let at = |i: usize| s.get(i).copied().unwrap_or('\0');
    let mut i = 0;
    while i < s.len() {
        let c = s[i];
        let prev = if i > 0 { s[i - 1] } else { '\0' };
        if c == '/' && at(i + 1) == '/' {
            let end = (i..s.len()).find(|&j| s[j] == '\n').unwrap_or(s.len());
            blank(&mut out, i, end);
            i = end;
        } else if c == '/' && at(i + 1) == '*' {
            let (mut depth, mut j) = (1, i + 2);
            while j < s.len() && depth > 0 {
                if s[j] == '/' && at(j + 1) == '*' {
                    depth += 1;
                    j += 2;
                } else if s[j] == '*' && at(j + 1) == '/' {
                    depth -= 1;
                    j += 2;
                } else {
                    j += 1;
                }
            }
            blank(&mut out, i, j);
            i = j;
        } else if c == 'r'
            && (!is_ident(prev) || (prev == 'b' && (i < 2 || !is_ident(s[i - 2]))))
            && (at(i + 1) == '"' || at(i + 1) == '#')
        {
            // A raw string r"..." or r#"..."#, or an identifier starting with r.
            let mut j = i + 1;
            while at(j) == '#' {
                j += 1;
            }
            if at(j) != '"' {
                i += 1;
                continue;
            }
            let hashes = j - i - 1;
            let mut k = j + 1;
            let end = loop {
                if k >= s.len() {
                    break s.len();
                }
                if s[k] == '"' && (1..=hashes).all(|h| at(k + h) == '#') {
                    break k + 1 + hashes;
                }
                k += 1;
            };
            blank(&mut out, j, end);
            i = end;
        } else if c == '"' {
            let mut j = i + 1;
            while j < s.len() && s[j] != '"' {
                j += if s[j] == '\\' { 2 } else { 1 };
            }
            blank(&mut out, i, j + 1);
            i = j + 1;
        } else if c == '\'' {
            if at(i + 1) == '\\' {
                // '\n', '\'', '\u{..}': the closing quote is the first one after the escape.
                let end = (i + 3..s.len()).find(|&j| s[j] == '\'').unwrap_or(s.len());
                blank(&mut out, i, end + 1);
                i = end + 1;
            } else if at(i + 2) == '\'' {
                blank(&mut out, i, i + 3);
                i += 3;
            } else {
                i += 1; // a lifetime or a label
            }
        } else {
            i += 1;
        }
    }
    out
}

fn starts_with_at(code: &[char], i: usize, text: &str) -> bool {
    text.chars()
        .enumerate()
        .all(|(k, c)| code.get(i + k) == Some(&c))
}

fn skip_ws(code: &[char], mut i: usize) -> usize {
    while i < code.len() && code[i].is_whitespace() {
        i += 1;
    }
    i
}

/// The ranges of `code` that are `#[cfg(test)]` items (the attribute, any attributes after it,
/// and the item up to its `;` or the `}` that closes it), and the names of `mod NAME;` among
/// them (modules in files of their own that exist only for tests).
fn test_items(code: &[char]) -> (Vec<(usize, usize)>, Vec<String>) {
    let (mut ranges, mut mods) = (Vec::new(), Vec::new());
    let mut i = 0;
    while i < code.len() {
        if !starts_with_at(code, i, "#[cfg(test)]") {
            i += 1;
            continue;
        }
        let start = i;
        let mut j = skip_ws(code, i + "#[cfg(test)]".len());
        while starts_with_at(code, j, "#[") {
            let mut depth = 0;
            while j < code.len() {
                match code[j] {
                    '[' => depth += 1,
                    ']' => {
                        depth -= 1;
                        if depth == 0 {
                            j += 1;
                            break;
                        }
                    }
                    _ => {}
                }
                j += 1;
            }
            j = skip_ws(code, j);
        }
        let item = j;
        let (mut depth, mut nest) = (0, 0);
        let end = loop {
            if j >= code.len() {
                break code.len();
            }
            match code[j] {
                ';' if depth == 0 && nest == 0 => break j + 1,
                '(' | '[' => nest += 1,
                ')' | ']' => nest -= 1,
                '{' => depth += 1,
                '}' => {
                    depth -= 1;
                    if depth == 0 {
                        break j + 1;
                    }
                }
                _ => {}
            }
            j += 1;
        };
        let text: String = code[item..end].iter().collect();
        let words: Vec<&str> = text
            .split(|c: char| !is_ident(c))
            .filter(|w| !w.is_empty())
            .collect();
        if text.trim_end().ends_with(';')
            && let Some(k) = words.iter().position(|w| *w == "mod")
            && let Some(name) = words.get(k + 1)
        {
            mods.push((*name).to_owned());
        }
        ranges.push((start, end));
        i = end;
    }
    (ranges, mods)
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    let mut entries: Vec<PathBuf> = entries.flatten().map(|e| e.path()).collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// The module path of a file under src/: `src/a/b.rs` and `src/a/b/mod.rs` are `[a, b]`,
/// `src/lib.rs` and `src/main.rs` the crate root `[]`.
fn module_of(rel_to_src: &Path) -> Vec<String> {
    let mut parts: Vec<String> = rel_to_src
        .iter()
        .map(|p| p.to_string_lossy().into_owned())
        .collect();
    let last = parts.pop().unwrap_or_default();
    let stem = last.trim_end_matches(".rs");
    if !(stem == "mod" || (parts.is_empty() && (stem == "lib" || stem == "main"))) {
        parts.push(stem.to_owned());
    }
    parts
}

/// Every Rust file of `root`/src, lexed; files of modules declared only under `#[cfg(test)]`
/// are test code as a whole.
fn src_files(root: &Path) -> Vec<RustFile> {
    let src = root.join("src");
    let mut paths = Vec::new();
    rust_files(&src, &mut paths);
    let mut files: Vec<RustFile> = paths
        .iter()
        .map(|p| {
            let original = std::fs::read_to_string(p).unwrap_or_default();
            let code = blank_non_code(&original);
            let mut non_test = code.clone();
            for (a, b) in test_items(&code).0 {
                for c in &mut non_test[a..b] {
                    if *c != '\n' {
                        *c = ' ';
                    }
                }
            }
            let rel_src = p.strip_prefix(&src).unwrap_or(p);
            RustFile {
                rel: format!("src/{}", rel_src.to_string_lossy().replace('\\', "/")),
                original,
                code,
                non_test,
                module: module_of(rel_src),
            }
        })
        .collect();
    // `#[cfg(test)] mod NAME;`: the file (or folder) of NAME is test code.
    let mut test_modules: Vec<Vec<String>> = Vec::new();
    for f in &files {
        for name in test_items(&f.code).1 {
            let mut m = f.module.clone();
            m.push(name);
            test_modules.push(m);
        }
    }
    for f in &mut files {
        if test_modules.iter().any(|m| f.module.starts_with(m)) {
            f.non_test = f
                .non_test
                .iter()
                .map(|&c| if c == '\n' { c } else { ' ' })
                .collect();
        }
    }
    files
}

/// The identifiers of `code` with their offsets.
fn idents(code: &[char]) -> Vec<(usize, String)> {
    let mut out = Vec::new();
    let mut i = 0;
    while i < code.len() {
        if is_ident(code[i]) && (i == 0 || !is_ident(code[i - 1])) {
            let start = i;
            while i < code.len() && is_ident(code[i]) {
                i += 1;
            }
            let word: String = code[start..i].iter().collect();
            if !word.starts_with(|c: char| c.is_ascii_digit()) {
                out.push((start, word));
            }
        } else {
            i += 1;
        }
    }
    out
}

/// For each path `head::X` or `head::{X, Y::Z, ..}` in `code`: its offset and the names that
/// follow `head::` (X; X and Y).
fn paths_after(code: &[char], head: &str) -> Vec<(usize, Vec<String>)> {
    let mut out = Vec::new();
    for (at, word) in idents(code) {
        if word != head {
            continue;
        }
        let mut j = skip_ws(code, at + head.len());
        if !starts_with_at(code, j, "::") {
            continue;
        }
        j = skip_ws(code, j + 2);
        let mut names = Vec::new();
        if code.get(j) == Some(&'{') {
            let (mut depth, mut expect_name) = (0, true);
            while j < code.len() {
                let c = code[j];
                match c {
                    '{' => {
                        depth += 1;
                        expect_name = depth == 1;
                    }
                    '}' => {
                        depth -= 1;
                        if depth == 0 {
                            break;
                        }
                    }
                    ',' if depth == 1 => expect_name = true,
                    c if expect_name && is_ident(c) => {
                        let start = j;
                        while j < code.len() && is_ident(code[j]) {
                            j += 1;
                        }
                        names.push(code[start..j].iter().collect());
                        expect_name = false;
                        continue;
                    }
                    c if !c.is_whitespace() => expect_name = false,
                    _ => {}
                }
                j += 1;
            }
        } else {
            let start = j;
            while j < code.len() && is_ident(code[j]) {
                j += 1;
            }
            if j > start {
                names.push(code[start..j].iter().collect());
            }
        }
        out.push((at, names));
    }
    out
}

fn line_of(code: &[char], at: usize) -> usize {
    code[..at].iter().filter(|&&c| c == '\n').count() + 1
}

// ---------------------------------------------------------------------------------------------
// Backticked `module::item` names.

/// Crates outside this one that the map may name as `krate::item`.
const EXTERNAL: &[&str] = &[
    "std",
    "core",
    "alloc",
    "wgpu",
    "egui",
    "eframe",
    "egui_wgpu",
    "web_sys",
    "js_sys",
    "glam",
    "bytemuck",
    "serde_json",
    "clap",
    "anyhow",
    "ureq",
    "rayon",
];

/// Backticked lower-case paths with `::` (`io::load`, `cpu::findings::find`,
/// `Type`-less or with a `Type::method` tail), `a::{x, y}` expanded, a leading `crate::` kept.
fn module_paths(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    for span in backticked(text) {
        let span = span.trim().trim_end_matches("()");
        if !span.starts_with(|c: char| c.is_ascii_lowercase()) || !span.contains("::") {
            continue;
        }
        let expanded: Vec<String> = match (span.find("::{"), span.ends_with('}')) {
            (Some(k), true) => span[k + 3..span.len() - 1]
                .split(',')
                .map(|item| format!("{}::{}", &span[..k], item.trim()))
                .collect(),
            _ => vec![span.to_owned()],
        };
        for p in expanded {
            if p.split("::")
                .all(|s| !s.is_empty() && s.chars().all(is_ident))
            {
                out.push(p);
            }
        }
    }
    out
}

const DEFINING: &[&str] = &[
    "fn", "struct", "enum", "const", "static", "mod", "type", "trait", "union",
];

/// Whether `name` is defined (`fn name`, `struct name`, ..., `static mut name`) in `code`.
fn defines(code: &[char], name: &str) -> bool {
    let words = idents(code);
    words
        .windows(2)
        .any(|w| DEFINING.contains(&w[0].1.as_str()) && w[1].1 == name)
        || words
            .windows(3)
            .any(|w| w[0].1 == "static" && w[1].1 == "mut" && w[2].1 == name)
}

/// Why `path` (a backticked `module::item`) does not resolve, or None when it does: some
/// module of src/ whose path ends with the leading segments (equals them after `crate::`)
/// defines the first item, and the last one, in its file or anywhere under its folder.
fn unresolved(files: &[RustFile], path: &str) -> Option<String> {
    let mut segs: Vec<&str> = path.split("::").collect();
    let absolute = segs[0] == "crate";
    if absolute {
        segs.remove(0);
    }
    if segs.is_empty() {
        return Some("names the crate only".to_owned());
    }
    if !absolute && EXTERNAL.contains(&segs[0]) {
        return None;
    }
    let mut modules_found = false;
    for k in (1..=segs.len()).rev() {
        let prefix = &segs[..k];
        let matches = |m: &Vec<String>| {
            m.len() >= k
                && (!absolute || m.len() == k)
                && m[m.len() - k..].iter().zip(prefix).all(|(a, b)| a == b)
        };
        let mut candidates: Vec<Vec<String>> = files
            .iter()
            .map(|f| f.module.clone())
            .filter(|m| matches(m))
            .collect();
        candidates.sort();
        candidates.dedup();
        if candidates.is_empty() {
            continue;
        }
        modules_found = true;
        let items = &segs[k..];
        if items.is_empty() {
            return None;
        }
        for m in &candidates {
            let under: Vec<&RustFile> = files.iter().filter(|f| f.module.starts_with(m)).collect();
            let defined = |name: &str| under.iter().any(|f| defines(&f.code, name));
            if defined(items[0]) && defined(items[items.len() - 1]) {
                return None;
            }
        }
    }
    Some(if modules_found {
        "no such item defined in the module".to_owned()
    } else {
        "no such module under src/".to_owned()
    })
}

#[test]
fn every_module_item_in_architecture_md_is_defined() {
    let files = src_files(&root());
    let paths = module_paths(&architecture_md());
    let missing: Vec<String> = paths
        .iter()
        .filter_map(|p| unresolved(&files, p).map(|why| format!("`{p}`: {why}")))
        .collect();
    println!("ARCHITECTURE.md: {} module paths checked", paths.len());
    assert!(
        paths.len() > 20,
        "too few module paths found: the parser broke"
    );
    assert!(
        missing.is_empty(),
        "ARCHITECTURE.md names module items that are not defined: {missing:#?}"
    );
}

// ---------------------------------------------------------------------------------------------
// Invariants enforced by scanning src/.

/// What a rule looks for in code.
enum Pattern {
    /// An identifier (`wgpu` matches `wgpu::Device` and `use wgpu;`, not `wgpu_options`).
    Ident(&'static str),
    /// A path `head::name` or `head::{.., name, ..}` (`std::fs`, `crate::render`).
    Path(&'static str, &'static str),
    /// `crate::X` for any top-level module X of src/lib.rs not in the list.
    CrateOtherThan(&'static [&'static str]),
}

/// Where a rule's patterns may appear after all: a path prefix, how the invariant in
/// ARCHITECTURE.md names it, and why.
struct Allowed {
    path: &'static str,
    named: &'static str,
    why: &'static str,
}

const fn allow(path: &'static str, named: &'static str, why: &'static str) -> Allowed {
    Allowed { path, named, why }
}

struct Rule {
    /// The words of its `Invariant:` in ARCHITECTURE.md (whitespace aside).
    claim: &'static str,
    /// Files the rule covers: path prefixes from the repository root.
    scope: &'static [&'static str],
    patterns: &'static [Pattern],
    /// Where the patterns may appear after all.
    allowed: &'static [Allowed],
    /// Whether `#[cfg(test)]` code is exempt.
    skip_tests: bool,
}

const RULES: &[Rule] = &[
    Rule {
        claim: "`src/io` never names `wgpu` or `std::fs` outside its tests",
        scope: &["src/io/"],
        patterns: &[
            Pattern::Ident("wgpu"),
            Pattern::Ident("egui_wgpu"),
            Pattern::Path("std", "fs"),
        ],
        allowed: &[],
        // suv.rs and stream.rs tests read fixtures from tests/data with std::fs.
        skip_tests: true,
    },
    Rule {
        claim: "`src/io` depends on no other module but `src/volume.rs` and `src/error.rs`",
        scope: &["src/io/"],
        patterns: &[Pattern::CrateOtherThan(&["io", "volume", "error"])],
        allowed: &[],
        skip_tests: false,
    },
    Rule {
        claim: "`src/cpu` depends on no other module of the crate but `src/volume.rs`",
        scope: &["src/cpu/"],
        patterns: &[Pattern::CrateOtherThan(&["cpu", "volume"])],
        allowed: &[],
        skip_tests: false,
    },
    Rule {
        claim: "`src/volume.rs` depends on no other module of the crate",
        scope: &["src/volume.rs"],
        patterns: &[Pattern::CrateOtherThan(&["volume"])],
        allowed: &[],
        skip_tests: false,
    },
    Rule {
        claim: "`src/compute` never names `crate::render`",
        scope: &["src/compute/"],
        patterns: &[Pattern::Path("crate", "render")],
        allowed: &[],
        skip_tests: false,
    },
    Rule {
        claim: "`src/render` never names `crate::compute`",
        scope: &["src/render/"],
        patterns: &[Pattern::Path("crate", "compute")],
        allowed: &[],
        skip_tests: false,
    },
    Rule {
        claim: "`wgpu` is named only in `src/gpu`, `src/compute`, `src/render`",
        scope: &["src/"],
        patterns: &[Pattern::Ident("wgpu"), Pattern::Ident("egui_wgpu")],
        allowed: &[
            allow(
                "src/gpu/",
                "`src/gpu`",
                "the device, buffers, readback, volume textures",
            ),
            allow("src/compute/", "`src/compute`", "the feature kernels"),
            allow(
                "src/render/",
                "`src/render`",
                "the ray caster, slice kernel and probe",
            ),
            allow(
                "src/app/startup.rs",
                "`src/app/startup.rs`",
                "eframe's wgpu setup",
            ),
            allow(
                "src/app/paint.rs",
                "`src/app/paint.rs`",
                "wgpu textures registered in egui",
            ),
            allow(
                "src/app/mip_view/",
                "`src/app/mip_view/`",
                "its wgpu texture in egui",
            ),
            allow(
                "src/app/slices/",
                "`src/app/slices/`",
                "their wgpu textures in egui",
            ),
            allow(
                "src/app/pet/mip.rs",
                "`src/app/pet/mip.rs`",
                "the PET MIP draws with egui_wgpu",
            ),
            allow(
                "src/app/export/movie.rs",
                "`src/app/export/movie.rs`",
                "textures it renders off-screen",
            ),
            // Exceptions to issue 30's rule (wgpu only in gpu, compute, render and the app's
            // panes): these commands make their own device or wait on it, outside the app.
            allow(
                "src/cli/render/",
                "`src/cli/render/`",
                "WebGPU limits, blocking polls",
            ),
            allow(
                "src/cli/bench/",
                "`src/cli/bench/`",
                "times kernels on its own buffers",
            ),
            allow(
                "src/cli/whole_body.rs",
                "`src/cli/whole_body.rs`",
                "waits between phases",
            ),
        ],
        skip_tests: false,
    },
    Rule {
        claim: "in `src/app` only `src/app/platform/` and `src/app/pacs/transport/` ask \
                `target_arch`",
        scope: &["src/app/"],
        patterns: &[Pattern::Ident("target_arch")],
        allowed: &[
            allow(
                "src/app/platform/",
                "`src/app/platform/`",
                "the page's and the native window's sides",
            ),
            allow(
                "src/app/pacs/transport/",
                "`src/app/pacs/transport/`",
                "the archive's tasks: `fetch` in the page, threads natively",
            ),
        ],
        skip_tests: false,
    },
    Rule {
        claim: "`anyhow` is named only in `src/cli` and `src/main.rs`",
        scope: &["src/"],
        patterns: &[Pattern::Ident("anyhow")],
        allowed: &[
            allow("src/cli/", "`src/cli`", "the command line's errors"),
            allow(
                "src/main.rs",
                "`src/main.rs`",
                "the binary prints cli::run's error",
            ),
        ],
        skip_tests: false,
    },
    Rule {
        claim: "HTTP requests are made only by `src/io/dicomweb/client.rs`, \
                `src/io/dicomweb/web.rs`, `src/app/platform/web/fetch.rs` and `src/app/platform/web/files/`",
        scope: &["src/"],
        patterns: &[
            Pattern::Ident("ureq"),
            Pattern::Ident("fetch_with_str"),
            Pattern::Ident("fetch_with_str_and_init"),
            Pattern::Ident("fetch_with_request"),
            Pattern::Ident("fetch_with_request_and_init"),
        ],
        allowed: &[
            allow(
                "src/io/dicomweb/client.rs",
                "`src/io/dicomweb/client.rs`",
                "native, ureq",
            ),
            allow(
                "src/io/dicomweb/web.rs",
                "`src/io/dicomweb/web.rs`",
                "the page's fetch",
            ),
            allow(
                "src/app/platform/web/fetch.rs",
                "`src/app/platform/web/fetch.rs`",
                "the page's ?url= downloads",
            ),
            allow(
                "src/app/platform/web/files/",
                "`src/app/platform/web/files/`",
                "the page's demo CT",
            ),
        ],
        skip_tests: false,
    },
];

/// The top-level modules of the crate (`mod X` in src/lib.rs).
fn top_modules(files: &[RustFile]) -> Vec<String> {
    let lib = files
        .iter()
        .find(|f| f.rel == "src/lib.rs")
        .expect("src/lib.rs");
    let words = idents(&lib.code);
    words
        .windows(2)
        .filter(|w| w[0].1 == "mod")
        .map(|w| w[1].1.clone())
        .collect()
}

/// Each place in `files` that breaks `rule`, as "path:line: what: the line".
fn violations(rule: &Rule, files: &[RustFile]) -> Vec<String> {
    let top = top_modules(files);
    let mut out = Vec::new();
    for f in files {
        if !rule.scope.iter().any(|s| f.rel.starts_with(s))
            || rule.allowed.iter().any(|a| f.rel.starts_with(a.path))
        {
            continue;
        }
        let code = if rule.skip_tests {
            &f.non_test
        } else {
            &f.code
        };
        let mut hits: Vec<(usize, String)> = Vec::new();
        for pattern in rule.patterns {
            match pattern {
                Pattern::Ident(name) => {
                    hits.extend(idents(code).into_iter().filter(|(_, w)| w == name));
                }
                Pattern::Path(head, name) => hits.extend(
                    paths_after(code, head)
                        .into_iter()
                        .filter(|(_, names)| names.iter().any(|n| n == name))
                        .map(|(at, _)| (at, format!("{head}::{name}"))),
                ),
                Pattern::CrateOtherThan(ok) => {
                    for (at, names) in paths_after(code, "crate") {
                        for n in names {
                            if top.contains(&n) && !ok.contains(&n.as_str()) {
                                hits.push((at, format!("crate::{n}")));
                            }
                        }
                    }
                }
            }
        }
        for (at, what) in hits {
            let line = line_of(code, at);
            let text = f.original.lines().nth(line - 1).unwrap_or("").trim();
            out.push(format!("{}:{line}: {what}: {text}", f.rel));
        }
    }
    out
}

/// The `Invariant:` paragraphs of a Markdown text, whitespace normalised: from a line starting
/// `Invariant:` to a blank line, a heading, a list item or the next `Invariant:`.
fn invariants(text: &str) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    let mut open = false;
    for line in text.lines() {
        let t = line.trim();
        if t.starts_with("Invariant:") {
            out.push(t.to_owned());
            open = true;
        } else if t.is_empty() || t.starts_with('#') || t.starts_with("- ") || t.starts_with("```")
        {
            open = false;
        } else if open && let Some(last) = out.last_mut() {
            last.push(' ');
            last.push_str(t);
        }
    }
    out.into_iter()
        .map(|p| p.split_whitespace().collect::<Vec<_>>().join(" "))
        .collect()
}

#[test]
fn checked_invariants_are_stated_and_hold() {
    let root = root();
    let stated = invariants(&architecture_md());
    assert!(
        stated.len() >= 10,
        "too few `Invariant:` lines found: the parser broke"
    );
    let mut problems = Vec::new();
    for rule in RULES {
        let claim = rule.claim.split_whitespace().collect::<Vec<_>>().join(" ");
        let Some(paragraph) = stated
            .iter()
            .find(|p| p.contains(&claim) && p.contains("(checked)"))
        else {
            problems.push(format!(
                "no `Invariant:` marked (checked) in ARCHITECTURE.md says: {claim}"
            ));
            continue;
        };
        for a in rule.allowed {
            if !root.join(a.path).exists() {
                problems.push(format!(
                    "allowed path {} ({}) does not exist",
                    a.path, a.why
                ));
            }
            if !paragraph.contains(a.named) {
                problems.push(format!(
                    "the invariant does not name {} ({}), which its rule allows: {paragraph}",
                    a.named, a.path
                ));
            }
        }
    }
    for p in stated.iter().filter(|p| p.contains("(checked)")) {
        let enforced = RULES
            .iter()
            .any(|r| p.contains(&r.claim.split_whitespace().collect::<Vec<_>>().join(" ")));
        if !enforced {
            problems.push(format!(
                "marked (checked) but no rule here enforces it: {p}"
            ));
        }
    }
    let files = src_files(&root);
    assert!(
        files.len() > 50,
        "too few files under src/: {}",
        files.len()
    );
    for rule in RULES {
        let covered = files
            .iter()
            .filter(|f| rule.scope.iter().any(|s| f.rel.starts_with(s)))
            .count();
        if covered == 0 {
            problems.push(format!("no file in the scope of: {}", rule.claim));
        }
        for v in violations(rule, &files) {
            problems.push(format!("{v}\n    breaks: {}", rule.claim));
        }
    }
    println!(
        "ARCHITECTURE.md: {} invariants, {} checked by scanning {} files",
        stated.len(),
        RULES.len(),
        files.len()
    );
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

/// The scanner itself: comments, strings and test code do not count, paths in groups do.
#[test]
fn the_scanner_sees_code_only() {
    let src = r##"
// wgpu in a comment
/* wgpu in a block /* nested */ comment */
let s = "wgpu in a string \" still";
let r = r#"wgpu in a raw "string""#;
let c = '"'; let d = '\''; let l: &'static str = "x";
use std::{fs, io::Read};
fn f() { crate::render::x(); }
#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests { fn t() { std::fs::read("x"); wgpu::Device; } }
#[cfg(test)]
mod synth;
let w = wgpu_options;
"##;
    let code = blank_non_code(src);
    let words: Vec<String> = idents(&code).into_iter().map(|(_, w)| w).collect();
    assert_eq!(
        words.iter().filter(|w| *w == "wgpu").count(),
        1,
        "{words:?}"
    );
    assert!(
        words.iter().any(|w| w == "static"),
        "a lifetime is code: {words:?}"
    );
    let fs: Vec<_> = paths_after(&code, "std")
        .into_iter()
        .filter(|(_, n)| n.iter().any(|n| n == "fs"))
        .collect();
    assert_eq!(fs.len(), 2, "use std::{{fs, ..}} and std::fs::read");
    let (ranges, mods) = test_items(&code);
    assert_eq!(ranges.len(), 2);
    assert_eq!(mods, vec!["synth".to_owned()]);
    let mut non_test = code.clone();
    for (a, b) in ranges {
        non_test[a..b].iter_mut().for_each(|c| *c = ' ');
    }
    let rest: Vec<String> = idents(&non_test).into_iter().map(|(_, w)| w).collect();
    assert!(
        !rest.iter().any(|w| w == "wgpu"),
        "test code is skipped: {rest:?}"
    );
    assert_eq!(
        paths_after(&non_test, "crate")[0].1,
        vec!["render".to_owned()]
    );
    assert_eq!(
        module_paths("`io::load`, `a::{b, c}`, `std::fs`, `Volume::unit`, `src/io/`"),
        vec!["io::load", "a::b", "a::c", "std::fs"]
    );
}

/// The modules of src/app import each other without a ring: `a -> b` when a file of `a` names
/// `app::b` (or, directly under src/app, `super::b`) outside its tests.
#[test]
fn app_modules_form_no_ring() {
    let files = src_files(&root());
    let app: Vec<&RustFile> = files
        .iter()
        .filter(|f| f.module.first().map(String::as_str) == Some("app") && f.module.len() >= 2)
        .collect();
    let mut modules: Vec<String> = app.iter().map(|f| f.module[1].clone()).collect();
    modules.sort();
    modules.dedup();
    assert!(modules.len() > 20, "too few app modules: {modules:?}");
    let mut edges: std::collections::BTreeMap<String, std::collections::BTreeMap<String, String>> =
        std::collections::BTreeMap::new();
    for f in &app {
        let from = &f.module[1];
        let mut named = paths_after(&f.non_test, "app");
        if f.module.len() == 2 {
            named.extend(paths_after(&f.non_test, "super"));
        }
        for (at, names) in named {
            for to in names {
                if &to != from && modules.contains(&to) {
                    edges
                        .entry(from.clone())
                        .or_default()
                        .entry(to)
                        .or_insert_with(|| format!("{}:{}", f.rel, line_of(&f.non_test, at)));
                }
            }
        }
    }
    // Depth-first search for a back edge.
    fn visit(
        m: &str,
        edges: &std::collections::BTreeMap<String, std::collections::BTreeMap<String, String>>,
        path: &mut Vec<String>,
        done: &mut Vec<String>,
    ) -> Option<Vec<String>> {
        if let Some(i) = path.iter().position(|p| p == m) {
            let mut ring = path[i..].to_vec();
            ring.push(m.to_owned());
            return Some(ring);
        }
        if done.iter().any(|d| d == m) {
            return None;
        }
        path.push(m.to_owned());
        for to in edges.get(m).into_iter().flat_map(|e| e.keys()) {
            if let Some(ring) = visit(to, edges, path, done) {
                return Some(ring);
            }
        }
        path.pop();
        done.push(m.to_owned());
        None
    }
    let mut done = Vec::new();
    for m in &modules {
        if let Some(ring) = visit(m, &edges, &mut Vec::new(), &mut done) {
            let steps: Vec<String> = ring
                .windows(2)
                .map(|w| format!("{} -> {} ({})", w[0], w[1], edges[&w[0]][&w[1]]))
                .collect();
            panic!("src/app imports in a ring:\n  {}", steps.join("\n  "));
        }
    }
    println!(
        "src/app: {} modules, {} imports between them, no ring",
        modules.len(),
        edges.values().map(|e| e.len()).sum::<usize>()
    );
}
