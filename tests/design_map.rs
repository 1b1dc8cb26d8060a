//! docs/design.md is the map as built: every repository path it names in backticks exists, and
//! every Rust item it names (`tap::queue`, `App::observe`, `RebootsSeen`) is defined in the
//! sources. A path is either from the repository's root (`src/tui/map.rs`) or the tail of one
//! that exists, as a crate's table names its rooms (`tui/app/`, `guided.rs`). An item is checked
//! by its kind: a type by `struct|enum|trait|type NAME`, a module by `mod NAME`, a function by
//! `fn NAME`, a variant or constant after its type by the word. Code blocks are diagrams and
//! are not read.

use std::path::{Path, PathBuf};

use walkdir::WalkDir;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The source and document trees a path or item may name.
const TREES: [&str; 11] = [
    "src",
    "link",
    "firmware-sim",
    "tests",
    "benches",
    "fuzz",
    "python",
    "docs",
    "config",
    "assets",
    ".ci",
];

/// Names the map uses from other crates, which the sources use but do not define.
const EXTERNAL: [&str; 3] = ["JoinSet", "MessageData", "Debug"];

/// The code spans of a document's prose (outside fenced code blocks), with their line numbers.
fn code_spans(text: &str) -> Vec<(usize, String)> {
    let mut in_fence = false;
    let mut spans = Vec::new();
    for (n, line) in text.lines().enumerate() {
        if line.trim_start().starts_with("```") {
            in_fence = !in_fence;
            continue;
        }
        if in_fence {
            continue;
        }
        let mut parts = line.split('`');
        parts.next();
        while let (Some(span), Some(_)) = (parts.next(), parts.next()) {
            spans.push((n + 1, span.to_owned()));
        }
    }
    spans
}

/// Whether a span is a repository path: no spaces, a folder or a file with an extension of ours.
fn is_path(span: &str) -> bool {
    !span.contains(char::is_whitespace)
        && !span.starts_with(['-', '/', '.'])
        && !span.contains("::")
        && !span.contains(':')
        && (span.contains('/')
            || [".rs", ".md", ".toml", ".sh", ".py"]
                .iter()
                .any(|e| span.ends_with(e)))
}

fn is_ident(s: &str) -> bool {
    let mut chars = s.chars();
    chars
        .next()
        .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
        && chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
}

fn is_type_name(s: &str) -> bool {
    s.starts_with(|c: char| c.is_ascii_uppercase()) && s.chars().any(|c| c.is_ascii_lowercase())
}

/// The segments of a Rust path a span names (`vtol_link::{SystemId, ComponentId}` gives both
/// paths), without a call's arguments; `None` when the span is no Rust path.
fn rust_paths(span: &str) -> Option<Vec<Vec<String>>> {
    let span = match span.find('(') {
        Some(i) if span.ends_with(')') => &span[..i],
        _ => span,
    };
    let (head, group) = match span.find("::{") {
        Some(i) if span.ends_with('}') => (&span[..i], Some(&span[i + 3..span.len() - 1])),
        _ => (span, None),
    };
    let head: Vec<String> = head.split("::").map(str::to_owned).collect();
    if !head.iter().all(|s| is_ident(s)) {
        return None;
    }
    let paths = match group {
        Some(g) => {
            let tails: Vec<&str> = g.split(',').map(str::trim).collect();
            if !tails.iter().all(|t| is_ident(t)) {
                return None;
            }
            tails
                .iter()
                .map(|t| {
                    let mut p = head.clone();
                    p.push((*t).to_owned());
                    p
                })
                .collect()
        }
        None => vec![head],
    };
    let named = paths[0].len() > 1 || is_type_name(&paths[0][0]);
    named.then_some(paths)
}

/// Every file and folder of the trees, relative to the root, with `/` separators.
fn repository_paths(root: &Path) -> Vec<String> {
    let mut out = Vec::new();
    for tree in TREES {
        for entry in WalkDir::new(root.join(tree))
            .into_iter()
            .filter_entry(|e| e.file_name() != "target" && e.file_name() != "__pycache__")
        {
            let entry = entry.expect("directory entry");
            let rel = entry.path().strip_prefix(root).expect("under the root");
            out.push(rel.to_string_lossy().replace('\\', "/"));
        }
    }
    out
}

fn path_exists(span: &str, root: &Path, all: &[String]) -> bool {
    let bare = span.trim_end_matches('/');
    root.join(bare).exists() || all.iter().any(|p| p.ends_with(&format!("/{bare}")))
}

