//! Guards the one-way layering that `src/lib.rs` and `crates/core/src/lib.rs` document.
//! Across crates Cargo enforces the direction (navguard-core names neither navguard-sim
//! nor navguard; navguard-sim does not name navguard); this test checks what Cargo
//! cannot: inside navguard-core each layer of `simd.rs, epoch.rs, geo/, detect/, gnss/,
//! strapdown/, filter/, learn/, features/, monitor/, session/` imports none after it;
//! navguard-core and navguard-sim (and navguard-formats) depend on no async, storage or
//! HTTP crate, and navguard-core on no plotting crate; and only the CLI's `experiment`
//! commands reach into `navguard_sim::experiment` (the rest of the CLI and the service
//! use `navguard_sim` and its `plot`). Test code (after a file's first `#[cfg(test)]`, and
//! files that are whole test modules) may cross layers.

use std::fs;
use std::path::{Path, PathBuf};

/// The layers of `crates/core/src/lib.rs`, in order: production code of each may use the
/// ones before it, never one after it (docs/architecture.md §A1).
const LAYERS: &[(&str, &str)] = &[
    ("crates/core/src/simd.rs", "simd"),
    ("crates/core/src/epoch.rs", "epoch"),
    ("crates/core/src/geo", "geo"),
    ("crates/core/src/detect", "detect"),
    ("crates/core/src/gnss", "gnss"),
    ("crates/core/src/strapdown", "strapdown"),
    ("crates/core/src/filter", "filter"),
    ("crates/core/src/learn", "learn"),
    ("crates/core/src/features", "features"),
    ("crates/core/src/monitor", "monitor"),
    ("crates/core/src/session", "session"),
];

/// Each further rule: the folders (or files), from the workspace root, it covers and the
/// paths they may not use.
const RULES: &[(&[&str], &[&str])] = &[(
    &[
        "src/service",
        "src/cli/mod.rs",
        "src/cli/calibrate.rs",
        "src/cli/convert.rs",
        "src/cli/http.rs",
        "src/cli/loadgen.rs",
        "src/cli/loadgen",
        "src/cli/replay",
        "src/cli/simulate.rs",
    ],
    &["navguard_sim::experiment"],
)];

/// The crates (by their `Cargo.toml`) that may not depend on the listed packages: the core,
/// the simulator and the file readers stay synchronous and offline, and only the
/// simulator plots.
const DEPENDENCY_RULES: &[(&str, &[&str])] = &[
    (
        "crates/core/Cargo.toml",
        &[
            "tokio",
            "axum",
            "sqlx",
            "tower",
            "tower-http",
            "reqwest",
            "hyper",
            "async-nats",
            "navguard",
            "navguard-sim",
            "plotters",
        ],
    ),
    (
        "crates/sim/Cargo.toml",
        &[
            "tokio",
            "axum",
            "sqlx",
            "tower",
            "tower-http",
            "reqwest",
            "hyper",
            "async-nats",
            "navguard",
        ],
    ),
    (
        "crates/formats/Cargo.toml",
        &[
            "tokio",
            "axum",
            "sqlx",
            "tower",
            "tower-http",
            "reqwest",
            "hyper",
            "async-nats",
            "navguard",
            "navguard-sim",
            "plotters",
        ],
    ),
];

