//! Architecture rules checked on the source tree: no import circle between the files of any crate
//! of the workspace (nor between the top-level modules of the host library, the `gpmm` program and
//! the firmware), the core's layers one way, and no source file over 800 lines (tests aside).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display())) {
        let path = entry.expect("directory entry").path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// A file's module path below the crate root (`["mesh", "io"]` for `mesh/io/mod.rs`, `["fit"]`
/// for `fit.rs`); empty for the root (`lib.rs`, `main.rs`).
fn module_path(src: &Path, file: &Path) -> Vec<String> {
    let rel = file.strip_prefix(src).expect("a file of the crate");
    let mut path: Vec<String> = rel.components().map(|c| c.as_os_str().to_string_lossy().into_owned()).collect();
    let last = path.pop().unwrap_or_default();
    let stem = last.strip_suffix(".rs").unwrap_or(&last);
    if !(stem == "mod" || (path.is_empty() && (stem == "lib" || stem == "main"))) {
        path.push(stem.to_string());
    }
    path
}

/// The names a path starting at `rest` (just after `crate::` or `super::`) reaches first:
/// `a` for `a::b`, `a` and `b` for `{a::x, b}`.
fn first_names(rest: &str) -> Vec<String> {
    let ident = |s: &str| -> String { s.trim_start().chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '_').collect() };
    let Some(group) = rest.strip_prefix('{') else {
        return vec![ident(rest)].into_iter().filter(|n| !n.is_empty()).collect();
    };
    // The items of the group at its own depth.
    let (mut names, mut depth, mut item_start) = (Vec::new(), 0usize, 0usize);
    for (i, c) in group.char_indices() {
        match c {
            '{' => depth += 1,
            '}' if depth == 0 => {
                names.push(ident(&group[item_start..i]));
                break;
            }
            '}' => depth -= 1,
            ',' if depth == 0 => {
                names.push(ident(&group[item_start..i]));
                item_start = i + 1;
            }
            _ => {}
        }
    }
    names.into_iter().filter(|n| !n.is_empty() && n != "self").collect()
}

/// Module names that `text` refers to as `crate::NAME` or in `crate::{NAME, ...}`.
fn crate_refs(text: &str) -> BTreeSet<String> {
    text.match_indices("crate::").flat_map(|(i, _)| first_names(&text[i + 7..])).collect()
}

/// Top-level names that `text`, the code of a module `depth` levels below the root, refers to
/// through as many `super::` (`super::NAME` in `fit.rs` or `fit/mod.rs`).
fn super_refs(text: &str, depth: usize) -> BTreeSet<String> {
    let hop = "super::".repeat(depth);
    let mut refs = BTreeSet::new();
    for (i, _) in text.match_indices(hop.as_str()) {
        let rest = &text[i + hop.len()..];
        if !text[..i].ends_with("super::") && !rest.starts_with("super::") {
            refs.extend(first_names(rest));
        }
    }
    refs
}

/// The code of a source file that counts for imports: no unit tests (they may use anything), no comments.
fn code_of(text: &str) -> String {
    let code = text.split("#[cfg(test)]").next().unwrap_or("");
    code.lines().filter(|l| !l.trim_start().starts_with("//")).collect::<Vec<_>>().join("\n")
}

/// The import graph between the top-level modules of the crate whose root is in `src`: an
/// edge from each module to every other top-level module its files name through `crate::` or
/// `super::` (the root, `lib.rs` or `main.rs`, is left out: it declares them all).
fn module_graph(src: &Path) -> BTreeMap<String, BTreeSet<String>> {
    let mut files = Vec::new();
    rust_files(src, &mut files);
    let mut graph: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    let mut refs: Vec<(String, BTreeSet<String>)> = Vec::new();
    for f in &files {
        let path = module_path(src, f);
        let Some(module) = path.first() else { continue };
        graph.entry(module.clone()).or_default();
        let code = code_of(&std::fs::read_to_string(f).expect("read source"));
        let mut names = crate_refs(&code);
        names.extend(super_refs(&code, path.len()));
        refs.push((module.clone(), names));
    }
    for (module, names) in refs {
        let known: BTreeSet<String> = names.into_iter().filter(|n| *n != module && graph.contains_key(n)).collect();
        graph.get_mut(&module).expect("module").extend(known);
    }
    graph
}

