//! The workspace's shape, checked on every test run: no two modules of one crate import
//! each other (directly or around a circle), no `.rs` file over 600 lines, thin `main.rs`.
//!
//! Module dependencies are read from the source: every `crate::…` and `super::…` path
//! (in `use` trees and in expressions), resolved to the module file it names. An edge
//! between two modules is lifted to the children of their common parent (so `a::x` using
//! `b::y` is an edge `a → b` among the children of the crate root); edges between a module
//! and its own ancestors (a `mod.rs` using its children, a child using `super::`) are
//! allowed. Each folder's children must then form a DAG.
//!
//! The documents that describe this shape (DESIGN §2 and §8, the README's crate list,
//! each `lib.rs`'s module docs) are checked against it in `layout/docs.rs`.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

#[path = "layout/docs.rs"]
mod docs;

const MAX_LINES: usize = 600;
const MAX_MAIN_LINES: usize = 150;

fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .canonicalize()
        .unwrap()
}

/// The workspace's crate folders (those with a `Cargo.toml` and a `src/`).
fn crate_dirs() -> Vec<PathBuf> {
    let mut dirs: Vec<PathBuf> = std::fs::read_dir(workspace_root())
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.join("Cargo.toml").is_file() && p.join("src").is_dir())
        .collect();
    dirs.sort();
    dirs
}

type ModPath = Vec<String>;

/// Library module files under `src/`: module path → file (`lib.rs` is the root; `main.rs`
/// and `src/bin/` belong to binaries and are left out).
fn module_files(src: &Path) -> BTreeMap<ModPath, PathBuf> {
    fn walk(dir: &Path, prefix: &ModPath, out: &mut BTreeMap<ModPath, PathBuf>) {
        let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)
            .unwrap()
            .filter_map(|e| e.ok().map(|e| e.path()))
            .collect();
        entries.sort();
        for p in entries {
            let name = p.file_name().unwrap().to_string_lossy().to_string();
            if p.is_dir() {
                if prefix.is_empty() && name == "bin" {
                    continue;
                }
                let mut sub = prefix.clone();
                sub.push(name);
                walk(&p, &sub, out);
            } else if let Some(stem) = name.strip_suffix(".rs") {
                let path = match stem {
                    "lib" | "main" if prefix.is_empty() => {
                        if stem == "main" {
                            continue;
                        }
                        prefix.clone()
                    }
                    "mod" => prefix.clone(),
                    _ => {
                        let mut m = prefix.clone();
                        m.push(stem.to_string());
                        m
                    }
                };
                out.insert(path, p);
            }
        }
    }
    let mut out = BTreeMap::new();
    walk(src, &Vec::new(), &mut out);
    out
}

