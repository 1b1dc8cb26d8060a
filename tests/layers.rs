//! The import rules of the frame path, read from the sources as Rust: the router is
//! crate-private and the daemon is the only room that names it. The consumers of frames (the
//! tracker, the client, the terminal UI, the status line) read what they need of the links from
//! `links` and `tap`, and the binary reads it through `daemon::Running`.
//!
//! Every source file of the library and the binary is parsed (`syn`) by following the `mod`
//! declarations from `lib.rs` and `main.rs`, and every `use` tree and every path (in code,
//! types, attributes and macro arguments) is resolved to the module it names: `crate::`,
//! `self::`, `super::` chains, `vtol_gcs::`, names brought in by `use` (renamed or not) and glob
//! imports. A rule that some spelling slips past is no rule, so the last test writes it every
//! way it can be written.

use std::collections::{BTreeSet, HashMap};
use std::path::{Path, PathBuf};

use proc_macro2::{Spacing, TokenStream, TokenTree};
use syn::visit::Visit;
use walkdir::WalkDir;

/// The crate a module path starts in: the library (`vtol_gcs`) or the binary.
const LIB: &str = "<lib>";
const BIN: &str = "<bin>";

/// The modules allowed to name the router: itself and the daemon that drives it.
const ROUTER_CALLERS: [&str; 2] = ["router", "daemon"];

/// What names are in scope in one module: imported names and glob-imported modules.
#[derive(Debug, Default)]
struct Scope {
    names: HashMap<String, Vec<Vec<String>>>,
    globs: Vec<Vec<String>>,
}

/// Everything one file names, as absolute module paths (`[LIB, "router", ..]`), with the path
/// as written.
#[derive(Debug, Default)]
struct Named {
    paths: Vec<(Vec<String>, String)>,
}

/// One parsed file: the module path its items are in, and its syntax.
struct Unit {
    krate: &'static str,
    module: Vec<String>,
    file: PathBuf,
    syntax: syn::File,
}

fn segs(path: &syn::Path) -> Vec<String> {
    path.segments.iter().map(|s| s.ident.to_string()).collect()
}

/// Resolves `segs` (as written, `leading` for a leading `::`) in `module` of `krate`: every
/// absolute module path it may name.
fn resolve(
    krate: &str,
    module: &[String],
    scopes: &HashMap<Vec<String>, Scope>,
    leading: bool,
    segs: &[String],
) -> Vec<Vec<String>> {
    let Some(first) = segs.first() else {
        return Vec::new();
    };
    let rooted = |root: Vec<String>, rest: &[String]| {
        let mut p = root;
        p.extend(rest.iter().cloned());
        vec![p]
    };
    if leading {
        // `::name`: an extern crate.
        return if first == "vtol_gcs" {
            rooted(vec![LIB.to_owned()], &segs[1..])
        } else {
            Vec::new()
        };
    }
    match first.as_str() {
        "crate" => return rooted(vec![krate.to_owned()], &segs[1..]),
        "vtol_gcs" => return rooted(vec![LIB.to_owned()], &segs[1..]),
        "self" | "super" => {
            let mut at = module.to_vec();
            let mut rest = segs;
            if first == "self" {
                rest = &rest[1..];
            }
            while rest.first().is_some_and(|s| s == "super") {
                at.pop();
                rest = &rest[1..];
            }
            let mut root = vec![krate.to_owned()];
            root.extend(at);
            return rooted(root, rest);
        }
        _ => {}
    }
    // A name of this module (a child module, an item), one brought in by `use`, or one of a
    // glob-imported module: any of them.
    let mut root = vec![krate.to_owned()];
    root.extend(module.iter().cloned());
    let mut found = rooted(root, segs);
    if let Some(scope) = scopes.get(module) {
        for target in scope.names.get(first).into_iter().flatten() {
            found.extend(rooted(target.clone(), &segs[1..]));
        }
        for glob in &scope.globs {
            found.extend(rooted(glob.clone(), segs));
        }
    }
    found
}

