//! The module graph: every `crate::` path in `src/` (and `super::` out of a top-level file),
//! collected per top-level module, has no cycle, and every edge goes down the layers that
//! `docs/architecture.md` lists — so a new import against the grain fails here, naming the
//! file, the line and the cycle.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// A module's imports of other top-level modules: target → (file, line) of the first use.
type Edges = BTreeMap<String, BTreeMap<String, (PathBuf, usize)>>;

/// The top-level modules of `src/` (files and folders, `lib.rs` and `main.rs` aside).
fn modules(src: &Path) -> BTreeSet<String> {
    std::fs::read_dir(src)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter_map(|p| {
            let name = p.file_stem()?.to_string_lossy().to_string();
            (p.is_dir() || p.extension().is_some_and(|e| e == "rs")).then_some(name)
        })
        .filter(|n| n != "lib" && n != "main")
        .collect()
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|e| e == "rs") {
            out.push(p);
        }
    }
}

/// The names a path written after `crate::` starts with: `a` in `crate::a::b`, each of `a`,
/// `b` in `crate::{a::x, b}`.
fn first_segments(rest: &str) -> Vec<String> {
    let ident = |s: &str| s.chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect::<String>();
    match rest.strip_prefix('{') {
        Some(inner) => {
            let mut depth = 0;
            let mut names = Vec::new();
            let mut start = true;
            for (i, c) in inner.char_indices() {
                match c {
                    '{' => depth += 1,
                    '}' if depth == 0 => break,
                    '}' => depth -= 1,
                    ',' if depth == 0 => start = true,
                    c if start && !c.is_whitespace() => {
                        names.push(ident(&inner[i..]));
                        start = false;
                    }
                    _ => {}
                }
            }
            names
        }
        None => vec![ident(rest)],
    }
}

/// Every edge between top-level modules, from the code (comments and doc comments left out).
/// `macros`: crate-root macros (`#[macro_export]`) and the module that defines each.
fn edges(src: &Path, mods: &BTreeSet<String>) -> Edges {
    let mut files = Vec::new();
    rust_files(src, &mut files);
    files.sort();
    let mut macros = BTreeMap::new();
    for f in &files {
        let text = std::fs::read_to_string(f).unwrap();
        let mut exported = false;
        for l in text.lines() {
            if l.contains("#[macro_export]") {
                exported = true;
            } else if let (true, Some(rest)) = (exported, l.trim().strip_prefix("macro_rules! ")) {
                macros.insert(rest.trim_end_matches(" {").to_string(), owner(src, f));
                exported = false;
            }
        }
    }
    let mut out = Edges::new();
    for f in &files {
        let from = owner(src, f);
        if from.is_empty() {
            continue;
        }
        let top_file = f.parent() == Some(src);
        let text = std::fs::read_to_string(f).unwrap();
        for (n, line) in text.lines().enumerate() {
            let code = line.split("//").next().unwrap_or("");
            let mut refs = Vec::new();
            for pat in ["crate::", "halftrace::"] {
                for (i, _) in code.match_indices(pat) {
                    let before = code[..i].chars().last();
                    if before.is_some_and(|c| c.is_alphanumeric() || c == '_') {
                        continue;
                    }
                    refs.extend(first_segments(&code[i + pat.len()..]));
                }
            }
            if top_file {
                for (i, _) in code.match_indices("super::") {
                    refs.extend(first_segments(&code[i + 7..]));
                }
            }
            for r in refs {
                let to = if mods.contains(&r) {
                    r
                } else if let Some(m) = macros.get(&r) {
                    m.clone()
                } else {
                    continue;
                };
                if to != from {
                    out.entry(from.clone()).or_default().entry(to).or_insert((f.clone(), n + 1));
                }
            }
        }
    }
    out
}

/// The top-level module a file belongs to ("" for `lib.rs`, `main.rs`).
fn owner(src: &Path, f: &Path) -> String {
    let rel = f.strip_prefix(src).unwrap();
    let first = rel.components().next().unwrap().as_os_str().to_string_lossy().to_string();
    let name = first.trim_end_matches(".rs").to_string();
    if name == "lib" || name == "main" {
        String::new()
    } else {
        name
    }
}