/// A circle in `graph` (its modules in order, the first repeated at the end), if there is one.
fn find_circle(graph: &BTreeMap<String, BTreeSet<String>>) -> Option<Vec<String>> {
    // Depth-first search, reporting the path that closes.
    fn visit(n: &str, g: &BTreeMap<String, BTreeSet<String>>, path: &mut Vec<String>, done: &mut BTreeSet<String>) -> Option<Vec<String>> {
        if let Some(k) = path.iter().position(|p| p == n) {
            let mut cycle = path[k..].to_vec();
            cycle.push(n.to_string());
            return Some(cycle);
        }
        if done.contains(n) {
            return None;
        }
        path.push(n.to_string());
        for d in g.get(n).into_iter().flatten() {
            if let Some(c) = visit(d, g, path, done) {
                return Some(c);
            }
        }
        path.pop();
        done.insert(n.to_string());
        None
    }
    let mut done = BTreeSet::new();
    graph.keys().find_map(|n| visit(n, graph, &mut Vec::new(), &mut done))
}

/// Asserts that `graph`, the import graph between the `what` (modules or files) of the crate in
/// `dir`, has at least `least` nodes and no circle.
fn assert_no_circle(graph: &BTreeMap<String, BTreeSet<String>>, dir: &str, what: &str, least: usize) {
    assert!(graph.len() >= least, "expected the {what} of {dir}, found {:?}", graph.keys());
    if let Some(circle) = find_circle(graph) {
        panic!("import circle between the {what} of {dir}: {}", circle.join(" -> "));
    }
}

/// Asserts that the crate in `dir` (relative to the repository) has at least `modules`
/// top-level modules and no import circle between them.
fn assert_no_import_circle(dir: &str, modules: usize) {
    assert_no_circle(&module_graph(&repo().join(dir)), dir, "modules", modules);
}

#[test]
fn host_modules_form_no_import_circle() {
    assert_no_import_circle("host/src", 6);
}

#[test]
fn cli_modules_form_no_import_circle() {
    assert_no_import_circle("host/cli/src", 10);
}

#[test]
fn firmware_modules_form_no_import_circle() {
    assert_no_import_circle("firmware-sim/src", 5);
}

#[test]
fn a_circle_is_found() {
    let graph = |edges: &[(&str, &str)]| {
        let mut g: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
        for (a, b) in edges {
            g.entry(a.to_string()).or_default().insert(b.to_string());
            g.entry(b.to_string()).or_default();
        }
        g
    };
    let circle = find_circle(&graph(&[("main", "fit"), ("fit", "clock"), ("frame_fit", "fit"), ("fit", "frame_fit")]));
    assert_eq!(circle, Some(["fit", "frame_fit", "fit"].map(String::from).to_vec()));
    let long = find_circle(&graph(&[("a", "b"), ("b", "c"), ("c", "d"), ("d", "b")])).expect("a circle");
    assert_eq!(long, ["b", "c", "d", "b"].map(String::from).to_vec());
    assert_eq!(find_circle(&graph(&[("a", "b"), ("b", "c"), ("a", "c"), ("d", "a")])), None);
}

#[test]
fn super_references_are_found_at_the_top_level_only() {
    assert_eq!(super_refs("use super::fit::X; super::super::gp::Y; super::{a, b::c};", 1), ["a", "b", "fit"].map(String::from).into());
    assert_eq!(super_refs("use super::fit::X; super::super::gp::Y;", 2), ["gp"].map(String::from).into());
    let src = Path::new("/r/src");
    assert_eq!(module_path(src, Path::new("/r/src/main.rs")), Vec::<String>::new());
    assert_eq!(module_path(src, Path::new("/r/src/mesh/io/mod.rs")), ["mesh", "io"].map(String::from).to_vec());
    assert_eq!(module_path(src, Path::new("/r/src/fit.rs")), ["fit"].map(String::from).to_vec());
}

/// Lines of a source file that count towards its length: all but its own unit tests.
fn counted_lines(text: &str) -> usize {
    text.split("\n#[cfg(test)]").next().unwrap_or("").lines().count()
}

#[test]
fn no_source_file_is_over_800_lines() {
    let mut files = Vec::new();
    for dir in ["core/src", "host/src", "host/cli/src", "host/python/src", "host/train/src", "firmware-sim/src", "tests/src"] {
        let d = repo().join(dir);
        if d.is_dir() {
            rust_files(&d, &mut files);
        }
    }
    assert!(files.len() > 40, "found only {} source files", files.len());
    let long: Vec<String> = files
        .iter()
        .filter_map(|f| {
            let n = counted_lines(&std::fs::read_to_string(f).expect("read source"));
            (n > 800).then(|| format!("{} ({n} lines)", f.display()))
        })
        .collect();
    assert!(long.is_empty(), "source files over 800 lines: {long:?}");
}

