//! `cargo xtask serve`, `cargo xtask build` and `cargo xtask test`: the README's commands. Each
//! installs what is missing (idempotently, on a fresh Debian machine as root with only the Rust
//! toolchain), then serves the web app, builds the site to deploy (dist/), or runs every check
//! CI runs.

use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode};
use std::time::Instant;

const TRUNK_VERSION: &str = "0.21.14";
/// Debian packages the checks need: lavapipe (Vulkan on the CPU) for the GPU tests, Chromium for
/// the browser test, and Orthanc with its DICOMweb plugin (ServeFolders comes with orthanc), the
/// real archive that tests/io/dicomweb_orthanc.rs and tests/browser/pacs.mjs start on a free
/// 127.0.0.1 port, and pydicom (with numpy), which reads back the DICOM Shapecast stores
/// (tests/io/read_back.py).
const APT_PACKAGES: &[&str] = &[
    "mesa-vulkan-drivers",
    "chromium",
    "orthanc",
    "orthanc-dicomweb",
    "python3-pydicom",
    "python3-numpy",
];
const WASM_TARGET: &str = "wasm32-unknown-unknown";

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args.first().map(String::as_str) {
        Some("serve") => serve(&args[1..]),
        Some("build") => setup(Needs {
            web: true,
            apt: false,
            node: true,
        })
        .and_then(|()| build_site()),
        Some("test") => test(&args[1..]),
        Some("setup") => setup(Needs::all()),
        _ => {
            eprintln!(
                "usage: cargo xtask serve [--port N]   build the web app and serve it on 127.0.0.1\n       \
                 cargo xtask build                  build the site to deploy into dist/ (wasm-opt'd)\n       \
                 cargo xtask test [--skip STEP]...   install what is missing and run every check\n       \
                 cargo xtask setup                  only install what is missing\n\
                 steps: fmt, clippy, clippy-wasm, test, web-build, browser, browser-links"
            );
            return ExitCode::from(2);
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("xtask: {e}");
            ExitCode::FAILURE
        }
    }
}

type Result<T = ()> = std::result::Result<T, String>;

fn root() -> PathBuf {
    // xtask/ lives directly under the repository root.
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from("."))
}

fn cargo_bin_dir() -> PathBuf {
    std::env::var_os("CARGO_HOME")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cargo")))
        .unwrap_or_else(|| PathBuf::from("/root/.cargo"))
        .join("bin")
}

/// Runs a command in the repository root, echoing it, and fails if it fails.
fn run(cmd: &mut Command) -> Result {
    eprintln!("xtask: $ {}", show(cmd));
    let status = cmd
        .current_dir(root())
        .status()
        .map_err(|e| format!("could not start `{}`: {e}", show(cmd)))?;
    if status.success() {
        Ok(())
    } else {
        Err(format!("`{}` failed ({status})", show(cmd)))
    }
}

fn show(cmd: &Command) -> String {
    let mut s = cmd.get_program().to_string_lossy().into_owned();
    for a in cmd.get_args() {
        s.push(' ');
        s.push_str(&a.to_string_lossy());
    }
    s
}

/// The stdout of a command, or None if it cannot run or fails.
fn output(program: &str, args: &[&str]) -> Option<String> {
    let out = Command::new(program).args(args).output().ok()?;
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).into_owned())
}

#[derive(Clone, Copy)]
struct Needs {
    web: bool,
    apt: bool,
    node: bool,
}

impl Needs {
    fn all() -> Self {
        Self {
            web: true,
            apt: true,
            node: true,
        }
    }
}

fn setup(needs: Needs) -> Result {
    if needs.web {
        ensure_wasm_target()?;
        ensure_trunk()?;
        ensure_wasm_bindgen()?;
        // Trunk runs cargo with --offline (it must never download), so every crate, including
        // the wasm-only ones, has to be in cargo's cache first.
        run(Command::new("cargo").args(["fetch", "--locked"]))?;
    }
    if needs.apt {
        ensure_apt()?;
    }
    if needs.node {
        ensure_node_modules()?;
    }
    Ok(())
}

fn ensure_wasm_target() -> Result {
    let installed = output("rustup", &["target", "list", "--installed"]).unwrap_or_default();
    if installed.lines().any(|l| l.trim() == WASM_TARGET) {
        return Ok(());
    }
    run(Command::new("rustup").args(["target", "add", WASM_TARGET]))
}