/// A `use` tree flattened: each path it names, the name it binds (if any), and whether it is a
/// glob.
fn flatten(
    tree: &syn::UseTree,
    prefix: &mut Vec<String>,
    out: &mut Vec<(Vec<String>, Option<String>, bool)>,
) {
    match tree {
        syn::UseTree::Path(p) => {
            prefix.push(p.ident.to_string());
            flatten(&p.tree, prefix, out);
            prefix.pop();
        }
        syn::UseTree::Name(n) if n.ident == "self" => {
            out.push((prefix.clone(), prefix.last().cloned(), false));
        }
        syn::UseTree::Name(n) => {
            let mut p = prefix.clone();
            p.push(n.ident.to_string());
            out.push((p, Some(n.ident.to_string()), false));
        }
        syn::UseTree::Rename(r) => {
            let mut p = prefix.clone();
            if r.ident != "self" {
                p.push(r.ident.to_string());
            }
            out.push((p, Some(r.rename.to_string()), false));
        }
        syn::UseTree::Glob(_) => out.push((prefix.clone(), None, true)),
        syn::UseTree::Group(g) => {
            for t in &g.items {
                flatten(t, prefix, out);
            }
        }
    }
}

/// First pass: the `use` items of every module of a file (inline modules too), resolved.
struct Uses<'a> {
    krate: &'static str,
    module: Vec<String>,
    scopes: &'a mut HashMap<Vec<String>, Scope>,
    named: &'a mut Named,
}

impl<'ast> Visit<'ast> for Uses<'_> {
    fn visit_item_mod(&mut self, m: &'ast syn::ItemMod) {
        if m.content.is_some() {
            self.module.push(m.ident.to_string());
            syn::visit::visit_item_mod(self, m);
            self.module.pop();
        }
    }

    fn visit_item_use(&mut self, u: &'ast syn::ItemUse) {
        let mut flat = Vec::new();
        flatten(&u.tree, &mut Vec::new(), &mut flat);
        let leading = u.leading_colon.is_some();
        for (path, name, glob) in flat {
            let written = format!("use {}{}", if leading { "::" } else { "" }, path.join("::"));
            let targets = resolve(self.krate, &self.module, self.scopes, leading, &path);
            let scope = self.scopes.entry(self.module.clone()).or_default();
            for t in &targets {
                self.named.paths.push((t.clone(), written.clone()));
                if glob {
                    scope.globs.push(t.clone());
                }
                if let Some(n) = &name {
                    scope.names.entry(n.clone()).or_default().push(t.clone());
                }
            }
        }
    }
}

/// Second pass: every other path (expressions, types, patterns, attributes, visibilities,
/// and the tokens of macro calls and definitions).
struct Paths<'a> {
    krate: &'static str,
    module: Vec<String>,
    scopes: &'a HashMap<Vec<String>, Scope>,
    named: &'a mut Named,
}

impl Paths<'_> {
    fn note(&mut self, leading: bool, segs: &[String]) {
        let written = format!("{}{}", if leading { "::" } else { "" }, segs.join("::"));
        for t in resolve(self.krate, &self.module, self.scopes, leading, segs) {
            self.named.paths.push((t, written.clone()));
        }
    }

    /// The paths in a macro's tokens: `a::b::c` and `::a::b`, inside groups too.
    fn scan(&mut self, tokens: TokenStream) {
        let mut flat = Vec::new();
        flatten_tokens(tokens, &mut flat);
        let mut i = 0;
        while i < flat.len() {
            let leading = flat[i] == Tok::Colon2;
            let start = i + usize::from(leading);
            let mut path = Vec::new();
            let mut j = start;
            while let Some(Tok::Ident(name)) = flat.get(j) {
                path.push(name.clone());
                if flat.get(j + 1) == Some(&Tok::Colon2) {
                    j += 2;
                } else {
                    j += 1;
                    break;
                }
            }
            if path.is_empty() {
                i += 1;
            } else {
                self.note(leading, &path);
                i = j.max(i + 1);
            }
        }
    }
}

#[derive(Debug, PartialEq, Eq)]
enum Tok {
    Ident(String),
    Colon2,
    Other,
}

fn flatten_tokens(tokens: TokenStream, out: &mut Vec<Tok>) {
    let mut tokens = tokens.into_iter().peekable();
    while let Some(t) = tokens.next() {
        match t {
            TokenTree::Ident(i) => out.push(Tok::Ident(i.to_string())),
            TokenTree::Punct(p) if p.as_char() == ':' && p.spacing() == Spacing::Joint => {
                if matches!(tokens.peek(), Some(TokenTree::Punct(q)) if q.as_char() == ':') {
                    tokens.next();
                    out.push(Tok::Colon2);
                } else {
                    out.push(Tok::Other);
                }
            }
            TokenTree::Group(g) => {
                out.push(Tok::Other);
                flatten_tokens(g.stream(), out);
                out.push(Tok::Other);
            }
            _ => out.push(Tok::Other),
        }
    }
}

