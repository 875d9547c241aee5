//! The repository's shape (docs/testing.md): a README for users, source files that fit in one's
//! head, and modules that import one another without cycles.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

/// Every `.rs` file under `dir`, sorted.
fn rust_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|x| x == "rs") {
                out.push(p);
            }
        }
    }
    out.sort();
    out
}

#[test]
fn the_readme_is_at_most_300_lines() {
    let text = std::fs::read_to_string(Path::new(ROOT).join("README.md")).unwrap();
    let lines = text.lines().count();
    assert!(lines <= 300, "README.md has {lines} lines");
}

#[test]
fn no_source_file_is_over_1000_lines() {
    let long: Vec<_> = rust_files(&Path::new(ROOT).join("src"))
        .into_iter()
        .map(|p| (std::fs::read_to_string(&p).unwrap().lines().count(), p))
        .filter(|(n, _)| *n > 1000)
        .collect();
    assert!(long.is_empty(), "files over 1000 lines: {long:?}");
}

/// The library's module path of a file under `src/` (`a/mod.rs` and `a.rs` are `a`, `lib.rs`
/// is the root ``); `None` for the binary.
fn module_of(src: &Path, file: &Path) -> Option<Vec<String>> {
    let rel = file.strip_prefix(src).unwrap().with_extension("");
    let mut parts: Vec<String> = rel
        .components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect();
    match parts.last().map(String::as_str) {
        Some("main") if parts.len() == 1 => return None,
        Some("mod") | Some("lib") => {
            parts.pop();
        }
        _ => {}
    }
    Some(parts)
}

/// The paths a file's code names: `crate::a::b` and `super::c`, with a `{..}` group's items
/// (over several lines too, nested groups by their heads), outside comments and the `tests`
/// module.
fn named_paths(text: &str) -> Vec<(bool, Vec<String>)> {
    let code: String = text
        .split("#[cfg(test)]\nmod tests")
        .next()
        .unwrap()
        .lines()
        .filter(|l| !l.trim_start().starts_with("//"))
        .collect::<Vec<_>>()
        .join("\n");
    let path_char = |c: char| c.is_alphanumeric() || c == '_' || c == ':';
    let mut out = Vec::new();
    for (anchor, is_super) in [("crate::", false), ("super::", true)] {
        for (at, _) in code.match_indices(anchor) {
            if code[..at].ends_with(path_char) {
                continue;
            }
            let rest = &code[at + anchor.len()..];
            let end = rest.find(|c: char| !path_char(c)).unwrap_or(rest.len());
            let path: Vec<String> = rest[..end]
                .split("::")
                .filter(|s| !s.is_empty())
                .map(String::from)
                .collect();
            if let Some(group) = rest[end..].strip_prefix('{') {
                // The group's top-level items, up to its closing brace.
                let (mut depth, mut item) = (0, String::new());
                for c in group.chars() {
                    match c {
                        '{' => depth += 1,
                        '}' if depth == 0 => break,
                        '}' => depth -= 1,
                        ',' if depth == 0 => {
                            out.extend(group_item(&path, &item).map(|p| (is_super, p)));
                            item.clear();
                            continue;
                        }
                        _ => {}
                    }
                    item.push(c);
                }
                out.extend(group_item(&path, &item).map(|p| (is_super, p)));
            }
            out.push((is_super, path));
        }
    }
    out
}

/// `path` extended by the head of a `use` group's item when that head is a module name
/// (lower case, not `self`).
fn group_item(path: &[String], item: &str) -> Option<Vec<String>> {
    let head = item.trim().split("::").next()?.trim();
    (head.starts_with(|c: char| c.is_lowercase()) && head != "self").then(|| {
        let mut p = path.to_vec();
        p.push(head.to_string());
        p
    })
}

#[test]
fn the_modules_import_one_another_without_cycles() {
    let src = Path::new(ROOT).join("src");
    let files: BTreeMap<Vec<String>, String> = rust_files(&src)
        .iter()
        .filter_map(|p| Some((module_of(&src, p)?, std::fs::read_to_string(p).unwrap())))
        .collect();
    // The longest module that is a prefix of `path`.
    let resolve = |path: &[String]| {
        (1..=path.len())
            .rev()
            .map(|n| path[..n].to_vec())
            .find(|m| files.contains_key(m))
    };
    // Edges between modules that are not each other's ancestors (a parent and its children
    // share one module's items by design).
    let mut edges: BTreeMap<Vec<String>, Vec<Vec<String>>> = BTreeMap::new();
    for (m, text) in &files {
        for (is_super, path) in named_paths(text) {
            let full = if is_super {
                let mut base = m[..m.len().saturating_sub(1)].to_vec();
                base.extend(path);
                base
            } else {
                path
            };
            let Some(to) = resolve(&full) else { continue };
            if !to.starts_with(m) && !m.starts_with(&to) {
                edges.entry(m.clone()).or_default().push(to);
            }
        }
    }
    // Depth-first search for a back edge; the cycle is reported as module paths.
    fn visit(
        m: &Vec<String>,
        edges: &BTreeMap<Vec<String>, Vec<Vec<String>>>,
        state: &mut BTreeMap<Vec<String>, u8>,
        stack: &mut Vec<Vec<String>>,
    ) -> Option<Vec<String>> {
        state.insert(m.clone(), 1);
        stack.push(m.clone());
        for to in edges.get(m).into_iter().flatten() {
            match state.get(to) {
                Some(1) => {
                    let from = stack.iter().position(|s| s == to).unwrap();
                    return Some(stack[from..].iter().map(|s| s.join("::")).collect());
                }
                Some(_) => {}
                None => {
                    if let Some(c) = visit(to, edges, state, stack) {
                        return Some(c);
                    }
                }
            }
        }
        stack.pop();
        state.insert(m.clone(), 2);
        None
    }
    let mut state = BTreeMap::new();
    for m in files.keys() {
        if !state.contains_key(m) {
            let cycle = visit(m, &edges, &mut state, &mut Vec::new());
            assert!(cycle.is_none(), "an import cycle: {cycle:?}");
        }
    }
    assert!(edges.len() > 20, "the module graph was not read: {edges:?}");
}