fn ensure_trunk() -> Result {
    let trunk = cargo_bin_dir().join("trunk");
    let version = output(&trunk.to_string_lossy(), &["--version"]).unwrap_or_default();
    if version.split_whitespace().nth(1) == Some(TRUNK_VERSION) {
        return Ok(());
    }
    eprintln!("xtask: installing trunk {TRUNK_VERSION} (several minutes on 2 cores, once)");
    // Trunk's own release profile is fat LTO in one codegen unit: most of its build time, for
    // a tool that only runs cargo and copies files. A plain optimised build instead, without
    // the update check (it asks crates.io; trunk runs offline here).
    run(Command::new("cargo")
        .args(["install", "--locked", &format!("trunk@{TRUNK_VERSION}")])
        .args(["--no-default-features", "--features", "rustls"])
        .env("CARGO_PROFILE_RELEASE_LTO", "false")
        .env("CARGO_PROFILE_RELEASE_CODEGEN_UNITS", "16")
        .env("CARGO_PROFILE_RELEASE_OPT_LEVEL", "2"))
}

/// The wasm-bindgen version Cargo.lock pins; the CLI must match it exactly.
fn locked_wasm_bindgen_version() -> Result<String> {
    let lock = std::fs::read_to_string(root().join("Cargo.lock"))
        .map_err(|e| format!("cannot read Cargo.lock: {e}"))?;
    let mut lines = lock.lines();
    while let Some(line) = lines.next() {
        if line.trim() == "name = \"wasm-bindgen\""
            && let Some(v) = lines
                .next()
                .and_then(|l| l.trim().strip_prefix("version = \""))
        {
            return Ok(v.trim_end_matches('"').to_owned());
        }
    }
    Err("Cargo.lock pins no wasm-bindgen version".to_owned())
}

fn ensure_wasm_bindgen() -> Result {
    let want = locked_wasm_bindgen_version()?;
    let trunk_toml = std::fs::read_to_string(root().join("Trunk.toml")).unwrap_or_default();
    if !trunk_toml.contains(&format!("wasm_bindgen = \"{want}\"")) {
        return Err(format!(
            "Trunk.toml's [tools] wasm_bindgen must be \"{want}\", the version Cargo.lock pins"
        ));
    }
    let bin = cargo_bin_dir().join("wasm-bindgen");
    let have = output(&bin.to_string_lossy(), &["--version"]).unwrap_or_default();
    if have.split_whitespace().nth(1) == Some(want.as_str()) {
        return Ok(());
    }
    eprintln!("xtask: installing wasm-bindgen-cli {want}");
    // Without --locked: the CLI's own lock file may pin crates newer than this toolchain allows.
    run(Command::new("cargo")
        .args(["install", "wasm-bindgen-cli", "--version", &want])
        .env("CARGO_PROFILE_RELEASE_LTO", "false")
        .env("CARGO_PROFILE_RELEASE_CODEGEN_UNITS", "16")
        .env("CARGO_PROFILE_RELEASE_OPT_LEVEL", "2"))
}

fn dpkg_installed(package: &str) -> bool {
    output("dpkg-query", &["-W", "-f=${Status}", package])
        .is_some_and(|s| s.contains("install ok installed"))
}

fn ensure_apt() -> Result {
    let missing: Vec<&str> = APT_PACKAGES
        .iter()
        .copied()
        .filter(|p| !dpkg_installed(p))
        .collect();
    apt_install(&missing)
}

/// Installs Debian packages (as root; otherwise says which to install).
fn apt_install(missing: &[&str]) -> Result {
    if missing.is_empty() {
        return Ok(());
    }
    let is_root = output("id", &["-u"]).is_some_and(|s| s.trim() == "0");
    if !is_root {
        return Err(format!(
            "missing Debian packages {missing:?}; run as root or: sudo apt-get install -y {}",
            missing.join(" ")
        ));
    }
    run(Command::new("apt-get").args(["update", "-q"]))?;
    run(Command::new("apt-get")
        .args(["install", "-y", "-q", "--no-install-recommends"])
        .args(missing)
        .env("DEBIAN_FRONTEND", "noninteractive"))
}

fn ensure_node_modules() -> Result {
    let dir = root().join("tests/browser");
    if ["playwright-core", "pngjs", "binaryen"]
        .iter()
        .all(|m| dir.join("node_modules").join(m).is_dir())
    {
        return Ok(());
    }
    // Node and npm come from Debian like the other packages when the machine has none (a
    // machine with another Node, e.g. NodeSource's, which bundles npm, is left as it is).
    if output("npm", &["--version"]).is_none() {
        apt_install(&["nodejs", "npm"])?;
    }
    // playwright-core never downloads a browser; the test drives Debian's /usr/bin/chromium.
    // binaryen is npm's build of wasm-opt (a working one: Debian's 108 breaks this wasm), used
    // by `cargo xtask build`; it comes from npm like the rest, never a download of its own.
    run(Command::new("npm")
        .args(["ci", "--no-audit", "--no-fund", "--prefix"])
        .arg(&dir))
}

