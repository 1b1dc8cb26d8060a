//! The import rules of the terminal UI, read from the sources with `syn`: the app (state and
//! keys) never names the view (drawing), which reads the app; and no two of the UI's modules
//! import each other, directly or round a longer circle, apart from `src/tui/mod.rs` and its
//! children.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use proc_macro2::TokenTree;
use syn::visit::{self, Visit};
use walkdir::WalkDir;

/// Every module path a source names, as written (`super::view::map`, `crate::tui::app::App`),
/// each with the inline module it is named in (`tests` of a `#[cfg(test)] mod tests`).
#[derive(Default)]
struct Named {
    /// Inline modules around the current item, outermost first.
    inline: Vec<String>,
    /// (inline modules, path segments).
    paths: Vec<(Vec<String>, Vec<String>)>,
}

impl Named {
    fn add(&mut self, segments: Vec<String>) {
        self.paths.push((self.inline.clone(), segments));
    }

    /// The paths of a `use` tree, each down to its leaf (a name, a rename's original, a glob's
    /// prefix).
    fn use_tree(&mut self, prefix: &mut Vec<String>, tree: &syn::UseTree) {
        match tree {
            syn::UseTree::Path(p) => {
                prefix.push(p.ident.to_string());
                self.use_tree(prefix, &p.tree);
                prefix.pop();
            }
            syn::UseTree::Name(n) => {
                let mut path = prefix.clone();
                path.push(n.ident.to_string());
                self.add(path);
            }
            syn::UseTree::Rename(r) => {
                let mut path = prefix.clone();
                path.push(r.ident.to_string());
                self.add(path);
            }
            syn::UseTree::Glob(_) => self.add(prefix.clone()),
            syn::UseTree::Group(g) => {
                for t in &g.items {
                    self.use_tree(prefix, t);
                }
            }
        }
    }
}

impl<'ast> Visit<'ast> for Named {
    fn visit_item_mod(&mut self, m: &'ast syn::ItemMod) {
        self.inline.push(m.ident.to_string());
        visit::visit_item_mod(self, m);
        self.inline.pop();
    }

    fn visit_item_use(&mut self, u: &'ast syn::ItemUse) {
        self.use_tree(&mut Vec::new(), &u.tree);
    }

    fn visit_path(&mut self, p: &'ast syn::Path) {
        // A path of one segment is a name in scope (a local, a type), not a module's.
        if p.segments.len() > 1 {
            self.add(p.segments.iter().map(|s| s.ident.to_string()).collect());
        }
        visit::visit_path(self, p);
    }

    fn visit_macro(&mut self, m: &'ast syn::Macro) {
        // A macro's arguments are tokens: the `a::b::c` runs in them.
        let mut run: Vec<String> = Vec::new();
        let mut colons = 0;
        let flush = |run: &mut Vec<String>, this: &mut Self| {
            if run.len() > 1 {
                this.add(std::mem::take(run));
            }
            run.clear();
        };
        let mut stack = vec![m.tokens.clone().into_iter()];
        while let Some(top) = stack.last_mut() {
            let Some(tt) = top.next() else {
                stack.pop();
                flush(&mut run, self);
                continue;
            };
            match tt {
                TokenTree::Ident(i) => {
                    if colons != 2 {
                        flush(&mut run, self);
                    }
                    run.push(i.to_string());
                    colons = 0;
                }
                TokenTree::Punct(p) if p.as_char() == ':' => colons += 1,
                TokenTree::Group(g) => {
                    flush(&mut run, self);
                    colons = 0;
                    stack.push(g.stream().into_iter());
                }
                _ => {
                    flush(&mut run, self);
                    colons = 0;
                }
            }
        }
        visit::visit_macro(self, m);
    }
}

/// The module paths `source` names.
fn named(source: &str) -> Vec<(Vec<String>, Vec<String>)> {
    let file = syn::parse_file(source).expect("the source parses");
    let mut n = Named::default();
    n.visit_file(&file);
    n.paths
}