/// Source with comments, string and char literals blanked (same length, newlines kept).
fn strip(src: &str) -> String {
    let b = src.as_bytes();
    let mut out = b.to_vec();
    let mut i = 0;
    let blank = |out: &mut Vec<u8>, from: usize, to: usize| {
        for c in &mut out[from..to] {
            if *c != b'\n' {
                *c = b' ';
            }
        }
    };
    while i < b.len() {
        if b[i..].starts_with(b"//") {
            let end = b[i..]
                .iter()
                .position(|&c| c == b'\n')
                .map_or(b.len(), |p| i + p);
            blank(&mut out, i, end);
            // Doc comments keep their intra-doc links (`[`crate::x`]`): rustdoc resolves
            // them, so they are dependencies too.
            if b[i..].starts_with(b"///") || b[i..].starts_with(b"//!") {
                for kw in [&b"crate::"[..], &b"super::"[..]] {
                    let mut j = i;
                    while let Some(p) = (j..end).find(|&k| b[k..end].starts_with(kw)) {
                        let mut e = p + kw.len();
                        while e < end && (is_ident(b[e]) || b[e] == b':') {
                            e += 1;
                        }
                        out[p..e].copy_from_slice(&b[p..e]);
                        j = e;
                    }
                }
            }
            i = end;
        } else if b[i..].starts_with(b"/*") {
            let mut depth = 0;
            let mut j = i;
            while j < b.len() {
                if b[j..].starts_with(b"/*") {
                    depth += 1;
                    j += 2;
                } else if b[j..].starts_with(b"*/") {
                    depth -= 1;
                    j += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    j += 1;
                }
            }
            blank(&mut out, i, j.min(b.len()));
            i = j;
        } else if b[i] == b'r'
            && (b[i..].starts_with(b"r\"") || b[i..].starts_with(b"r#"))
            && (i == 0 || !(b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_'))
        {
            let hashes = b[i + 1..].iter().take_while(|&&c| c == b'#').count();
            if b.get(i + 1 + hashes) != Some(&b'"') {
                i += 1;
                continue;
            }
            let close: Vec<u8> = std::iter::once(b'"')
                .chain(std::iter::repeat_n(b'#', hashes))
                .collect();
            let start = i + 2 + hashes;
            let end = (start..b.len())
                .find(|&j| b[j..].starts_with(&close))
                .map_or(b.len(), |j| j + close.len());
            blank(&mut out, i, end);
            i = end;
        } else if b[i] == b'"' {
            let mut j = i + 1;
            while j < b.len() && b[j] != b'"' {
                j += if b[j] == b'\\' { 2 } else { 1 };
            }
            let end = (j + 1).min(b.len());
            blank(&mut out, i, end);
            i = end;
        } else if b[i] == b'\'' {
            // A char literal ('x', '\n', '\''); a lifetime ('a) is left alone.
            let end = if b.get(i + 1) == Some(&b'\\') {
                (i + 2..b.len())
                    .find(|&j| b[j] == b'\'' && j > i + 2)
                    .map(|j| j + 1)
            } else if b.get(i + 2) == Some(&b'\'') {
                Some(i + 3)
            } else {
                None
            };
            match end {
                Some(e) => {
                    blank(&mut out, i, e);
                    i = e;
                }
                None => i += 1,
            }
        } else {
            i += 1;
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

fn is_ident(c: u8) -> bool {
    c.is_ascii_alphanumeric() || c == b'_'
}

/// The paths of a use tree (or a plain path) starting at `i`: `a::b::{c, d::e}` gives
/// `[a,b,c]`, `[a,b,d,e]`.
fn parse_tree(b: &[u8], mut i: usize, prefix: Vec<String>, out: &mut Vec<Vec<String>>) -> usize {
    let skip_ws = |i: &mut usize| {
        while *i < b.len() && b[*i].is_ascii_whitespace() {
            *i += 1;
        }
    };
    let mut path = prefix;
    loop {
        skip_ws(&mut i);
        if i < b.len() && b[i] == b'{' {
            i += 1;
            loop {
                skip_ws(&mut i);
                if i >= b.len() || b[i] == b'}' {
                    return i + 1;
                }
                i = parse_tree(b, i, path.clone(), out);
                skip_ws(&mut i);
                if i < b.len() && b[i] == b',' {
                    i += 1;
                }
            }
        }
        let start = i;
        while i < b.len() && is_ident(b[i]) {
            i += 1;
        }
        if i > start {
            path.push(String::from_utf8_lossy(&b[start..i]).into_owned());
        }
        let mut j = i;
        skip_ws(&mut j);
        if b[j..].starts_with(b"::") {
            i = j + 2;
            continue;
        }
        out.push(path);
        return i;
    }
}

/// Inline `mod name { … }` blocks: (start, end, name) byte ranges, outermost first.
fn inline_mods(b: &[u8]) -> Vec<(usize, usize, String)> {
    let mut mods = Vec::new();
    let mut i = 0;
    while let Some(p) = find(b, i, b"mod ") {
        i = p + 4;
        if p > 0 && is_ident(b[p - 1]) {
            continue;
        }
        let name_start = i;
        while i < b.len() && is_ident(b[i]) {
            i += 1;
        }
        let name = String::from_utf8_lossy(&b[name_start..i]).into_owned();
        let mut j = i;
        while j < b.len() && b[j].is_ascii_whitespace() {
            j += 1;
        }
        if j < b.len() && b[j] == b'{' {
            let mut depth = 0;
            let mut k = j;
            while k < b.len() {
                match b[k] {
                    b'{' => depth += 1,
                    b'}' => {
                        depth -= 1;
                        if depth == 0 {
                            break;
                        }
                    }
                    _ => {}
                }
                k += 1;
            }
            mods.push((j, k, name));
        }
    }
    mods
}

fn find(b: &[u8], from: usize, pat: &[u8]) -> Option<usize> {
    (from..b.len().saturating_sub(pat.len() - 1)).find(|&i| b[i..].starts_with(pat))
}

/// Module-level dependencies of one crate: (from module, to module) → a file that shows it.
fn dependencies(src: &Path) -> BTreeMap<(ModPath, ModPath), PathBuf> {
    let files = module_files(src);
    let resolve = |path: &[String]| -> Option<ModPath> {
        (0..=path.len())
            .rev()
            .map(|n| path[..n].to_vec())
            .find(|p| files.contains_key(p))
    };
    let mut deps = BTreeMap::new();
    for (module, file) in &files {
        let text = strip(&std::fs::read_to_string(file).unwrap());
        let b = text.as_bytes();
        let mods = inline_mods(b);
        for (kw, relative) in [("crate::", false), ("super::", true)] {
            let mut i = 0;
            while let Some(p) = find(b, i, kw.as_bytes()) {
                i = p + kw.len();
                if p > 0 && (is_ident(b[p - 1]) || b[p - 1] == b'$' || b[p - 1] == b':') {
                    continue;
                }
                let mut paths = Vec::new();
                let mut supers = 1;
                let mut at = i;
                if relative {
                    while b[at..].starts_with(b"super::") {
                        supers += 1;
                        at += 7;
                    }
                    i = at;
                }
                parse_tree(b, at, Vec::new(), &mut paths);
                // The module the reference sits in (inline modules nest inside the file's).
                let base: Vec<String> = if relative {
                    let mut here = module.clone();
                    here.extend(
                        mods.iter()
                            .filter(|(s, e, _)| *s < p && p < *e)
                            .map(|(_, _, n)| n.clone()),
                    );
                    if supers > here.len() {
                        continue;
                    }
                    here[..here.len() - supers].to_vec()
                } else {
                    Vec::new()
                };
                for tail in paths {
                    let mut full = base.clone();
                    full.extend(tail.into_iter().filter(|s| s != "self"));
                    if let Some(target) = resolve(&full)
                        && &target != module
                    {
                        deps.entry((module.clone(), target))
                            .or_insert_with(|| file.clone());
                    }
                }
            }
        }
    }
    deps
}

/// Cycles among siblings: each as "a → b → a (parent)" with a file for each edge.
fn sibling_cycles(src: &Path) -> Vec<String> {
    let mut graphs: BTreeMap<ModPath, BTreeMap<String, BTreeSet<String>>> = BTreeMap::new();
    let mut witness: BTreeMap<(ModPath, String, String), PathBuf> = BTreeMap::new();
    for ((from, to), file) in dependencies(src) {
        let common = from.iter().zip(&to).take_while(|(a, b)| a == b).count();
        if common == from.len() || common == to.len() {
            continue; // a module and its ancestor
        }
        let parent = from[..common].to_vec();
        let (a, b) = (from[common].clone(), to[common].clone());
        graphs
            .entry(parent.clone())
            .or_default()
            .entry(a.clone())
            .or_default()
            .insert(b.clone());
        witness.entry((parent, a, b)).or_insert(file);
    }
    let mut cycles = Vec::new();
    for (parent, graph) in &graphs {
        // Depth-first search with colours; report each back edge's cycle.
        let mut state: BTreeMap<&str, u8> = BTreeMap::new();
        fn visit<'a>(
            n: &'a str,
            g: &'a BTreeMap<String, BTreeSet<String>>,
            state: &mut BTreeMap<&'a str, u8>,
            stack: &mut Vec<&'a str>,
            found: &mut Vec<Vec<String>>,
        ) {
            state.insert(n, 1);
            stack.push(n);
            for m in g.get(n).into_iter().flatten() {
                match state.get(m.as_str()) {
                    Some(1) => {
                        let at = stack.iter().position(|s| *s == m).unwrap();
                        let mut c: Vec<String> =
                            stack[at..].iter().map(|s| s.to_string()).collect();
                        c.push(m.clone());
                        found.push(c);
                    }
                    Some(_) => {}
                    None => visit(m, g, state, stack, found),
                }
            }
            stack.pop();
            state.insert(n, 2);
        }
        let mut found = Vec::new();
        for n in graph.keys() {
            if !state.contains_key(n.as_str()) {
                visit(n, graph, &mut state, &mut Vec::new(), &mut found);
            }
        }
        for c in found {
            let edges: Vec<String> = c
                .windows(2)
                .map(|w| {
                    let f = &witness[&(parent.clone(), w[0].clone(), w[1].clone())];
                    format!("{} → {} ({})", w[0], w[1], f.display())
                })
                .collect();
            let place = if parent.is_empty() {
                "crate root".to_string()
            } else {
                parent.join("::")
            };
            cycles.push(format!("in {place}: {}", edges.join(", ")));
        }
    }
    cycles
}

#[test]
fn no_module_imports_another_that_imports_it_back() {
    let mut all = Vec::new();
    for dir in crate_dirs() {
        for c in sibling_cycles(&dir.join("src")) {
            all.push(format!(
                "{}: {c}",
                dir.file_name().unwrap().to_string_lossy()
            ));
        }
    }
    assert!(all.is_empty(), "module cycles:\n{}", all.join("\n"));
}

#[test]
fn the_cycle_check_finds_cycles() {
    let tmp = tempfile::tempdir().unwrap();
    let src = tmp.path();
    std::fs::create_dir_all(src.join("net")).unwrap();
    let write = |p: &str, s: &str| std::fs::write(src.join(p), s).unwrap();
    write(
        "lib.rs",
        "pub mod a;\npub mod b;\npub mod c;\npub mod d;\npub mod e;\npub mod net;\n",
    );
    // a → b directly, b → c in an expression, c → a through a grouped use tree: a circle.
    write(
        "a.rs",
        "use crate::b::Thing;\n// use crate::c; (a comment is no import)\n",
    );
    write("b.rs", "pub struct Thing;\nfn f() { crate::c::g(); }\n");
    // A doc link is a dependency too (rustdoc resolves it).
    write("d.rs", "//! See [`crate::e`].\n");
    write("e.rs", "use crate::d;\n");
    write(
        "c.rs",
        "use crate::{a::{self}, net::flow};\npub fn g() {}\n",
    );
    // Inside net/: flow ↔ lora through super::, and a child using its parent (allowed).
    write(
        "net/mod.rs",
        "pub mod flow;\npub mod lora;\npub use flow::Net;\n",
    );
    write("net/flow.rs", "use super::lora::Lora;\npub struct Net;\n");
    write(
        "net/lora.rs",
        "use super::flow::Net;\nuse super::*;\npub struct Lora;\n#[cfg(test)]\nmod tests { use super::Lora; }\n",
    );
    let cycles = sibling_cycles(src);
    assert_eq!(cycles.len(), 3, "{cycles:#?}");
    assert!(cycles[0].starts_with("in crate root: a → b"), "{cycles:#?}");
    assert!(cycles[0].contains("c → a"), "{cycles:#?}");
    assert!(cycles[1].starts_with("in crate root: d → e"), "{cycles:#?}");
    assert!(cycles[2].starts_with("in net: flow → lora"), "{cycles:#?}");
    // Without the back edges there is none.
    write("c.rs", "pub fn g() {}\n");
    write("d.rs", "//! See the e module.\n");
    write("net/lora.rs", "use super::*;\npub struct Lora;\n");
    assert!(sibling_cycles(src).is_empty());
}

#[test]
fn no_source_file_is_over_600_lines_and_main_rs_is_thin() {
    let mut long = Vec::new();
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        for e in std::fs::read_dir(dir).unwrap().flatten() {
            let p = e.path();
            let name = p.file_name().unwrap().to_string_lossy().to_string();
            if p.is_dir() {
                if name != "target" && !name.starts_with('.') {
                    walk(&p, out);
                }
            } else if name.ends_with(".rs") {
                out.push(p);
            }
        }
    }
    let mut files = Vec::new();
    for dir in crate_dirs() {
        walk(&dir, &mut files);
    }
    assert!(files.len() > 50, "found only {} .rs files", files.len());
    for f in files {
        let lines = std::fs::read_to_string(&f).unwrap().lines().count();
        let main = f.file_name().is_some_and(|n| n == "main.rs");
        let limit = if main { MAX_MAIN_LINES } else { MAX_LINES };
        if lines > limit {
            long.push(format!("{}: {lines} lines (limit {limit})", f.display()));
        }
    }
    assert!(
        long.is_empty(),
        "files over the limit:\n{}",
        long.join("\n")
    );
}