fn serve(args: &[String]) -> Result {
    let mut port = "8080".to_owned();
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--port" => port = it.next().cloned().ok_or("--port needs a number")?,
            other => return Err(format!("unknown argument {other:?}")),
        }
    }
    setup(Needs {
        web: true,
        apt: false,
        node: false,
    })?;
    eprintln!("xtask: building and serving the app at http://127.0.0.1:{port}/ (Ctrl-C to stop)");
    run(Command::new(cargo_bin_dir().join("trunk"))
        .args([
            "serve",
            "--release",
            // Its reload script would be an inline script the page's Content-Security-Policy
            // (rightly) refuses.
            "--no-autoreload",
            "--address",
            "127.0.0.1",
            "--port",
            &port,
        ])
        .env("PATH", path_with_cargo_bin()))
}

fn path_with_cargo_bin() -> std::ffi::OsString {
    let mut paths = vec![cargo_bin_dir()];
    if let Some(p) = std::env::var_os("PATH") {
        paths.extend(std::env::split_paths(&p));
    }
    std::env::join_paths(paths).unwrap_or_default()
}

struct Step {
    name: &'static str,
    run: fn() -> Result,
}

const STEPS: &[Step] = &[
    Step {
        name: "fmt",
        run: || run(Command::new("cargo").args(["fmt", "--all", "--", "--check"])),
    },
    Step {
        name: "clippy",
        run: || {
            run(Command::new("cargo").args([
                "clippy",
                "--workspace",
                "--all-targets",
                "--",
                "-D",
                "warnings",
            ]))
        },
    },
    Step {
        name: "clippy-wasm",
        run: || {
            run(Command::new("cargo").args([
                "clippy",
                "--package",
                "shapecast",
                "--lib",
                "--bins",
                "--target",
                WASM_TARGET,
                "--",
                "-D",
                "warnings",
            ]))
        },
    },
    Step {
        name: "test",
        // CI=true makes a missing GPU adapter or ../shared/data a failure, never a skip.
        run: || run(Command::new("cargo").args(["test", "--workspace"])),
    },
    Step {
        name: "web-build",
        run: build_site,
    },
    Step {
        name: "browser",
        run: || run(Command::new("node").arg("tests/browser/smoke.mjs")),
    },
    Step {
        name: "browser-links",
        run: || run(Command::new("node").arg("tests/browser/links.mjs")),
    },
    Step {
        name: "browser-pacs",
        // Orthanc (installed by setup) serves the built site and the series of ../shared/data.
        run: || run(Command::new("node").arg("tests/browser/pacs.mjs")),
    },
];

/// wasm-opt's flags: the size-oriented level, and the wasm features rustc's wasm32 target
/// emits (wasm-opt refuses instructions of features it was not told about).
const WASM_OPT_ARGS: &[&str] = &[
    "-Os",
    "--enable-bulk-memory",
    "--enable-mutable-globals",
    "--enable-nontrapping-float-to-int",
    "--enable-sign-ext",
    "--enable-reference-types",
    "--enable-multivalue",
];

/// The oldest binaryen that handles this wasm (Debian's 108 breaks it).
const MIN_WASM_OPT: u32 = 120;

/// A wasm-opt that works: npm's binaryen installed for the browser tests, else one on PATH,
/// if its version is at least [`MIN_WASM_OPT`].
fn working_wasm_opt() -> Option<(PathBuf, u32)> {
    let npm = root().join("tests/browser/node_modules/.bin/wasm-opt");
    [npm, PathBuf::from("wasm-opt")]
        .into_iter()
        .find_map(|bin| {
            let text = output(&bin.to_string_lossy(), &["--version"])?;
            // "wasm-opt version 132 (version_132)"
            let version: u32 = text.split_whitespace().nth(2)?.parse().ok()?;
            (version >= MIN_WASM_OPT).then_some((bin, version))
        })
}