impl<'ast> Visit<'ast> for Paths<'_> {
    fn visit_item_mod(&mut self, m: &'ast syn::ItemMod) {
        if m.content.is_some() {
            self.module.push(m.ident.to_string());
            syn::visit::visit_item_mod(self, m);
            self.module.pop();
        }
    }

    fn visit_item_use(&mut self, _: &'ast syn::ItemUse) {
        // Read by the first pass.
    }

    fn visit_path(&mut self, p: &'ast syn::Path) {
        self.note(p.leading_colon.is_some(), &segs(p));
        syn::visit::visit_path(self, p);
    }

    fn visit_macro(&mut self, m: &'ast syn::Macro) {
        self.scan(m.tokens.clone());
        syn::visit::visit_macro(self, m);
    }
}

/// Everything `unit` names.
fn names(unit: &Unit) -> Named {
    let mut scopes = HashMap::new();
    let mut named = Named::default();
    Uses {
        krate: unit.krate,
        module: unit.module.clone(),
        scopes: &mut scopes,
        named: &mut named,
    }
    .visit_file(&unit.syntax);
    Paths {
        krate: unit.krate,
        module: unit.module.clone(),
        scopes: &scopes,
        named: &mut named,
    }
    .visit_file(&unit.syntax);
    named
}

/// The value of a `#[path = "…"]` attribute.
fn path_attr(attrs: &[syn::Attribute]) -> Option<String> {
    attrs.iter().find_map(|a| match &a.meta {
        syn::Meta::NameValue(nv) if nv.path.is_ident("path") => match &nv.value {
            syn::Expr::Lit(syn::ExprLit {
                lit: syn::Lit::Str(s),
                ..
            }) => Some(s.value()),
            _ => None,
        },
        _ => None,
    })
}

/// Every file of the crate rooted at `root`, following its `mod` declarations.
fn load(krate: &'static str, root: &Path) -> Vec<Unit> {
    let mut units = Vec::new();
    let mut todo = vec![(root.to_owned(), Vec::<String>::new(), true)];
    while let Some((file, module, owns_dir)) = todo.pop() {
        let text =
            std::fs::read_to_string(&file).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
        let syntax = syn::parse_file(&text).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
        let here = file.parent().expect("a file's folder").to_owned();
        // Where the file's child modules are: beside it for lib.rs, main.rs and mod.rs, in the
        // folder of its name otherwise.
        let dir = if owns_dir {
            here.clone()
        } else {
            here.join(file.file_stem().expect("a file name"))
        };
        for item in &syntax.items {
            let syn::Item::Mod(m) = item else { continue };
            if m.content.is_some() {
                // Inline modules inside an inline one would need their own folder; none here.
                continue;
            }
            let mut child = module.clone();
            child.push(m.ident.to_string());
            let (path, owns) = if let Some(p) = path_attr(&m.attrs) {
                (here.join(p), false)
            } else if dir.join(format!("{}.rs", m.ident)).exists() {
                (dir.join(format!("{}.rs", m.ident)), false)
            } else {
                (dir.join(m.ident.to_string()).join("mod.rs"), true)
            };
            todo.push((path, child, owns));
        }
        units.push(Unit {
            krate,
            module,
            file,
            syntax,
        });
    }
    units
}

fn src() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("src")
}

fn names_router(path: &[String]) -> bool {
    path.len() >= 2 && path[0] == LIB && path[1] == "router"
}

/// The router's module as written in `lib.rs`.
fn router_mod() -> syn::ItemMod {
    let text = std::fs::read_to_string(src().join("lib.rs")).expect("lib.rs");
    let lib = syn::parse_file(&text).expect("lib.rs parses");
    lib.items
        .into_iter()
        .find_map(|i| match i {
            syn::Item::Mod(m) if m.ident == "router" => Some(m),
            _ => None,
        })
        .expect("lib.rs declares the router")
}

#[test]
fn every_source_file_is_read() {
    let mut units = load(LIB, &src().join("lib.rs"));
    units.extend(load(
        BIN,
        &src().join("bin").join("vtol-gcs").join("main.rs"),
    ));
    let read: BTreeSet<PathBuf> = units.into_iter().map(|u| u.file).collect();
    let on_disk: BTreeSet<PathBuf> = WalkDir::new(src())
        .into_iter()
        .map(|e| e.expect("directory entry").into_path())
        .filter(|p| p.extension().is_some_and(|e| e == "rs"))
        .collect();
    let unread: Vec<_> = on_disk.difference(&read).collect();
    assert!(
        unread.is_empty(),
        "files the rules did not read: {unread:?}"
    );
    assert!(read.len() > 50, "too few files: {}", read.len());
}