#[test]
fn crate_references_are_found() {
    assert_eq!(crate_refs("use crate::mesh::Mesh; use crate::gp::{a}; crate::mesh::x"), ["gp", "mesh"].map(String::from).into());
    let grouped = "use crate::{clock, fit::{self, Buffers}, fail};\nuse crate::{\n    detect,\n    stack::peak,\n};";
    assert_eq!(crate_refs(grouped), ["clock", "detect", "fail", "fit", "stack"].map(String::from).into());
}

#[test]
fn the_core_depends_one_way() {
    // format, model and render must not import the fit (the fit imports them), render not the
    // model (the model imports it), and geometry, the ground floor, nothing of the crate.
    let src = repo().join("core/src");
    let code_of = |f: &Path| {
        let text = std::fs::read_to_string(f).expect("read source");
        let code = text.split("#[cfg(test)]").next().unwrap_or("").to_string();
        code.lines().filter(|l| !l.trim_start().starts_with("//")).collect::<Vec<_>>().join("\n")
    };
    let rules = [("format", "fit"), ("model", "fit"), ("render", "fit"), ("render", "format"), ("model", "format"), ("render", "model")];
    for (folder, forbidden) in rules {
        let mut files = Vec::new();
        rust_files(&src.join(folder), &mut files);
        assert!(!files.is_empty(), "core/src/{folder} has no sources");
        for f in &files {
            let refs = crate_refs(&code_of(f));
            assert!(!refs.contains(forbidden), "{} (core {folder}) imports crate::{forbidden}", f.display());
        }
    }
    let geometry = src.join("geometry.rs");
    let code = code_of(&geometry);
    let refs = crate_refs(&code);
    assert!(refs.is_empty() && !code.contains("super::"), "{} (core geometry) imports {refs:?} of the crate", geometry.display());
}

// ---- File-level import graph -------------------------------------------------------------------

/// Whether `c` may be part of an identifier.
fn ident_char(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_'
}

/// The paths of a use tree or expression path starting at `text` (its first segment first):
/// `a::b::{c, d::{e, f}}` gives `a::b::c`, `a::b::d::e` and `a::b::d::f`; `a::b::c(x)` gives
/// `a::b::c`. A glob ends in `*`; `self` inside a group names the group's own path.
fn use_paths(text: &str) -> Vec<Vec<String>> {
    fn tree(chars: &[char], i: &mut usize, prefix: &[String], out: &mut Vec<Vec<String>>) {
        let mut path = prefix.to_vec();
        loop {
            while *i < chars.len() && chars[*i].is_whitespace() {
                *i += 1;
            }
            if chars.get(*i) == Some(&'{') {
                *i += 1;
                loop {
                    tree(chars, i, &path, out);
                    while *i < chars.len() && chars[*i].is_whitespace() {
                        *i += 1;
                    }
                    match chars.get(*i) {
                        Some(',') => *i += 1,
                        Some('}') => {
                            *i += 1;
                            return;
                        }
                        _ => return,
                    }
                    while *i < chars.len() && chars[*i].is_whitespace() {
                        *i += 1;
                    }
                    if chars.get(*i) == Some(&'}') {
                        *i += 1;
                        return;
                    }
                }
            }
            if chars.get(*i) == Some(&'*') {
                *i += 1;
                path.push("*".to_string());
                out.push(path);
                return;
            }
            let start = *i;
            while *i < chars.len() && ident_char(chars[*i]) {
                *i += 1;
            }
            if start == *i {
                if path.len() > prefix.len() {
                    out.push(path);
                }
                return;
            }
            let seg: String = chars[start..*i].iter().collect();
            if seg == "self" && !prefix.is_empty() && path.len() == prefix.len() {
                out.push(path);
                return;
            }
            path.push(seg);
            if chars.get(*i) == Some(&':') && chars.get(*i + 1) == Some(&':') {
                *i += 2;
            } else {
                out.push(path);
                return;
            }
        }
    }
    let chars: Vec<char> = text.chars().collect();
    let mut out = Vec::new();
    tree(&chars, &mut 0, &[], &mut out);
    out
}