/// `trunk build --release`, then wasm-opt on the wasm where a working one is installed (the
/// Subresource Integrity hash trunk wrote for the wasm is updated to match). The result in
/// dist/ is the folder to deploy (README, "Deploy").
fn build_site() -> Result {
    run(Command::new(cargo_bin_dir().join("trunk"))
        .args(["build", "--release"])
        .env("PATH", path_with_cargo_bin()))?;
    let dist = root().join("dist");
    let wasm = std::fs::read_dir(&dist)
        .map_err(|e| format!("cannot list {}: {e}", dist.display()))?
        .flatten()
        .map(|e| e.path())
        .find(|p| p.to_string_lossy().ends_with("_bg.wasm"))
        .ok_or("trunk built no _bg.wasm into dist/")?;
    let before = file_size(&wasm);
    let Some((wasm_opt, version)) = working_wasm_opt() else {
        eprintln!(
            "xtask: no working wasm-opt (binaryen >= {MIN_WASM_OPT}; `cargo xtask setup` installs npm's): the wasm stays unoptimised, {:.2} MB",
            before as f64 / 1e6
        );
        return Ok(());
    };
    let t = Instant::now();
    let optimised = wasm.with_extension("opt.wasm");
    run(Command::new(&wasm_opt)
        .args(WASM_OPT_ARGS)
        .arg(&wasm)
        .arg("-o")
        .arg(&optimised))?;
    std::fs::rename(&optimised, &wasm).map_err(|e| format!("cannot replace the wasm: {e}"))?;
    update_integrity(&dist.join("index.html"), &wasm)?;
    let after = file_size(&wasm);
    eprintln!(
        "xtask: wasm-opt {version} {}: {:.2} MB -> {:.2} MB in {:.0} s",
        WASM_OPT_ARGS[0],
        before as f64 / 1e6,
        after as f64 / 1e6,
        t.elapsed().as_secs_f64()
    );
    Ok(())
}

fn file_size(path: &Path) -> u64 {
    std::fs::metadata(path).map(|m| m.len()).unwrap_or(0)
}

/// Rewrites the `integrity="sha384-..."` of the tag that names `file` in `index`.
fn update_integrity(index: &Path, file: &Path) -> Result {
    use base64::Engine as _;
    use sha2::Digest as _;
    let html = std::fs::read_to_string(index)
        .map_err(|e| format!("cannot read {}: {e}", index.display()))?;
    let name = file
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let bytes = std::fs::read(file).map_err(|e| format!("cannot read {}: {e}", file.display()))?;
    let hash = base64::engine::general_purpose::STANDARD.encode(sha2::Sha384::digest(&bytes));
    let mut out = String::with_capacity(html.len());
    let mut changed = 0;
    for tag in html.split_inclusive('>') {
        if (tag.contains(&format!("/{name}\"")) || tag.contains(&format!("\"{name}\"")))
            && let Some(start) = tag.find("integrity=\"sha384-")
        {
            let value_start = start + "integrity=\"".len();
            let end = tag[value_start..]
                .find('"')
                .map(|e| value_start + e)
                .ok_or("unterminated integrity attribute")?;
            out.push_str(&tag[..value_start]);
            out.push_str(&format!("sha384-{hash}"));
            out.push_str(&tag[end..]);
            changed += 1;
            continue;
        }
        out.push_str(tag);
    }
    if changed == 0 && html.contains("integrity=") && html.contains(&name) {
        return Err(format!(
            "{} names {name} with an integrity hash this step could not find to update",
            index.display()
        ));
    }
    std::fs::write(index, out).map_err(|e| format!("cannot write {}: {e}", index.display()))
}

fn test(args: &[String]) -> Result {
    let mut skip: Vec<String> = Vec::new();
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--skip" => skip.push(it.next().cloned().ok_or("--skip needs a step name")?),
            other => return Err(format!("unknown argument {other:?}")),
        }
    }
    for s in &skip {
        if !STEPS.iter().any(|step| step.name == s) {
            return Err(format!("no step named {s:?}"));
        }
    }
    let t0 = Instant::now();
    setup(Needs::all())?;
    eprintln!("xtask: setup took {:.0} s", t0.elapsed().as_secs_f64());
    let mut passed = 0;
    let mut failed = Vec::new();
    let mut times = Vec::new();
    for step in STEPS {
        if skip.iter().any(|s| s == step.name) {
            eprintln!("xtask: step {} skipped on request (--skip)", step.name);
            continue;
        }
        eprintln!("xtask: === step {} ===", step.name);
        let t = Instant::now();
        let r = (step.run)();
        times.push((step.name, t.elapsed().as_secs_f64()));
        match r {
            Ok(()) => passed += 1,
            Err(e) => {
                eprintln!("xtask: step {} FAILED: {e}", step.name);
                failed.push(step.name);
            }
        }
    }
    for (name, secs) in &times {
        eprintln!("xtask: {name:<12} {secs:>7.1} s");
    }
    eprintln!("xtask: total {:.0} s", t0.elapsed().as_secs_f64());
    if !skip.is_empty() {
        eprintln!("xtask: skipped on request: {}", skip.join(", "));
    }
    println!("steps: {passed} passed, {} failed", failed.len());
    if failed.is_empty() {
        Ok(())
    } else {
        Err(format!("failed steps: {}", failed.join(", ")))
    }
}
