//! The documents' links hold: every relative link in README.md, BENCHMARKS.md and docs/**/*.md
//! names a file or folder that exists, and every `#anchor` names a heading of its target (the
//! slug GitHub gives it). Links in code blocks and code spans are text, not links; links with a
//! scheme (`https:`, `mailto:`) are left to the reader.

use std::collections::HashSet;
use std::path::{Path, PathBuf};

use walkdir::WalkDir;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The lines of a document outside fenced code blocks, with their line numbers.
fn prose_lines(text: &str) -> Vec<(usize, &str)> {
    let mut fence: Option<&str> = None;
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let trimmed = line.trim_start();
        match fence {
            Some(marker) => {
                if trimmed.starts_with(marker) {
                    fence = None;
                }
            }
            None if trimmed.starts_with("```") => fence = Some("```"),
            None if trimmed.starts_with("~~~") => fence = Some("~~~"),
            None => out.push((n + 1, line)),
        }
    }
    out
}

/// The prose lines with their code spans blanked out, so that a link written in backticks is
/// not one. A code span may run on over a line break; a blank line ends the paragraph, and
/// with it any span left open.
fn without_code_spans<'a>(
    lines: impl IntoIterator<Item = (usize, &'a str)>,
) -> Vec<(usize, String)> {
    let mut in_code = false;
    let mut out = Vec::new();
    for (n, line) in lines {
        if line.trim().is_empty() {
            in_code = false;
        }
        let blanked: String = line
            .chars()
            .map(|c| {
                if c == '`' {
                    in_code = !in_code;
                    ' '
                } else if in_code {
                    ' '
                } else {
                    c
                }
            })
            .collect();
        out.push((n, blanked));
    }
    out
}

/// The targets of the inline links and images of one line, code spans already blanked out:
/// `[text](target "title")`.
fn link_targets(line: &str) -> Vec<String> {
    let mut targets = Vec::new();
    let mut rest = line;
    while let Some(i) = rest.find("](") {
        let after = &rest[i + 2..];
        // The target ends at the parenthesis that closes the one the link opened.
        let mut depth = 1;
        let mut end = None;
        for (j, c) in after.char_indices() {
            match c {
                '(' => depth += 1,
                ')' => {
                    depth -= 1;
                    if depth == 0 {
                        end = Some(j);
                        break;
                    }
                }
                _ => {}
            }
        }
        let Some(end) = end else { break };
        let inside = after[..end].trim();
        let target = match inside.strip_prefix('<') {
            Some(angled) => angled.split('>').next().unwrap_or(""),
            None => inside.split_whitespace().next().unwrap_or(""),
        };
        targets.push(target.to_owned());
        rest = &after[end..];
    }
    // Reference definitions: `[name]: target`.
    let trimmed = line.trim_start();
    if trimmed.starts_with('[')
        && let Some(i) = trimmed.find("]:")
        && let Some(target) = trimmed[i + 2..].split_whitespace().next()
    {
        targets.push(target.to_owned());
    }
    targets
}

/// GitHub's anchor for a heading's text: lower case, spaces to hyphens, everything that is not
/// a letter, a digit, `-` or `_` dropped (code spans, emphasis and link syntax with it).
fn slug(heading: &str) -> String {
    // A link in a heading reads as its text.
    let mut text = String::new();
    let mut rest = heading;
    while let Some(i) = rest.find("](") {
        text.push_str(&rest[..i]);
        let after = &rest[i + 2..];
        rest = after.find(')').map_or("", |j| &after[j + 1..]);
    }
    text.push_str(rest);
    text.trim()
        .to_lowercase()
        .chars()
        .filter_map(|c| match c {
            ' ' => Some('-'),
            c if c.is_alphanumeric() || c == '-' || c == '_' => Some(c),
            _ => None,
        })
        .collect()
}

/// Every anchor a document's headings make, with GitHub's `-1`, `-2` … for repeats.
fn anchors(text: &str) -> HashSet<String> {
    let mut seen = HashSet::new();
    for (_, line) in prose_lines(text) {
        let hashes = line.chars().take_while(|&c| c == '#').count();
        if !(1..=6).contains(&hashes) || !line[hashes..].starts_with(' ') {
            continue;
        }
        let base = slug(line[hashes..].trim().trim_end_matches('#'));
        let mut anchor = base.clone();
        let mut n = 0;
        while seen.contains(&anchor) {
            n += 1;
            anchor = format!("{base}-{n}");
        }
        seen.insert(anchor);
    }
    seen
}