/// Whether `text` holds `keyword NAME` with NAME ending at a word boundary.
fn defines(text: &str, keywords: &[&str], name: &str) -> bool {
    keywords.iter().any(|kw| {
        let needle = format!("{kw} {name}");
        text.match_indices(&needle).any(|(i, _)| {
            let before = text[..i].chars().next_back();
            let after = text[i + needle.len()..].chars().next();
            !before.is_some_and(|c| c.is_ascii_alphanumeric() || c == '_')
                && !after.is_some_and(|c| c.is_ascii_alphanumeric() || c == '_')
        })
    })
}

fn has_word(text: &str, name: &str) -> bool {
    defines(text, &[""], name) || text.contains(&format!("::{name}")) || {
        text.match_indices(name).any(|(i, _)| {
            let before = text[..i].chars().next_back();
            let after = text[i + name.len()..].chars().next();
            !before.is_some_and(|c| c.is_ascii_alphanumeric() || c == '_')
                && !after.is_some_and(|c| c.is_ascii_alphanumeric() || c == '_')
        })
    }
}

/// Why a Rust path names nothing defined, if it does not.
fn missing_item(path: &[String], sources: &str) -> Option<String> {
    const CRATES: [&str; 6] = [
        "crate",
        "vtol_gcs",
        "vtol_link",
        "firmware_sim",
        "self",
        "super",
    ];
    let mut after_type = false;
    for (i, seg) in path.iter().enumerate() {
        if i == 0 && CRATES.contains(&seg.as_str()) {
            continue;
        }
        let found = if EXTERNAL.contains(&seg.as_str()) {
            true
        } else if after_type {
            defines(sources, &["fn", "const"], seg) || has_word(sources, seg)
        } else if seg.starts_with(|c: char| c.is_ascii_uppercase()) {
            defines(sources, &["struct", "enum", "trait", "type", "union"], seg)
        } else {
            defines(sources, &["mod"], seg)
        };
        if !found {
            return Some(seg.clone());
        }
        after_type = seg.starts_with(|c: char| c.is_ascii_uppercase());
    }
    None
}

/// The text of every Rust source in the trees, joined.
fn all_sources(root: &Path, all: &[String]) -> String {
    let mut text = String::new();
    for p in all.iter().filter(|p| p.ends_with(".rs")) {
        text.push_str(&std::fs::read_to_string(root.join(p)).expect("source file"));
        text.push('\n');
    }
    text
}

#[test]
fn every_path_and_item_the_design_map_names_exists() {
    let root = root();
    let doc = std::fs::read_to_string(root.join("docs/design.md")).expect("docs/design.md");
    let all = repository_paths(&root);
    let sources = all_sources(&root, &all);
    let mut broken = Vec::new();
    let (mut paths, mut items) = (0, 0);
    for (line, span) in code_spans(&doc) {
        if is_path(&span) {
            paths += 1;
            if !path_exists(&span, &root, &all) {
                broken.push(format!("docs/design.md:{line}: no path `{span}`"));
            }
        } else if let Some(rust) = rust_paths(&span) {
            for path in rust {
                items += 1;
                if let Some(seg) = missing_item(&path, &sources) {
                    broken.push(format!(
                        "docs/design.md:{line}: `{span}`: nothing defines `{seg}`"
                    ));
                }
            }
        }
    }
    assert!(
        paths > 30 && items > 20,
        "the reader found {paths} paths and {items} items"
    );
    assert!(broken.is_empty(), "{}", broken.join("\n"));
}

#[test]
fn the_reader_tells_paths_from_items_and_misses_a_wrong_one() {
    assert!(is_path("src/tui/map.rs") && is_path("tui/app/") && is_path("guided.rs"));
    assert!(!is_path("//!") && !is_path("--serve") && !is_path("replay:FILE"));
    assert_eq!(
        rust_paths("vtol_link::{SystemId, ComponentId}"),
        Some(vec![
            vec!["vtol_link".to_owned(), "SystemId".to_owned()],
            vec!["vtol_link".to_owned(), "ComponentId".to_owned()],
        ])
    );
    assert_eq!(
        rust_paths("Vehicle::step(dt)"),
        Some(vec![vec!["Vehicle".to_owned(), "step".to_owned()]])
    );
    assert_eq!(rust_paths("ARMED"), None);
    assert_eq!(rust_paths("router"), None);
    let sources = "pub struct App;\nimpl App { pub fn observe(&self) {} }\npub mod tap;\n";
    let path = |s: &str| rust_paths(s).unwrap().remove(0);
    assert_eq!(missing_item(&path("App::observe"), sources), None);
    assert_eq!(missing_item(&path("crate::tap"), sources), None);
    assert_eq!(
        missing_item(&path("App::draw"), sources),
        Some("draw".to_owned())
    );
    assert_eq!(
        missing_item(&path("Apps"), sources),
        Some("Apps".to_owned())
    );
    let root = root();
    let all = repository_paths(&root);
    assert!(path_exists("tui/app/", &root, &all));
    assert!(!path_exists("tui/exec.rs", &root, &all));
}