/// The module a source file under `src/` is (`src/tui/app/mod.rs` → `tui::app`).
fn module_of(src: &Path, file: &Path) -> Vec<String> {
    let rel = file.strip_prefix(src).expect("a file under src");
    let mut m: Vec<String> = rel
        .with_extension("")
        .iter()
        .map(|c| c.to_string_lossy().into_owned())
        .collect();
    if m.last().is_some_and(|l| l == "mod") {
        m.pop();
    }
    m
}

/// The crate path a `path` named in module `module` leads to (`super::view` in `tui::app` →
/// `tui::view`); a path that starts with a name in scope is taken as under `module`.
fn resolve(module: &[String], path: &[String]) -> Vec<String> {
    let mut at: Vec<String> = module.to_vec();
    let mut rest = path;
    match path.first().map(String::as_str) {
        Some("crate" | "vtol_gcs") => {
            at.clear();
            rest = &path[1..];
        }
        Some("self") => rest = &path[1..],
        _ => {}
    }
    while rest.first().is_some_and(|s| s == "super") {
        at.pop();
        rest = &rest[1..];
    }
    at.extend(rest.iter().cloned());
    at
}

/// Every `.rs` file under `dir`.
fn sources(dir: &Path) -> Vec<PathBuf> {
    WalkDir::new(dir)
        .into_iter()
        .map(|e| e.expect("directory entry").into_path())
        .filter(|p| p.extension().is_some_and(|e| e == "rs"))
        .collect()
}

/// The paths of `source` (module `module`) that name the UI's view module, in any spelling.
fn names_of_the_view(module: &[String], source: &str) -> Vec<String> {
    named(source)
        .into_iter()
        .filter(|(inline, path)| {
            let mut here = module.to_vec();
            here.extend(inline.iter().cloned());
            let to = resolve(&here, path);
            path.iter().any(|s| s == "view") || to.starts_with(&["tui".into(), "view".into()])
        })
        .map(|(_, path)| path.join("::"))
        .collect()
}

#[test]
fn the_app_never_names_the_view() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let files = sources(&src.join("tui/app"));
    assert!(files.len() > 3, "the app moved: {files:?}");
    let mut broken = Vec::new();
    for file in &files {
        let text = std::fs::read_to_string(file).expect("source file");
        for path in names_of_the_view(&module_of(&src, file), &text) {
            broken.push(format!("{} names {path}", file.display()));
        }
    }
    assert!(broken.is_empty(), "{}", broken.join("\n"));
}

#[test]
fn the_view_rule_sees_every_spelling() {
    let app = ["tui".to_owned(), "app".to_owned()];
    let found = |s: &str| names_of_the_view(&app, s);
    assert_eq!(found("use super::view;"), ["super::view"]);
    assert_eq!(found("use crate::tui::{app, view};"), ["crate::tui::view"]);
    assert_eq!(found("use crate::tui::view as v;"), ["crate::tui::view"]);
    assert_eq!(
        found("use vtol_gcs::tui::view::map::*;"),
        ["vtol_gcs::tui::view::map"]
    );
    assert_eq!(
        found("fn f() { crate::tui::view::draw(); }"),
        ["crate::tui::view::draw"]
    );
    assert_eq!(
        found("fn f() -> String { format!(\"{}\", super::view::MIN_SIZE.0) }"),
        ["super::view::MIN_SIZE"]
    );
    assert_eq!(
        found("struct A { m: super::super::tui::view::map::MapState }"),
        ["super::super::tui::view::map::MapState"]
    );
    // A local or a field called `view` is not the module.
    assert!(found("fn f(a: &App) -> bool { let view = a.view; view == View::Fleet }").is_empty());
}

/// The UI's modules directly under `src/tui` (`app`, `view`, `map` …) and the others each
/// one's files name.
fn rooms(src: &Path) -> BTreeMap<String, BTreeSet<String>> {
    child_edges(src, &["tui".to_owned()])
}