/// What is wrong with the links of one document, one line each.
fn broken_links(file: &Path) -> Vec<String> {
    let text = std::fs::read_to_string(file).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
    let dir = file.parent().expect("a document lives in a folder");
    let shown = file
        .strip_prefix(root())
        .unwrap_or(file)
        .display()
        .to_string();
    let mut broken = Vec::new();
    for (n, line) in without_code_spans(prose_lines(&text)) {
        for target in link_targets(&line) {
            if target.is_empty() || target.contains("://") || target.starts_with("mailto:") {
                continue;
            }
            let (path, anchor) = match target.split_once('#') {
                Some((path, anchor)) => (path, Some(anchor)),
                None => (target.as_str(), None),
            };
            let resolved = if path.is_empty() {
                file.to_path_buf()
            } else {
                dir.join(path)
            };
            if !resolved.exists() {
                broken.push(format!("{shown}:{n}: {target}: no such file"));
                continue;
            }
            let Some(anchor) = anchor else { continue };
            if resolved.extension().is_none_or(|e| e != "md") {
                broken.push(format!(
                    "{shown}:{n}: {target}: an anchor into a file that is not markdown"
                ));
                continue;
            }
            let target_text = std::fs::read_to_string(&resolved).expect("linked document");
            if !anchors(&target_text).contains(anchor) {
                broken.push(format!("{shown}:{n}: {target}: no heading makes #{anchor}"));
            }
        }
    }
    broken
}

#[test]
fn every_relative_link_and_anchor_resolves() {
    let root = root();
    let mut files = vec![root.join("README.md"), root.join("BENCHMARKS.md")];
    files.extend(
        WalkDir::new(root.join("docs"))
            .into_iter()
            .map(|e| e.expect("directory entry").into_path())
            .filter(|p| p.extension().is_some_and(|e| e == "md")),
    );
    assert!(files.len() > 5, "the documents moved: {files:?}");
    let broken: Vec<String> = files.iter().flat_map(|f| broken_links(f)).collect();
    assert!(broken.is_empty(), "broken links:\n{}", broken.join("\n"));
}

#[test]
fn slugs_are_github_s() {
    assert_eq!(
        slug("Trust, rate limits and signing"),
        "trust-rate-limits-and-signing"
    );
    assert_eq!(slug("`firmware-sim serve`"), "firmware-sim-serve");
    assert_eq!(
        slug("Signing and SETUP_SIGNING"),
        "signing-and-setup_signing"
    );
    assert_eq!(slug("The twin (`firmware-sim`)"), "the-twin-firmware-sim");
    assert_eq!(
        slug("Fig. 3: attitude — the twin"),
        "fig-3-attitude--the-twin"
    );
    assert_eq!(slug("See [the map](design.md) first"), "see-the-map-first");
    let made = anchors("# A\n\n## A\n\n```\n# not a heading\n```\n### B #\n");
    let expected: HashSet<String> = ["a", "a-1", "b"].into_iter().map(String::from).collect();
    assert_eq!(made, expected);
}

#[test]
fn the_scanner_sees_links_and_skips_code() {
    let prose = |text: &'static str| -> Vec<String> {
        without_code_spans(prose_lines(text))
            .iter()
            .flat_map(|(_, line)| link_targets(line))
            .collect()
    };
    assert_eq!(
        prose("see [a](docs/a.md#x) and ![f](fig.png \"title\") but not `[b](c.md)`"),
        vec!["docs/a.md#x", "fig.png"]
    );
    assert_eq!(
        prose("a span `that runs\non [b](c.md)` ends; [d](e.md)\n\n`open\n\n[f](g.md)"),
        vec!["e.md", "g.md"],
        "a code span runs on over a line break, and ends with its paragraph"
    );
    assert_eq!(
        link_targets("[q](<with space.md>) [p](f(1).md)"),
        vec!["with space.md", "f(1).md"]
    );
    assert_eq!(link_targets("[ref]: docs/ref.md"), vec!["docs/ref.md"]);
    let lines: Vec<usize> = prose_lines("a\n```sh\n[x](y.md)\n```\nb")
        .iter()
        .map(|(n, _)| *n)
        .collect();
    assert_eq!(lines, vec![1, 5], "a link in a code block is text");
}

#[test]
fn a_broken_link_is_reported() {
    let dir = std::env::temp_dir().join(format!("docs-links-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("scratch folder");
    let doc = dir.join("doc.md");
    std::fs::write(
        &doc,
        "# Top\n\n[ok](#top) [gone](missing.md) [bad anchor](#nowhere) [self](doc.md#top)\n",
    )
    .expect("scratch document");
    let broken = broken_links(&doc);
    std::fs::remove_dir_all(&dir).expect("scratch folder removed");
    assert_eq!(broken.len(), 2, "{broken:?}");
    assert!(
        broken[0].ends_with("missing.md: no such file"),
        "{broken:?}"
    );
    assert!(
        broken[1].ends_with("#nowhere: no heading makes #nowhere"),
        "{broken:?}"
    );
}
