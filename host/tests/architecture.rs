//! Architecture rules checked on the source tree: no import circle between the host library's
//! top-level modules, and no source file over 800 lines (tests aside).

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

/// The top-level module a file of `host/src` belongs to (`mesh` for `mesh/io/mod.rs`).
fn top_module(src: &Path, file: &Path) -> Option<String> {
    let rel = file.strip_prefix(src).ok()?;
    let first = rel.components().next()?.as_os_str().to_str()?;
    let name = first.strip_suffix(".rs").unwrap_or(first);
    (name != "lib").then(|| name.to_string())
}

/// Module names that `text` refers to as `crate::NAME`.
fn crate_refs(text: &str) -> BTreeSet<String> {
    let mut refs = BTreeSet::new();
    for (i, _) in text.match_indices("crate::") {
        let name: String = text[i + 7..].chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '_').collect();
        if !name.is_empty() {
            refs.insert(name);
        }
    }
    refs
}

#[test]
fn host_modules_form_no_import_circle() {
    let src = repo().join("host/src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    let mut graph: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for f in &files {
        let Some(module) = top_module(&src, f) else { continue };
        let text = std::fs::read_to_string(f).expect("read source");
        // Only the library code: a file's unit tests may use anything.
        let code: String = text
            .split("#[cfg(test)]")
            .next()
            .unwrap_or("")
            .lines()
            .filter(|l| !l.trim_start().starts_with("//"))
            .collect::<Vec<_>>()
            .join("\n");
        let deps = graph.entry(module.clone()).or_default();
        deps.extend(crate_refs(&code).into_iter().filter(|d| *d != module));
    }
    assert!(graph.len() >= 6, "expected the host's module folders, found {:?}", graph.keys());
    // Depth-first search for a cycle, reporting its path.
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
    for n in graph.keys() {
        if let Some(cycle) = visit(n, &graph, &mut Vec::new(), &mut done) {
            panic!("import circle between host modules: {}", cycle.join(" -> "));
        }
    }
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
