//! The twin's layers, read from the sources: `model` (the pure core) reaches nothing above it and
//! no clock, runtime or transport; `nav` reaches only `model`; `endpoint` never reaches the
//! `shell` or tokio.

use std::path::{Path, PathBuf};

use walkdir::WalkDir;

/// Lines of the files under `layer` that name one of `forbidden`.
fn violations(layer: &str, forbidden: &[&str]) -> Vec<String> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("src")
        .join(layer);
    let files: Vec<PathBuf> = WalkDir::new(&dir)
        .into_iter()
        .map(|e| e.expect("directory entry").into_path())
        .filter(|p| p.extension().is_some_and(|e| e == "rs"))
        .collect();
    assert!(!files.is_empty(), "no layer {layer}");
    let mut found = Vec::new();
    for file in files {
        let text = std::fs::read_to_string(&file).expect("source file");
        for (n, line) in text.lines().enumerate() {
            // Doc comments may point at other layers; code may not.
            let code = line.trim_start();
            if code.starts_with("//") {
                continue;
            }
            for f in forbidden {
                if code.contains(f) {
                    found.push(format!("{}:{}: {f}", file.display(), n + 1));
                }
            }
        }
    }
    found
}

#[test]
fn the_core_is_pure() {
    let v = violations(
        "model",
        &[
            "crate::nav",
            "crate::endpoint",
            "crate::shell",
            "crate::atomic_file",
            "tokio",
            "vtol_link",
            "Instant::now",
            "SystemTime",
            "std::fs",
            "std::net",
        ],
    );
    assert!(v.is_empty(), "{}", v.join("\n"));
}

#[test]
fn the_navigator_sits_on_the_core_only() {
    let v = violations(
        "nav",
        &[
            "crate::endpoint",
            "crate::shell",
            "tokio",
            "vtol_link",
            "Instant::now",
        ],
    );
    assert!(v.is_empty(), "{}", v.join("\n"));
}

#[test]
fn the_endpoint_never_reaches_the_shell() {
    let v = violations("endpoint", &["crate::shell", "tokio::", "Instant::now"]);
    assert!(v.is_empty(), "{}", v.join("\n"));
}
