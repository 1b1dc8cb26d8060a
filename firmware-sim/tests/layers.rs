//! The twin's layers, read from the sources: `model` (the pure core) reaches nothing above it and
//! no clock, runtime or transport; `nav` imports only `model` and, of vtol-link, its text files
//! (the parameter and mission files); `endpoint` never reaches the `shell` or tokio.

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

/// What `nav` may import: these rooms of the twin, and these modules of vtol-link.
const NAV_MAY_IMPORT: (&[&str], &[&str]) = (&["model", "nav"], &["text_file"]);

/// Every `PREFIX::NAME` on a line, with the name.
fn paths_named<'a>(code: &'a str, prefix: &str) -> Vec<&'a str> {
    let mut found = Vec::new();
    let mut rest = code;
    while let Some(i) = rest.find(prefix) {
        let after = &rest[i + prefix.len()..];
        let end = after
            .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
            .unwrap_or(after.len());
        found.push(&after[..end]);
        rest = after;
    }
    found
}

/// Inside the model, plant and sensors take their inputs from `signals` and never import the
/// controller or the vehicle that drive them; the controller never imports the vehicle.
#[test]
fn the_model_has_no_circle() {
    let mut v = Vec::new();
    for room in ["model/plant", "model/sensors.rs", "model/signals.rs"] {
        v.extend(violations(
            room,
            &[
                "crate::model::control",
                "crate::model::vehicle",
                "crate::model::estimator",
            ],
        ));
    }
    v.extend(violations("model/control", &["crate::model::vehicle"]));
    assert!(v.is_empty(), "{}", v.join("\n"));
}

#[test]
fn the_navigator_sits_on_the_core_only() {
    let (rooms, link_modules) = NAV_MAY_IMPORT;
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("src")
        .join("nav");
    let mut found = violations("nav", &["tokio", "Instant::now"]);
    for entry in WalkDir::new(&dir) {
        let file = entry.expect("directory entry").into_path();
        if file.extension().is_none_or(|e| e != "rs") {
            continue;
        }
        let text = std::fs::read_to_string(&file).expect("source file");
        for (n, line) in text.lines().enumerate() {
            let code = line.trim_start();
            if code.starts_with("//") {
                continue;
            }
            for room in paths_named(code, "crate::") {
                if !rooms.contains(&room) {
                    found.push(format!("{}:{}: crate::{room}", file.display(), n + 1));
                }
            }
            for module in paths_named(code, "vtol_link::") {
                if !link_modules.contains(&module) {
                    found.push(format!("{}:{}: vtol_link::{module}", file.display(), n + 1));
                }
            }
            // `use vtol_link;` or `vtol_link::{..}` would hide what is imported.
            if code.contains("vtol_link") && paths_named(code, "vtol_link::").is_empty() {
                found.push(format!("{}:{}: vtol_link", file.display(), n + 1));
            }
        }
    }
    assert!(found.is_empty(), "{}", found.join("\n"));
}

#[test]
fn the_import_reader_sees_each_path() {
    let line = "use crate::model::x; let e = crate::shell::y(vtol_link::text_file::read_text(p));";
    assert_eq!(paths_named(line, "crate::"), ["model", "shell"]);
    assert_eq!(paths_named(line, "vtol_link::"), ["text_file"]);
    assert_eq!(paths_named("vtol_link::{a, b}", "vtol_link::"), [""]);
}

/// `serve` starts the vehicle loop; the loop takes what they share (the radio) from `radio`,
/// never from `serve`.
#[test]
fn the_vehicle_loop_never_imports_the_server() {
    let v = violations(
        "shell/vehicle_loop.rs",
        &["crate::shell::serve", "super::serve"],
    );
    assert!(v.is_empty(), "{}", v.join("\n"));
}

#[test]
fn the_endpoint_never_reaches_the_shell() {
    let v = violations("endpoint", &["crate::shell", "tokio::", "Instant::now"]);
    assert!(v.is_empty(), "{}", v.join("\n"));
}