/// The source files of the crate whose root is in `src`, by module path.
fn crate_modules(src: &Path) -> BTreeMap<Vec<String>, PathBuf> {
    let mut files = Vec::new();
    rust_files(src, &mut files);
    files.into_iter().map(|f| (module_path(src, &f), f)).collect()
}

/// Whether `code` defines an item called `name` (a function, type, constant, module or macro).
fn defines(code: &str, name: &str) -> bool {
    ["fn ", "struct ", "enum ", "trait ", "type ", "const ", "static ", "union ", "mod ", "macro_rules! "].iter().any(|kw| {
        code.match_indices(&format!("{kw}{name}")).any(|(i, m)| {
            let before = code[..i].chars().next_back().is_none_or(|c| !ident_char(c));
            let after = code[i + m.len()..].chars().next().is_none_or(|c| !ident_char(c));
            before && after
        })
    })
}

/// The `use` statements of `code` (re-exports and private imports alike, which a child module
/// also sees), each as its text after `use` up to the `;`.
fn use_statements(code: &str) -> Vec<&str> {
    let mut out = Vec::new();
    for (i, _) in code.match_indices("use ") {
        let head = code[..i].rsplit('\n').next().unwrap_or("");
        let t = head.trim();
        if t.is_empty() || t == "pub" || (t.starts_with("pub(") && t.ends_with(')')) {
            let rest = &code[i + 4..];
            out.push(&rest[..rest.find(';').unwrap_or(rest.len())]);
        }
    }
    out
}

/// `code` without its re-export statements (a facade's `pub use` passes names through; it is not
/// an import of the file that says it).
fn without_reexports(code: &str) -> String {
    code.lines()
        .scan(false, |inside, line| {
            let starts = {
                let t = line.trim_start();
                t.starts_with("pub") && t.contains(" use ")
            };
            let skip = *inside || starts;
            *inside = skip && !line.contains(';');
            Some((!skip).then_some(line))
        })
        .flatten()
        .collect::<Vec<_>>()
        .join("\n")
}

/// Finds the file that defines what a path names, within one crate.
struct Resolver<'a> {
    /// The crate's files by module path.
    modules: &'a BTreeMap<Vec<String>, PathBuf>,
    /// Each file's code (no unit tests, no comments).
    code: BTreeMap<Vec<String>, String>,
}

impl Resolver<'_> {
    /// The file that `path` (absolute module segments, then item names) leads to, following the
    /// re-exports of module facades; `None` outside the crate.
    fn resolve(&self, path: &[String], depth: usize) -> Option<Vec<String>> {
        let mut module: Vec<String> = Vec::new();
        let mut rest = path;
        while let Some((first, tail)) = rest.split_first() {
            let mut next = module.clone();
            next.push(first.clone());
            if !self.modules.contains_key(&next) {
                break;
            }
            module = next;
            rest = tail;
        }
        let Some(item) = rest.first() else { return Some(module) };
        let code = self.code.get(&module)?;
        if depth > 8 || item == "*" || defines(code, item) {
            return Some(module);
        }
        for statement in use_statements(code) {
            for p in use_paths(statement) {
                let leaf = p.last().map(String::as_str).unwrap_or("");
                let alias_hit = statement.contains(&format!(" as {item}"));
                if leaf == item || leaf == "*" || alias_hit {
                    if let Some(abs) = self.absolute(&module, &p) {
                        let target = if leaf == "*" {
                            let mut t = abs[..abs.len() - 1].to_vec();
                            t.push(item.clone());
                            t
                        } else {
                            abs
                        };
                        if let Some(found) = self.resolve(&target, depth + 1) {
                            if found != module && (leaf != "*" || self.code.get(&found).is_some_and(|c| defines(c, item))) {
                                return Some(found);
                            }
                        }
                    }
                }
            }
        }
        Some(module)
    }

    /// `path` as written in module `from`, made absolute (`crate::`, `super::`, `self::` or a
    /// child module's name first); `None` for a path that starts elsewhere (another crate).
    fn absolute(&self, from: &[String], path: &[String]) -> Option<Vec<String>> {
        let (first, tail) = path.split_first()?;
        let mut base = from.to_vec();
        let mut rest = tail;
        match first.as_str() {
            "crate" => base.clear(),
            "self" => {}
            "super" => {
                base.pop();
                while rest.first().is_some_and(|s| s == "super") {
                    base.pop();
                    rest = &rest[1..];
                }
            }
            child => {
                base.push(child.to_string());
                if !self.modules.contains_key(&base) {
                    return None;
                }
            }
        }
        let mut abs = base;
        abs.extend(rest.iter().cloned());
        Some(abs)
    }
}

