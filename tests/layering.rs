//! Guards the one-way layering that `src/lib.rs` documents: the numerical core
//! (`epoch.rs`, `geo/ filter/ detect/ learn/ features/`) imports nothing above it,
//! `monitor/` imports neither the simulator nor the service nor the CLI, no layer
//! below `service/` touches the async or storage crates, nothing before `sim/` plots,
//! and only the CLI's `experiment` command reaches into `sim::experiment` (the rest
//! of the CLI and the service use `sim` and its `plot`). Test code (after a file's first
//! `#[cfg(test)]`, and files that are whole test modules) may cross layers.

use std::fs;
use std::path::{Path, PathBuf};

/// Each rule: the folders (or files) under `src/` it covers and the paths they may not use.
const RULES: &[(&[&str], &[&str])] = &[
    (
        &[
            "simd.rs", "epoch.rs", "geo", "filter", "detect", "learn", "features",
        ],
        &[
            "crate::monitor",
            "crate::sim",
            "crate::service",
            "crate::cli",
            "navguard::",
        ],
    ),
    (
        &["monitor"],
        &["crate::sim", "crate::service", "crate::cli", "navguard::"],
    ),
    (
        &[
            "simd.rs", "epoch.rs", "geo", "filter", "detect", "learn", "features", "monitor", "sim",
        ],
        &["tokio", "axum", "sqlx", "tower", "reqwest"],
    ),
    (
        &[
            "simd.rs", "epoch.rs", "geo", "filter", "detect", "learn", "features", "monitor",
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
    for (roots, forbidden) in RULES {
        for root in *roots {
            let mut files = Vec::new();
            rust_files(&src.join(root), &mut files);
            assert!(!files.is_empty(), "no Rust files under src/{root}");
            for file in files {
                for line in offending_lines(&production_code(&file), forbidden) {
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