/// A cycle of `g`, as the modules along it (the first repeated at the end), if any.
fn find_cycle(g: &BTreeMap<String, BTreeSet<String>>) -> Option<Vec<String>> {
    fn visit(
        g: &BTreeMap<String, BTreeSet<String>>,
        n: &str,
        state: &mut BTreeMap<String, u8>,
        path: &mut Vec<String>,
    ) -> Option<Vec<String>> {
        state.insert(n.to_string(), 1);
        path.push(n.to_string());
        for m in g.get(n).into_iter().flatten() {
            match state.get(m.as_str()).copied().unwrap_or(0) {
                1 => {
                    let i = path.iter().position(|p| p == m).unwrap();
                    let mut c = path[i..].to_vec();
                    c.push(m.clone());
                    return Some(c);
                }
                0 => {
                    if let Some(c) = visit(g, m, state, path) {
                        return Some(c);
                    }
                }
                _ => {}
            }
        }
        path.pop();
        state.insert(n.to_string(), 2);
        None
    }
    let mut state = BTreeMap::new();
    for n in g.keys() {
        if state.get(n.as_str()).copied().unwrap_or(0) == 0 {
            if let Some(c) = visit(g, n, &mut state, &mut Vec::new()) {
                return Some(c);
            }
        }
    }
    None
}

/// The layers of `docs/architecture.md`'s table (`| N | a, b, … |` rows under "## Layers"):
/// module → layer number.
fn layers(doc: &str) -> BTreeMap<String, usize> {
    let section = doc.split("## Layers").nth(1).expect("docs/architecture.md has a '## Layers' section");
    let mut out = BTreeMap::new();
    for line in section.lines().take_while(|l| !l.starts_with("## ")) {
        let cells: Vec<&str> = line.split('|').map(str::trim).collect();
        if let (Some(n), Some(mods)) = (cells.get(1).and_then(|c| c.parse::<usize>().ok()), cells.get(2)) {
            for m in mods.split(',') {
                out.insert(m.trim().trim_matches('`').to_string(), n);
            }
        }
    }
    out
}

#[test]
fn top_level_modules_form_layers_without_a_cycle() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let src = root.join("src");
    let mods = modules(&src);
    let e = edges(&src, &mods);
    let graph: BTreeMap<String, BTreeSet<String>> =
        e.iter().map(|(k, v)| (k.clone(), v.keys().cloned().collect())).collect();
    let where_ = |a: &str, b: &str| {
        let (f, l) = &e[a][b];
        format!("{}:{l}", f.strip_prefix(&root).unwrap().display())
    };
    if let Some(c) = find_cycle(&graph) {
        let steps: Vec<String> =
            c.windows(2).map(|w| format!("{} → {} ({})", w[0], w[1], where_(&w[0], &w[1]))).collect();
        panic!("the top-level modules import each other in a cycle:\n  {}", steps.join("\n  "));
    }
    let doc = std::fs::read_to_string(root.join("docs/architecture.md")).unwrap();
    let layer = layers(&doc);
    let unlisted: Vec<&String> = mods.iter().filter(|m| !layer.contains_key(*m)).collect();
    assert!(unlisted.is_empty(), "modules missing from docs/architecture.md's layer table: {unlisted:?}");
    let mut wrong = Vec::new();
    for (a, tos) in &graph {
        for b in tos {
            if layer[b] >= layer[a] {
                wrong.push(format!("{a} (layer {}) imports {b} (layer {}) at {}", layer[a], layer[b], where_(a, b)));
            }
        }
    }
    assert!(wrong.is_empty(), "imports against the layers of docs/architecture.md:\n  {}", wrong.join("\n  "));
    let n: usize = graph.values().map(BTreeSet::len).sum();
    eprintln!("{} top-level modules, {n} edges between them, all downward", mods.len());
}

/// The check can fail: a planted cycle is found and spelled out; paths in braces count.
#[test]
fn a_planted_cycle_is_found() {
    let g = |edges: &[(&str, &str)]| {
        let mut m: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
        for (a, b) in edges {
            m.entry(a.to_string()).or_default().insert(b.to_string());
        }
        m
    };
    assert_eq!(find_cycle(&g(&[("runner", "gpu"), ("gpu", "base"), ("sweep", "runner")])), None);
    let c = find_cycle(&g(&[("runner", "gpu"), ("gpu", "layout"), ("layout", "runner"), ("sweep", "runner")])).unwrap();
    assert_eq!((c.first(), c.last(), c.len()), (c.last(), c.first(), 4), "{c:?}");
    assert_eq!(first_segments("{base::Ray, layout::{Encoded, LayoutId}, scene}"), ["base", "layout", "scene"]);
    assert_eq!(first_segments("gpu::Gpu;"), ["gpu"]);
}