#[test]
fn only_the_daemon_names_the_router() {
    let mut units = load(LIB, &src().join("lib.rs"));
    units.extend(load(
        BIN,
        &src().join("bin").join("vtol-gcs").join("main.rs"),
    ));
    let mut broken = Vec::new();
    for unit in &units {
        let allowed = unit.krate == LIB
            && unit
                .module
                .first()
                .is_some_and(|m| ROUTER_CALLERS.contains(&m.as_str()));
        if allowed {
            continue;
        }
        for (target, written) in names(unit).paths {
            if names_router(&target) {
                broken.push(format!("{}: {written}", unit.file.display()));
            }
        }
    }
    broken.dedup();
    assert!(
        broken.is_empty(),
        "the router named outside the daemon:\n{}",
        broken.join("\n")
    );
}

#[test]
fn outside_the_crate_the_router_cannot_be_named() {
    // `pub(crate)` (or private): the binary, the tests, the benches and the fuzz targets get a
    // compile error for any spelling of `vtol_gcs::router`.
    let m = router_mod();
    let crate_only = match &m.vis {
        syn::Visibility::Inherited => true,
        syn::Visibility::Restricted(r) => r.in_token.is_none() && r.path.is_ident("crate"),
        syn::Visibility::Public(_) => false,
    };
    assert!(
        crate_only,
        "lib.rs makes the router visible outside the crate"
    );
}

/// Whether `source`, as the file of module `module` of the library, names the router.
fn flags(module: &[&str], source: &str) -> bool {
    let unit = Unit {
        krate: LIB,
        module: module.iter().map(|s| (*s).to_owned()).collect(),
        file: PathBuf::from("example.rs"),
        syntax: syn::parse_file(source).expect("the example parses"),
    };
    names(&unit).paths.iter().any(|(t, _)| names_router(t))
}

#[test]
fn the_rule_reader_sees_every_spelling() {
    let named = [
        (&["tracker"][..], "use crate::router::Router;"),
        (&["tracker"], "use crate::router;"),
        (&["tracker"], "use crate::{router, links};"),
        (
            &["tracker"],
            "use crate::{links::Side, router::{self as r}};",
        ),
        (
            &["tracker"],
            "use crate::{self as c}; fn f() { c::router::x(); }",
        ),
        (&["tracker"], "use crate as c; fn f() { c::router::x(); }"),
        (&["tracker", "state"], "use super::super::router;"),
        (
            &["tracker", "state"],
            "use self::super::super::router::SharedRouter;",
        ),
        (&["tracker"], "use super::*; fn f() { router::x(); }"),
        (&["tracker"], "use crate::*; type T = router::Router;"),
        (&["tracker"], "fn f() { crate :: router :: x(); }"),
        (&["tracker"], "fn f() -> crate::router::Router { todo!() }"),
        (&["tracker"], "fn f() { let _ = vtol_gcs::router::x(); }"),
        (&["tracker"], "use ::vtol_gcs::router::Router;"),
        (
            &["tracker"],
            "fn f() { println!(\"{:?}\", crate::router::x()); }",
        ),
        (
            &["tracker"],
            "fn f() { g(vec![ :: vtol_gcs :: router :: X ]); }",
        ),
        (
            &["tracker"],
            "mod inner { use super::super::router::Router; }",
        ),
        (
            &["tracker"],
            "struct S { r: std::sync::Arc<super::router::Router> }",
        ),
        (&["tracker"], "impl S { pub(in crate::router) fn f() {} }"),
        (&[], "fn f() { router::x(); }"),
    ];
    for (module, source) in named {
        assert!(flags(module, source), "not seen in {module:?}: {source}");
    }
    let clean = [
        (&["tracker"][..], "use crate::links::{RouterStats, Side};"),
        (
            &["tracker"],
            "// crate::router in a comment\n/// [`crate::router`] in a doc\nfn f() {}",
        ),
        (&["tracker"], "fn f() { let router = 1; let _ = router; }"),
        (&["tracker", "state"], "use super::router;"),
        (&["tracker"], "fn f() { let _ = \"crate::router\"; }"),
    ];
    for (module, source) in clean {
        assert!(!flags(module, source), "seen in {module:?}: {source}");
    }
}