/// A circle in `edges`, as the rooms round it, if there is one.
fn circle(edges: &BTreeMap<String, BTreeSet<String>>) -> Option<Vec<String>> {
    fn walk(
        at: &str,
        edges: &BTreeMap<String, BTreeSet<String>>,
        path: &mut Vec<String>,
        done: &mut BTreeSet<String>,
    ) -> Option<Vec<String>> {
        if let Some(i) = path.iter().position(|p| p == at) {
            let mut c = path[i..].to_vec();
            c.push(at.to_owned());
            return Some(c);
        }
        if done.contains(at) {
            return None;
        }
        path.push(at.to_owned());
        for next in edges.get(at).into_iter().flatten() {
            if let Some(c) = walk(next, edges, path, done) {
                return Some(c);
            }
        }
        path.pop();
        done.insert(at.to_owned());
        None
    }
    let mut done = BTreeSet::new();
    edges
        .keys()
        .find_map(|k| walk(k, edges, &mut Vec::new(), &mut done))
}

#[test]
fn no_import_circle_among_the_ui_modules() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let edges = rooms(&src);
    assert!(
        edges.get("view").is_some_and(|v| v.contains("app")),
        "the reader lost the view's import of the app: {edges:?}"
    );
    assert_eq!(circle(&edges), None, "{edges:#?}");
}

#[test]
fn the_circle_finder_finds_a_long_one() {
    let edges: BTreeMap<String, BTreeSet<String>> = [
        ("app", &["map"][..]),
        ("map", &["progress"]),
        ("progress", &["app"]),
        ("view", &["app"]),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_owned(), v.iter().map(|s| (*s).to_owned()).collect()))
    .collect();
    assert_eq!(
        circle(&edges),
        Some(vec![
            "app".into(),
            "map".into(),
            "progress".into(),
            "app".into()
        ])
    );
}

/// The child modules of module `parent` (`[]` for the crate, `["tui"]` …) and which of the
/// others each one's files name. The parent's own file may name its children and they it.
fn child_edges(src: &Path, parent: &[String]) -> BTreeMap<String, BTreeSet<String>> {
    let dir = parent.iter().fold(src.to_path_buf(), |d, p| d.join(p));
    let names: BTreeSet<String> = std::fs::read_dir(&dir)
        .expect("a module folder")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.is_dir() || p.extension().is_some_and(|e| e == "rs"))
        .filter_map(|p| Some(p.file_stem()?.to_string_lossy().into_owned()))
        .filter(|n| !["mod", "lib", "bin"].contains(&n.as_str()))
        .collect();
    let mut edges: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for file in sources(&dir) {
        if file.starts_with(src.join("bin")) {
            continue;
        }
        let module = module_of(src, &file);
        let Some(from) = module
            .get(parent.len())
            .filter(|m| names.contains(*m))
            .cloned()
        else {
            continue;
        };
        let text = std::fs::read_to_string(&file).expect("source file");
        let out = edges.entry(from.clone()).or_default();
        for (inline, path) in named(&text) {
            let mut here = module.clone();
            here.extend(inline);
            let to = resolve(&here, &path);
            if to.starts_with(parent)
                && let Some(room) = to.get(parent.len())
                && names.contains(room)
                && *room != from
            {
                out.insert(room.clone());
            }
        }
    }
    edges
}

#[test]
fn no_import_circle_anywhere_in_the_crate_outside_parent_and_child() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut parents: Vec<Vec<String>> = vec![Vec::new()];
    for e in WalkDir::new(&src).min_depth(1) {
        let p = e.expect("directory entry").into_path();
        if p.is_dir() && !p.starts_with(src.join("bin")) {
            parents.push(module_of(&src, &p.join("mod.rs")));
        }
    }
    assert!(parents.len() > 5, "the folders moved: {parents:?}");
    let top = child_edges(&src, &[]);
    assert!(
        top.get("tui").is_some_and(|t| t.contains("tracker")),
        "the reader lost the UI's import of the tracker: {top:?}"
    );
    let circles: Vec<String> = parents
        .iter()
        .filter_map(|p| circle(&child_edges(&src, p)).map(|c| format!("in {p:?}: {c:?}")))
        .collect();
    assert!(circles.is_empty(), "{}", circles.join("\n"));
}