/// Every rule: each layer against the layers after it, then [`RULES`].
fn rules() -> Vec<(Vec<&'static str>, Vec<String>)> {
    let mut rules: Vec<(Vec<&'static str>, Vec<String>)> = LAYERS
        .iter()
        .enumerate()
        .map(|(i, (root, _))| {
            let later = LAYERS[i + 1..].iter().map(|(_, m)| format!("crate::{m}"));
            (vec![*root], later.collect())
        })
        .collect();
    for (roots, forbidden) in RULES {
        let forbidden = forbidden.iter().map(|f| (*f).to_owned()).collect();
        rules.push((roots.to_vec(), forbidden));
    }
    rules
}

/// The package names in the `[dependencies]` table of a `Cargo.toml` (`name = ...` and
/// `name.workspace = true` lines; dev-dependencies may cross layers, like test code).
fn dependencies(manifest: &str) -> Vec<String> {
    let mut in_deps = false;
    let mut names = Vec::new();
    for line in manifest.lines() {
        let line = line.trim();
        if line.starts_with('[') {
            in_deps = line == "[dependencies]";
        } else if in_deps && !line.is_empty() && !line.starts_with('#') {
            let name = line.split(['=', '.', ' ']).next().unwrap_or("");
            names.push(name.trim().to_owned());
        }
    }
    names
}

fn rust_files(path: &Path, out: &mut Vec<PathBuf>) {
    if path.is_dir() {
        let mut entries: Vec<_> = fs::read_dir(path)
            .expect("read src dir")
            .map(|e| e.expect("dir entry").path())
            .collect();
        entries.sort();
        for entry in entries {
            rust_files(&entry, out);
        }
    } else if path.extension().is_some_and(|e| e == "rs") {
        out.push(path.to_path_buf());
    }
}

/// A file's production code: everything before its first `#[cfg(test)]`, or nothing
/// when the file itself is a test module (`tests.rs`, `*_tests.rs`).
fn production_code(path: &Path) -> String {
    let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
    if name == "tests.rs" || name.ends_with("_tests.rs") {
        return String::new();
    }
    let text = fs::read_to_string(path).expect("read source file");
    match text.find("#[cfg(test)]") {
        Some(i) => text[..i].to_owned(),
        None => text,
    }
}

/// The lines of `code` that name one of `forbidden` outside comments.
fn offending_lines(code: &str, forbidden: &[&str]) -> Vec<String> {
    code.lines()
        .enumerate()
        .filter(|(_, line)| {
            let code_part = line.split("//").next().unwrap_or("");
            forbidden.iter().any(|f| {
                code_part.contains(&format!("{f}::"))
                    || code_part.contains(&format!("{f}}}"))
                    || code_part.contains(&format!("{f};"))
                    || (f.ends_with("::") && code_part.contains(f))
            })
        })
        .map(|(i, line)| format!("{}: {}", i + 1, line.trim()))
        .collect()
}

#[test]
fn lower_layers_never_import_upper_layers() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut violations = Vec::new();
    for (roots, forbidden) in rules() {
        let forbidden: Vec<&str> = forbidden.iter().map(String::as_str).collect();
        for root in roots {
            let mut files = Vec::new();
            rust_files(&src.join(root), &mut files);
            assert!(!files.is_empty(), "no Rust files under {root}");
            for file in files {
                for line in offending_lines(&production_code(&file), &forbidden) {
                    violations.push(format!(
                        "{}:{line}",
                        file.strip_prefix(src).unwrap_or(&file).display()
                    ));
                }
            }
        }
    }
    assert!(
        violations.is_empty(),
        "layering broken (see crates/core/src/lib.rs # Layout):\n{}",
        violations.join("\n")
    );
}

#[test]
fn the_core_and_the_simulator_stay_synchronous() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut violations = Vec::new();
    for (manifest, forbidden) in DEPENDENCY_RULES {
        let text = fs::read_to_string(root.join(manifest)).expect("read Cargo.toml");
        let deps = dependencies(&text);
        assert!(!deps.is_empty(), "no [dependencies] in {manifest}");
        for dep in deps {
            if forbidden.contains(&dep.as_str()) {
                violations.push(format!("{manifest}: {dep}"));
            }
        }
    }
    assert!(
        violations.is_empty(),
        "layering broken:\n{}",
        violations.join("\n")
    );
}

#[test]
fn the_checker_sees_an_upward_import() {
    let code = "use crate::detect::Health;\nuse crate::monitor::Epoch; // up\n";
    assert_eq!(
        offending_lines(code, &["crate::monitor"]),
        vec!["2: use crate::monitor::Epoch; // up".to_owned()]
    );
    assert!(offending_lines("// see crate::monitor::x\n", &["crate::monitor"]).is_empty());
    assert_eq!(
        offending_lines("let t = tokio::spawn(f);\n", &["tokio"]).len(),
        1,
        "a bare crate path is caught"
    );
    assert_eq!(
        dependencies(
            "[dependencies]\ntokio = \"1\"\nserde.workspace = true\n[dev-dependencies]\nx = \"1\"\n"
        ),
        vec!["tokio".to_owned(), "serde".to_owned()]
    );
}
