//! Guards the one-way layering that `src/lib.rs` documents: each layer of `simd.rs,
//! epoch.rs, geo/, detect/, filter/, learn/, features/, monitor/, session/, sim/,
//! service/` imports none after it, no layer below `service/` touches the async or
//! storage crates or the CLI, nothing before `sim/` plots,
//! and only the CLI's `experiment` command reaches into `sim::experiment` (the rest
//! of the CLI and the service use `sim` and its `plot`). Test code (after a file's first
//! `#[cfg(test)]`, and files that are whole test modules) may cross layers.

use std::fs;
use std::path::{Path, PathBuf};

/// The layers of `src/lib.rs`, in order: production code of each may use the ones before
/// it, never one after it (docs/architecture.md §A1).
const LAYERS: &[(&str, &str)] = &[
    ("simd.rs", "simd"),
    ("epoch.rs", "epoch"),
    ("geo", "geo"),
    ("detect", "detect"),
    ("filter", "filter"),
    ("learn", "learn"),
    ("features", "features"),
    ("monitor", "monitor"),
    ("session", "session"),
    ("sim", "sim"),
    ("service", "service"),
];

/// Each further rule: the folders (or files) under `src/` it covers and the paths they
/// may not use.
const RULES: &[(&[&str], &[&str])] = &[
    (
        &[
            "simd.rs", "epoch.rs", "geo", "detect", "filter", "learn", "features", "monitor",
            "session", "sim",
        ],
        &[
            "tokio",
            "axum",
            "sqlx",
            "tower",
            "reqwest",
            "navguard::",
            "crate::cli",
        ],
    ),
    (
        &[
            "simd.rs", "epoch.rs", "geo", "detect", "filter", "learn", "features", "monitor",
            "session",
        ],
        &["plotters"],
    ),
    (
        &[
            "service",
            "cli/mod.rs",
            "cli/calibrate.rs",
            "cli/http.rs",
            "cli/loadgen.rs",
            "cli/loadgen",
            "cli/replay",
            "cli/simulate.rs",
        ],
        &["crate::sim::experiment", "navguard::sim::experiment"],
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
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut violations = Vec::new();
    for (roots, forbidden) in rules() {
        let forbidden: Vec<&str> = forbidden.iter().map(String::as_str).collect();
        for root in roots {
            let mut files = Vec::new();
            rust_files(&src.join(root), &mut files);
            assert!(!files.is_empty(), "no Rust files under src/{root}");
            for file in files {
                for line in offending_lines(&production_code(&file), &forbidden) {
                    violations.push(format!(
                        "{}:{line}",
                        file.strip_prefix(&src).unwrap_or(&file).display()
                    ));
                }
            }
        }
    }
    assert!(
        violations.is_empty(),
        "layering broken (see src/lib.rs # Layout):\n{}",
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
}
