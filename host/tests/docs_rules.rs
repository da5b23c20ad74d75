//! Documentation rules checked on the repository: the project speaks of itself to its users, so no
//! text file names work-period numbers, issue numbers or branch names; the evaluation, learning and
//! real-photo references and the README stay short; and every relative link of the README and of
//! `docs/*.md` leads to a file (and to a heading of it, where it names one).

use std::path::{Path, PathBuf};

/// Longest `docs/evaluation.md` may grow (lines).
const EVALUATION_MAX_LINES: usize = 600;
/// Longest `README.md` may grow (lines).
const README_MAX_LINES: usize = 200;
/// Longest `docs/learning.md` may grow (lines): under 350.
const LEARNING_MAX_LINES: usize = 349;
/// Longest `docs/real-photos.md` may grow (lines): under 350.
const REAL_PHOTOS_MAX_LINES: usize = 349;

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Directories that hold build outputs, caches or version control, not the project's files.
fn skipped_dir(root: &Path, dir: &Path) -> bool {
    let name = dir.file_name().and_then(|n| n.to_str()).unwrap_or("");
    let hidden = name.starts_with('.') && name != ".ci";
    hidden || name == "target" || name == "__pycache__" || name == "node_modules" || dir == root.join("out")
}

/// Every file under `dir`, build outputs and version control left out.
fn files(root: &Path, dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display())) {
        let path = entry.expect("directory entry").path();
        if path.is_dir() {
            if !skipped_dir(root, &path) {
                files(root, &path, out);
            }
        } else if path.is_file() {
            out.push(path);
        }
    }
}

/// The file's text, or `None` for a binary file (a NUL byte, or not UTF-8).
fn text(path: &Path) -> Option<String> {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    if bytes.contains(&0) {
        return None;
    }
    String::from_utf8(bytes).ok()
}

fn is_word(c: char) -> bool {
    c.is_alphanumeric() || c == '_'
}

/// Whether `line` names, ignoring case, a numbered work-period or issue ("stop" or "stops", or
/// "issue", then a space and a digit, after a word boundary), a numbered branch ("branch", a space,
/// letters, a digit) or work-periods themselves (the two words with a space between): the
/// repository-wide check written by hand, without a regular-expression crate.
fn names_a_work_period(line: &str) -> bool {
    let lower = line.to_lowercase();
    let chars: Vec<char> = lower.chars().collect();
    let at = |i: usize, word: &str| word.chars().enumerate().all(|(k, c)| chars.get(i + k) == Some(&c));
    let digit = |i: usize| chars.get(i).is_some_and(|c| c.is_ascii_digit());
    for i in 0..chars.len() {
        let boundary = i == 0 || !is_word(chars[i - 1]);
        if boundary && at(i, "stop") {
            let j = if at(i + 4, "s") { i + 5 } else { i + 4 };
            if at(j, " ") && digit(j + 1) {
                return true;
            }
        }
        if boundary && at(i, "issue ") && digit(i + 6) {
            return true;
        }
        if at(i, "branch ") {
            let mut j = i + 7;
            while chars.get(j).is_some_and(|c| c.is_ascii_lowercase()) {
                j += 1;
            }
            if j > i + 7 && digit(j) {
                return true;
            }
        }
        if at(i, "work") && at(i + 4, " period") {
            return true;
        }
    }
    false
}

#[test]
fn the_pattern_is_matched_as_the_regex_would() {
    // Spelled in pieces so that this file itself stays clean.
    let hit = |a: &str, b: &str| names_a_work_period(&[a, b].concat());
    assert!(hit("measured at st", "op 36"));
    assert!(hit("St", "ops 34 and 35"));
    assert!(hit("(Iss", "ue 13's targets)"));
    assert!(hit("on bran", "ch speed14"));
    assert!(hit("a wo", "rk period"));
    assert!(!hit("nons", "top 3"), "a word boundary is needed before the word");
    assert!(!hit("st", "op the chain"));
    assert!(!hit("st", "ops? [0-9]+"));
    assert!(!hit("iss", "ue tracker"));
    assert!(!hit("bran", "ch 14"), "a branch name starts with letters");
    assert!(!hit("wo", "rk-period"));
}

#[test]
fn no_file_names_work_periods_issues_or_branches() {
    let root = repo();
    let mut all = Vec::new();
    files(&root, &root, &mut all);
    all.sort();
    let mut found = Vec::new();
    for path in &all {
        let Some(text) = text(path) else { continue };
        for (n, line) in text.lines().enumerate() {
            if names_a_work_period(line) {
                let rel = path.strip_prefix(&root).unwrap_or(path);
                found.push(format!("{}:{}: {}", rel.display(), n + 1, line.trim()));
            }
        }
    }
    assert!(
        found.is_empty(),
        "cite sections or commits instead of work-period numbers, issue numbers or branch names:\n{}",
        found.join("\n")
    );
}

fn line_count(rel: &str) -> usize {
    let path = repo().join(rel);
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display())).lines().count()
}