/// The import graph between the files of the crate whose root is in `src` (by module path): an
/// edge from a file to each other file whose items its code names through `crate::`, `super::`,
/// `self::` or a child module's name, re-exports followed to the file that defines the item.
fn file_graph(src: &Path) -> BTreeMap<String, BTreeSet<String>> {
    let modules = crate_modules(src);
    let code: BTreeMap<Vec<String>, String> =
        modules.iter().map(|(m, f)| (m.clone(), code_of(&std::fs::read_to_string(f).expect("read source")))).collect();
    let resolver = Resolver { modules: &modules, code };
    let name = |m: &[String]| {
        let f = &modules[m];
        f.strip_prefix(src).unwrap_or(f).display().to_string()
    };
    let mut graph = BTreeMap::new();
    for (module, text) in &resolver.code {
        let text = without_reexports(text);
        let mut edges = BTreeSet::new();
        for (i, _) in text.match_indices("::") {
            // The start of the path this `::` belongs to: the identifier before it, if nothing but
            // a non-path character precedes that identifier.
            let head = &text[..i];
            let start = head.rfind(|c: char| !ident_char(c)).map_or(0, |k| k + 1);
            let before = &head[..start];
            if before.ends_with("::") || before.ends_with('$') || start == i {
                continue;
            }
            for path in use_paths(&text[start..]) {
                let Some(abs) = resolver.absolute(module, &path) else { continue };
                if let Some(target) = resolver.resolve(&abs, 0) {
                    if target != *module {
                        edges.insert(name(&target));
                    }
                }
            }
        }
        graph.insert(name(module), edges);
    }
    graph
}

/// Asserts that no two files of the crate in `dir` (relative to the repository) import each
/// other, directly or round a loop; it has at least `files` source files.
fn assert_no_file_circle(dir: &str, files: usize) {
    assert_no_circle(&file_graph(&repo().join(dir)), dir, "files", files);
}

#[test]
fn no_two_files_of_a_crate_import_each_other() {
    for (dir, files) in [
        ("core/src", 60),
        ("host/src", 60),
        ("host/cli/src", 15),
        ("host/python/src", 5),
        ("host/train/src", 8),
        ("firmware-sim/src", 6),
        ("tests/src", 1),
    ] {
        assert_no_file_circle(dir, files);
    }
}

#[test]
fn use_trees_are_expanded() {
    let paths = |s: &str| use_paths(s).into_iter().map(|p| p.join("::")).collect::<Vec<_>>();
    assert_eq!(paths("super::{a::X, b::{self, Y}, c};"), ["super::a::X", "super::b", "super::b::Y", "super::c"]);
    assert_eq!(paths("crate::fit::run(x)"), ["crate::fit::run"]);
    assert_eq!(paths("super::face::*;"), ["super::face::*"]);
    let code = "pub use face::{FaceBox, find_face};\npub(crate) use scan::{\n    scan,\n};\nuse x::Y;";
    assert_eq!(without_reexports(code), "use x::Y;");
    assert!(defines("pub struct FaceBox {", "FaceBox") && !defines("pub struct FaceBoxes {", "FaceBox"));
}

#[test]
fn a_file_circle_through_a_facade_is_found() {
    let dir = std::env::temp_dir().join(format!("gpmm-arch-{}", std::process::id()));
    let src = dir.join("src");
    std::fs::create_dir_all(src.join("net")).expect("temp dir");
    let write = |p: &str, t: &str| std::fs::write(src.join(p), t).expect("write");
    write("lib.rs", "pub mod net;\n");
    write("net/mod.rs", "pub mod face;\npub mod agreement;\npub use face::FaceBox;\npub use agreement::mean_gap;\n");
    write("net/face.rs", "use super::mean_gap;\npub struct FaceBox;\n");
    write("net/agreement.rs", "use super::FaceBox;\npub fn mean_gap() {}\n");
    let circle = find_circle(&file_graph(&src));
    write("net/face.rs", "pub struct FaceBox;\n");
    let none = find_circle(&file_graph(&src));
    std::fs::remove_dir_all(&dir).ok();
    assert_eq!(circle.map(|c| c.len()), Some(3), "face -> agreement -> face");
    assert_eq!(none, None);
}
