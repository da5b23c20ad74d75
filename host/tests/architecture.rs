//! Architecture rules checked on the source tree: no import circle between the top-level modules
//! of the host library, the `gpmm` program and the firmware, and no source file over 800 lines
//! (tests aside).

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

/// Asserts that the crate in `dir` (relative to the repository) has at least `modules`
/// top-level modules and no import circle between them.
fn assert_no_import_circle(dir: &str, modules: usize) {
    let graph = module_graph(&repo().join(dir));
    assert!(graph.len() >= modules, "expected the modules of {dir}, found {:?}", graph.keys());
    if let Some(circle) = find_circle(&graph) {
        panic!("import circle between the modules of {dir}: {}", circle.join(" -> "));
    }
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

#[test]
fn no_source_file_is_over_800_lines() {
    let mut files = Vec::new();
    for dir in ["core/src", "host/src", "host/cli/src", "firmware-sim/src", "tests/src"] {
        let d = repo().join(dir);
        if d.is_dir() {
            rust_files(&d, &mut files);
        }
    }
    assert!(files.len() > 40, "found only {} source files", files.len());
    let long: Vec<String> = files
        .iter()
        .filter_map(|f| {
            let text = std::fs::read_to_string(f).expect("read source");
            // A file's own unit tests do not count.
            let code = text.split("\n#[cfg(test)]").next().unwrap_or("");
            let n = code.lines().count();
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