#[test]
fn the_evaluation_reference_and_the_readme_stay_short() {
    let evaluation = line_count("docs/evaluation.md");
    assert!(evaluation <= EVALUATION_MAX_LINES, "docs/evaluation.md has {evaluation} lines, at most {EVALUATION_MAX_LINES}");
    let readme = line_count("README.md");
    assert!(readme <= README_MAX_LINES, "README.md has {readme} lines, at most {README_MAX_LINES}");
}

#[test]
fn the_learning_and_real_photo_references_stay_short() {
    let learning = line_count("docs/learning.md");
    assert!(learning <= LEARNING_MAX_LINES, "docs/learning.md has {learning} lines, at most {LEARNING_MAX_LINES}");
    let real_photos = line_count("docs/real-photos.md");
    assert!(real_photos <= REAL_PHOTOS_MAX_LINES, "docs/real-photos.md has {real_photos} lines, at most {REAL_PHOTOS_MAX_LINES}");
}

/// The targets of the Markdown links and images of `text` (`[..](target)`), outside code.
fn link_targets(text: &str) -> Vec<String> {
    let mut targets = Vec::new();
    let mut fenced = false;
    for line in text.lines() {
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
            continue;
        }
        if fenced {
            continue;
        }
        // Inline code spans hold commands and code, not links.
        let prose: String = line.split('`').step_by(2).collect::<Vec<_>>().join(" ");
        for (i, _) in prose.match_indices("](") {
            let rest = &prose[i + 2..];
            let end = rest.find(')').unwrap_or(rest.len());
            let target = rest[..end].split_whitespace().next().unwrap_or("");
            targets.push(target.to_string());
        }
    }
    targets
}

/// Whether a link target leaves the repository (a web address).
fn external(target: &str) -> bool {
    target.is_empty() || target.contains("://") || target.starts_with("mailto:")
}

/// The anchors of a Markdown page's headings, as GitHub makes them: lower case, punctuation
/// dropped, spaces as hyphens, a repeated heading numbered `-1`, `-2`, …
fn anchors(text: &str) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    let mut fenced = false;
    for line in text.lines() {
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
            continue;
        }
        let Some(title) = line.strip_prefix('#').filter(|_| !fenced) else { continue };
        let title = title.trim_start_matches('#').trim();
        let slug: String = title
            .to_lowercase()
            .chars()
            .filter_map(|c| match c {
                ' ' => Some('-'),
                c if c.is_alphanumeric() || c == '-' || c == '_' => Some(c),
                _ => None,
            })
            .collect();
        let repeats = out
            .iter()
            .filter(|a| **a == slug || a.strip_prefix(&slug).is_some_and(|r| r.starts_with('-') && r[1..].parse::<u32>().is_ok()))
            .count();
        out.push(if repeats == 0 { slug } else { format!("{slug}-{repeats}") });
    }
    out
}

#[test]
fn anchors_are_made_as_github_makes_them() {
    let text = "# The device\n## Where the 10 % comes from\n### Known limits\n```\n# not a heading\n```\n### Known limits";
    assert_eq!(anchors(text), ["the-device", "where-the-10--comes-from", "known-limits", "known-limits-1"]);
}

#[test]
fn links_are_found() {
    let text = "See [the docs](docs/a.md#part), ![a figure](images/b.png \"title\") and [web](https://x.org).\n\
                ```sh\ncat [x](not/a/link.md)\n```\n`[y](code.md)` is code.";
    assert_eq!(link_targets(text), ["docs/a.md#part", "images/b.png", "https://x.org"]);
}

#[test]
fn relative_links_of_the_docs_lead_to_files() {
    let root = repo();
    let mut pages = vec![root.join("README.md")];
    let docs = root.join("docs");
    for entry in std::fs::read_dir(&docs).unwrap_or_else(|e| panic!("{}: {e}", docs.display())) {
        let path = entry.expect("directory entry").path();
        if path.extension().is_some_and(|e| e == "md") {
            pages.push(path);
        }
    }
    pages.sort();
    let mut broken = Vec::new();
    for page in &pages {
        let text = std::fs::read_to_string(page).unwrap_or_else(|e| panic!("{}: {e}", page.display()));
        let dir = page.parent().expect("a page lies in a directory");
        for target in link_targets(&text) {
            if external(&target) {
                continue;
            }
            let (file, anchor) = target.split_once('#').unwrap_or((&target, ""));
            let path = if file.is_empty() { page.clone() } else { dir.join(file) };
            let exists = path.exists();
            let anchored = anchor.is_empty()
                || path.extension().is_none_or(|e| e != "md")
                || !exists
                || anchors(&std::fs::read_to_string(&path).unwrap_or_default()).iter().any(|a| a == anchor);
            if !exists || !anchored {
                broken.push(format!("{}: {target}", page.strip_prefix(&root).unwrap_or(page).display()));
            }
        }
    }
    assert!(broken.is_empty(), "links to files or headings that do not exist:\n{}", broken.join("\n"));
}
