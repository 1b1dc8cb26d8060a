//! The import rules of the frame path, read from the sources: the consumers of frames (the
//! tracker, the client, the terminal UI, the status line) share the `tap` and `trust` rooms with
//! the router and never reach into the router itself.

use std::path::Path;

use walkdir::WalkDir;

/// Every `crate::ROOM` and `vtol_gcs::ROOM` a file names, with its line number.
fn rooms_named(text: &str) -> Vec<(usize, String)> {
    let mut found = Vec::new();
    for (n, line) in text.lines().enumerate() {
        for prefix in ["crate::", "vtol_gcs::"] {
            let mut rest = line;
            while let Some(i) = rest.find(prefix) {
                let after = &rest[i + prefix.len()..];
                let room: String = after
                    .chars()
                    .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                    .collect();
                if !room.is_empty() {
                    found.push((n + 1, room));
                }
                rest = after;
            }
        }
    }
    found
}

#[test]
fn consumers_of_frames_never_import_the_router() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    for room in ["tracker", "client", "tui", "tap", "trust"] {
        let walk = WalkDir::new(src.join(room)).into_iter();
        files.extend(
            walk.map(|e| e.expect("directory entry").into_path())
                .filter(|p| p.extension().is_some_and(|e| e == "rs")),
        );
    }
    files.push(src.join("status.rs"));
    files.push(src.join("stream_fit.rs"));
    assert!(files.len() > 10, "the rooms moved: {files:?}");
    let mut broken = Vec::new();
    for file in &files {
        let text = std::fs::read_to_string(file).expect("source file");
        for (line, room) in rooms_named(&text) {
            if room == "router" {
                broken.push(format!("{}:{line} names crate::router", file.display()));
            }
        }
    }
    assert!(broken.is_empty(), "{}", broken.join("\n"));
}

#[test]
fn the_rule_reader_sees_both_spellings() {
    let found = rooms_named("use crate::router::Router; let x = vtol_gcs::tap::clock();");
    assert_eq!(
        found,
        vec![(1, "router".to_owned()), (1, "tap".to_owned())],
        "a rule the reader cannot see is no rule"
    );
}