/// Edges between the parts of one folder module `dir` (named `name` under `crate::`): a part is
/// a file or subfolder directly in `dir` (`mod.rs`, the module's interface, aside); part A
/// imports part B where a file of A writes `crate::name::B`, or `super::B` from a file directly
/// in `dir`, or `super::super::B` one folder down. Part → part → (file, line) of the first use.
fn part_edges(dir: &Path, name: &str) -> Edges {
    let mut files = Vec::new();
    rust_files(dir, &mut files);
    files.sort();
    let part = |f: &Path| {
        let first = f.strip_prefix(dir).unwrap().components().next().unwrap().as_os_str().to_string_lossy().to_string();
        first.trim_end_matches(".rs").to_string()
    };
    let parts: BTreeSet<String> = files.iter().map(|f| part(f)).filter(|p| p != "mod").collect();
    let mut out = Edges::new();
    for f in &files {
        let from = part(f);
        if from == "mod" {
            continue;
        }
        let depth = f.strip_prefix(dir).unwrap().components().count();
        let is_mod = f.file_name().is_some_and(|n| n == "mod.rs");
        let text = std::fs::read_to_string(f).unwrap();
        let mut pats = vec![format!("crate::{name}::")];
        match (depth, is_mod) {
            (1, _) => pats.push("super::".into()),
            (2, false) => pats.push("super::super::".into()),
            (2, true) | (3, false) => pats.push("super::super::".into()),
            _ => {}
        }
        for (n, line) in text.lines().enumerate() {
            let code = line.split("//").next().unwrap_or("");
            for pat in &pats {
                for (i, _) in code.match_indices(pat.as_str()) {
                    let before = code[..i].chars().last();
                    if before.is_some_and(|c| c.is_alphanumeric() || c == '_' || c == ':') {
                        continue;
                    }
                    for r in first_segments(&code[i + pat.len()..]) {
                        if parts.contains(&r) && r != from {
                            out.entry(from.clone()).or_default().entry(r).or_insert((f.clone(), n + 1));
                        }
                    }
                }
            }
        }
    }
    out
}

/// A cycle between the parts of folder module `dir`, spelled with the file and line of each step.
fn part_cycle(dir: &Path, name: &str, root: &Path) -> Option<String> {
    let e = part_edges(dir, name);
    let graph: BTreeMap<String, BTreeSet<String>> =
        e.iter().map(|(k, v)| (k.clone(), v.keys().cloned().collect())).collect();
    let c = find_cycle(&graph)?;
    let steps: Vec<String> = c
        .windows(2)
        .map(|w| {
            let (f, l) = &e[&w[0]][&w[1]];
            format!("{} → {} ({}:{l})", w[0], w[1], f.strip_prefix(root).unwrap_or(f).display())
        })
        .collect();
    Some(format!("{name}: {}", steps.join(", ")))
}

/// Inside every folder module the files import each other without a cycle too (the layer
/// test above sees only top-level modules).
#[test]
fn files_of_a_module_import_each_other_without_a_cycle() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let src = root.join("src");
    let mut found = Vec::new();
    let mut checked = 0;
    for m in modules(&src) {
        let dir = src.join(&m);
        if dir.is_dir() {
            checked += 1;
            found.extend(part_cycle(&dir, &m, &root));
        }
    }
    assert!(found.is_empty(), "files of one module import each other in a cycle:\n  {}", found.join("\n  "));
    assert!(checked >= 8, "only {checked} folder modules found");
}

/// The file-level check can fail: two files planted to import each other are caught, by
/// `super::` and by `crate::` paths, and a third that only imports is not part of the cycle.
#[test]
fn a_planted_file_cycle_is_found() {
    let dir = std::env::temp_dir().join(format!("halftrace-arch-{}", std::process::id()));
    let m = dir.join("layout");
    std::fs::create_dir_all(m.join("f16x")).unwrap();
    std::fs::write(m.join("mod.rs"), "pub mod half;\npub mod frames;\nuse self::half::X;\n").unwrap();
    std::fs::write(m.join("half.rs"), "use super::frames::Frame; // the frame\npub struct X;\n").unwrap();
    std::fs::write(m.join("frames.rs"), "// use super::half::X; in a comment does not count\npub struct Frame;\n")
        .unwrap();
    std::fs::write(m.join("f16x/hooks.rs"), "use crate::layout::{half::X, frames};\n").unwrap();
    assert_eq!(part_cycle(&m, "layout", &dir), None);
    std::fs::write(m.join("frames.rs"), "pub struct Frame;\nfn f() -> crate::layout::half::X { todo!() }\n").unwrap();
    let c = part_cycle(&m, "layout", &dir).expect("the planted cycle");
    assert!(c.contains("frames → half (layout/frames.rs:2)") && c.contains("half → frames (layout/half.rs:1)"), "{c}");
    std::fs::remove_dir_all(&dir).unwrap();
}
