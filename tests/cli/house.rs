//! The house rules that the compiler does not enforce, read from the source tree: no module
//! imports another that imports it back (at any level of the tree), the library never reaches
//! into the CLI, CLI commands share code only through `cli::args` and `cli::io`, every shader
//! names its CPU twin and the twin names the shader, and every document the code cites is in
//! the repository.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// `src/server/http/jobs.rs` → ["server", "http", "jobs"]; `src/raster/mod.rs` → ["raster"].
fn module_of(file: &Path) -> Vec<String> {
    let rel = file.strip_prefix(root().join("src")).unwrap();
    let mut parts: Vec<String> = rel
        .iter()
        .map(|c| c.to_string_lossy().into_owned())
        .collect();
    let last = parts.pop().unwrap();
    let stem = last.trim_end_matches(".rs");
    if stem != "mod" && stem != "lib" && stem != "main" {
        parts.push(stem.to_string());
    }
    parts
}

/// The code of a file without comments, string literals or `#[cfg(test)]` modules' contents
/// (unit tests may use anything).
fn code(text: &str) -> String {
    let mut out = String::new();
    let mut in_tests = false;
    let mut depth = 0i32;
    for line in text.lines() {
        let t = line.trim_start();
        if t.starts_with("#[cfg(test)]") && !in_tests {
            in_tests = true;
            depth = 0;
            continue;
        }
        let line = match line.find("//") {
            Some(i) => &line[..i],
            None => line,
        };
        if in_tests {
            depth += line.matches('{').count() as i32 - line.matches('}').count() as i32;
            if depth <= 0 && line.contains('}') {
                in_tests = false;
            }
            continue;
        }
        // String literals could hold `crate::`; drop their contents.
        let mut quoted = false;
        for c in line.chars() {
            if c == '"' {
                quoted = !quoted;
            } else if !quoted {
                out.push(c);
            }
        }
        out.push('\n');
    }
    out
}

/// Every path this code names through `crate::`, `super::` or (in the binary) `omniwarp::`,
/// with grouped imports (`use crate::{a, b::c}`) expanded, resolved against `module`.
fn references(code: &str, module: &[String]) -> Vec<Vec<String>> {
    let ident = |c: char| c.is_alphanumeric() || c == '_';
    let mut refs = Vec::new();
    let bytes: Vec<char> = code.chars().collect();
    let mut i = 0;
    while i < bytes.len() {
        let rest: String = bytes[i..bytes.len().min(i + 8)].iter().collect();
        let starts_word = i == 0 || !(ident(bytes[i - 1]) || bytes[i - 1] == ':');
        let base: Option<(Vec<String>, usize)> = if !starts_word {
            None
        } else if rest.starts_with("crate::") {
            Some((vec![], 7))
        } else if rest.starts_with("super::") {
            let mut m = module.to_vec();
            let mut j = i;
            while bytes[j..].iter().take(7).collect::<String>() == "super::" {
                m.pop();
                j += 7;
            }
            Some((m, j - i))
        } else {
            None
        };
        let Some((base, skip)) = base else {
            i += 1;
            continue;
        };
        i += skip;
        // Read a path `a::b::c`, or a group `{a, b::c}` after it.
        let mut stack = vec![base];
        let mut current: Vec<String> = stack[0].clone();
        let mut word = String::new();
        while i < bytes.len() {
            let c = bytes[i];
            if ident(c) {
                word.push(c);
            } else if c == ':' {
                if !word.is_empty() {
                    current.push(std::mem::take(&mut word));
                }
            } else if c == '{' {
                stack.push(current.clone());
            } else if c == ',' && stack.len() > 1 {
                if !word.is_empty() {
                    current.push(std::mem::take(&mut word));
                }
                refs.push(current.clone());
                current = stack.last().unwrap().clone();
            } else if c == '}' && stack.len() > 1 {
                if !word.is_empty() {
                    current.push(std::mem::take(&mut word));
                }
                refs.push(current.clone());
                stack.pop();
                current = stack.last().unwrap().clone();
                if stack.len() == 1 {
                    break;
                }
            } else if !c.is_whitespace() || stack.len() == 1 {
                break;
            }
            i += 1;
        }
        if !word.is_empty() {
            current.push(word);
        }
        if stack.len() == 1 {
            refs.push(current);
        }
    }
    refs
}

/// A cycle in a directed graph, if there is one.
fn cycle(edges: &BTreeMap<String, BTreeSet<String>>) -> Option<Vec<String>> {
    fn visit(
        n: &str,
        edges: &BTreeMap<String, BTreeSet<String>>,
        state: &mut BTreeMap<String, u8>,
        path: &mut Vec<String>,
    ) -> Option<Vec<String>> {
        match state.get(n) {
            Some(1) => {
                let start = path.iter().position(|p| p == n).unwrap();
                let mut c = path[start..].to_vec();
                c.push(n.to_string());
                return Some(c);
            }
            Some(2) => return None,
            _ => {}
        }
        state.insert(n.to_string(), 1);
        path.push(n.to_string());
        for m in edges.get(n).into_iter().flatten() {
            if let Some(c) = visit(m, edges, state, path) {
                return Some(c);
            }
        }
        path.pop();
        state.insert(n.to_string(), 2);
        None
    }
    let mut state = BTreeMap::new();
    for n in edges.keys() {
        if let Some(c) = visit(n, edges, &mut state, &mut Vec::new()) {
            return Some(c);
        }
    }
    None
}

struct Tree {
    files: Vec<(PathBuf, Vec<String>, String)>,
    modules: BTreeSet<Vec<String>>,
}

fn tree() -> Tree {
    let mut paths = Vec::new();
    rust_files(&root().join("src"), &mut paths);
    paths.sort();
    let files: Vec<_> = paths
        .into_iter()
        .map(|p| {
            let m = module_of(&p);
            let text = std::fs::read_to_string(&p).unwrap();
            (p, m, text)
        })
        .collect();
    let modules = files.iter().map(|(_, m, _)| m.clone()).collect();
    Tree { files, modules }
}

/// Sibling-level import edges: for a reference from module A to module B, the edge joins the
/// children of their deepest common ancestor that lead to each.
fn sibling_edges(t: &Tree, binary: bool) -> BTreeMap<String, BTreeMap<String, BTreeSet<String>>> {
    let mut graphs: BTreeMap<String, BTreeMap<String, BTreeSet<String>>> = BTreeMap::new();
    for (path, module, text) in &t.files {
        let in_cli = module.first().is_some_and(|m| m == "cli") || path.ends_with("main.rs");
        if in_cli != binary {
            continue;
        }
        for r in references(&code(text), module) {
            // The module a reference lands in: its longest prefix that is a module.
            let target = (0..=r.len())
                .rev()
                .map(|k| r[..k].to_vec())
                .find(|p| t.modules.contains(p))
                .unwrap_or_default();
            let common = module
                .iter()
                .zip(&target)
                .take_while(|(a, b)| a == b)
                .count();
            if common < module.len() && common < target.len() {
                let parent = module[..common].join("::");
                graphs
                    .entry(parent)
                    .or_default()
                    .entry(module[common].clone())
                    .or_default()
                    .insert(target[common].clone());
            }
        }
    }
    graphs
}

#[test]
fn no_module_imports_one_that_imports_it_back() {
    let t = tree();
    let graphs = sibling_edges(&t, false);
    // The parser must see the edges that exist, or this test could never fail.
    assert!(graphs[""]["render"].contains("raster"), "{graphs:?}");
    assert!(
        graphs["server::http"]["jobs"].contains("state"),
        "{graphs:?}"
    );
    for (parent, edges) in graphs.iter().chain(&sibling_edges(&t, true)) {
        if let Some(c) = cycle(edges) {
            panic!("module cycle under `{parent}`: {}", c.join(" → "));
        }
    }
}

#[test]
fn the_cycle_finder_finds_a_planted_cycle() {
    let code = "use crate::{render::Plan, cubemap::{Face, face_point}};\nuse super::super::x::Y;";
    let refs = references(code, &["a".into(), "b".into()]);
    assert!(
        refs.contains(&vec!["render".into(), "Plan".into()]),
        "{refs:?}"
    );
    assert!(
        refs.contains(&vec!["cubemap".into(), "face_point".into()]),
        "{refs:?}"
    );
    assert!(refs.contains(&vec!["x".into(), "Y".into()]), "{refs:?}");
    let mut edges = BTreeMap::new();
    for (a, b) in [
        ("raster", "render"),
        ("render", "cubemap"),
        ("cubemap", "raster"),
    ] {
        edges
            .entry(a.to_string())
            .or_insert_with(BTreeSet::new)
            .insert(b.to_string());
    }
    assert_eq!(cycle(&edges).map(|c| c.len()), Some(4));
    edges.get_mut("cubemap").unwrap().clear();
    assert_eq!(cycle(&edges), None);
}

#[test]
fn the_library_never_uses_the_cli_and_commands_share_only_args_and_io() {
    let t = tree();
    for (path, module, text) in &t.files {
        let code = code(text);
        if module.first().is_some_and(|m| m == "cli") {
            let depth = module.len();
            for r in references(&code, module) {
                let inside_cli = r.first().is_some_and(|m| m == "cli");
                let shared = r.get(1).is_some_and(|m| m == "args" || m == "io");
                // The dispatcher (cli/mod.rs, bench/mod.rs) calls its commands.
                let dispatcher =
                    path.ends_with("mod.rs") && r.len() > depth && r[..depth] == module[..];
                assert!(
                    !inside_cli || shared || dispatcher || r.len() <= 1,
                    "{}: `{}` — commands share code only through cli::args and cli::io",
                    path.display(),
                    r.join("::")
                );
            }
        } else {
            assert!(
                !code.contains("crate::cli") && !code.contains("omniwarp::cli"),
                "{} uses the CLI",
                path.display()
            );
        }
    }
}

#[test]
fn every_shader_and_its_cpu_twin_name_each_other() {
    let twins: &[(&str, &[&str])] = &[
        ("shaders/projections.wgsl", &["src/projection/mod.rs"]),
        ("shaders/scene.wgsl", &["src/scene/raycast.rs"]),
        (
            "shaders/ppp.wgsl",
            &["src/scene/raycast.rs", "src/scene/ppp.rs"],
        ),
        ("shaders/warp.wgsl", &["src/render/mod.rs"]),
        ("shaders/blur.wgsl", &["src/render/blur.rs"]),
        ("shaders/mesh.wgsl", &["src/scene/raycast.rs"]),
        ("shaders/fullscreen.wgsl", &["src/render/mod.rs"]),
        ("shaders/show.wgsl", &["src/play/headless.rs"]),
    ];
    let mut listed: Vec<&str> = twins.iter().map(|(s, _)| *s).collect();
    let mut present: Vec<String> = std::fs::read_dir(root().join("shaders"))
        .unwrap()
        .map(|e| format!("shaders/{}", e.unwrap().file_name().to_string_lossy()))
        .collect();
    listed.sort();
    present.sort();
    assert_eq!(
        listed, present,
        "every shader needs its CPU twin listed here"
    );
    for (shader, cpu) in twins {
        let s = std::fs::read_to_string(root().join(shader)).unwrap();
        for c in *cpu {
            assert!(s.contains(c), "{shader} does not name its CPU twin {c}");
            let text = std::fs::read_to_string(root().join(c)).unwrap();
            assert!(
                text.contains(shader),
                "{c} does not name its shader {shader}"
            );
        }
    }
}

#[test]
fn every_document_the_code_cites_is_in_the_repository() {
    let mut files = Vec::new();
    rust_files(&root().join("src"), &mut files);
    rust_files(&root().join("tests"), &mut files);
    for e in std::fs::read_dir(root().join("shaders")).unwrap() {
        files.push(e.unwrap().path());
    }
    let mut cited = 0;
    for f in files {
        let text = std::fs::read_to_string(&f).unwrap();
        for (i, _) in text.match_indices(".md") {
            let start = text[..i]
                .rfind(|c: char| !(c.is_alphanumeric() || "/_-.".contains(c)))
                .map_or(0, |s| s + 1);
            let name = &text[start..i + 3];
            if name.len() <= 3 || !name.chars().next().unwrap().is_alphabetic() {
                continue;
            }
            cited += 1;
            assert!(
                root().join(name).exists(),
                "{} cites {name}, which is not in the repository (write it under docs/)",
                f.display()
            );
        }
    }
    assert!(cited > 0, "the scan found no citation at all");
}

/// Text files of the tree under `dir` (recursively; fixtures and generated folders left out).
fn text_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        let name = p.file_name().unwrap().to_string_lossy();
        if p.is_dir() {
            if !["fixtures", "node_modules", "charts"].contains(&name.as_ref()) {
                text_files(&p, out);
            }
        } else if std::fs::read_to_string(&p).is_ok() {
            out.push(p);
        }
    }
}

/// The repository paths a text names (`src/…`, `tests/…`, `calibration/…` and the other top-level
/// folders, ending in a file name with an extension), with the line each is on.
fn named_paths(text: &str) -> Vec<(usize, &str)> {
    const TOP: [&str; 9] = [
        "src/",
        "tests/",
        "docs/",
        "calibration/",
        "scripts/",
        "shaders/",
        "examples/",
        "api/",
        "console/",
    ];
    let in_path = |c: char| c.is_ascii_alphanumeric() || "_./-".contains(c);
    let mut found = Vec::new();
    for (n, line) in text.lines().enumerate() {
        for top in TOP {
            for (i, _) in line.match_indices(top) {
                if line[..i].chars().next_back().is_some_and(in_path) {
                    continue;
                }
                let len = line[i..]
                    .find(|c: char| !in_path(c))
                    .unwrap_or(line.len() - i);
                let path = line[i..i + len].trim_end_matches('.');
                let file = path.rsplit('/').next().unwrap();
                let has_extension = file.rsplit_once('.').is_some_and(|(stem, ext)| {
                    !stem.is_empty()
                        && (1..=5).contains(&ext.len())
                        && ext.chars().all(|c| c.is_ascii_lowercase())
                });
                if has_extension {
                    found.push((n + 1, path));
                }
            }
        }
    }
    found
}

#[test]
fn the_path_scanner_finds_paths_and_only_paths() {
    let text = "see tests/core/lens.rs, and src/cli/bench/.\n\
                `calibration/bench/bench-peers` (a script); docs/limits.md.\n\
                my-src/x.rs is not one; nor is tests/ alone; api/openapi.yaml is";
    let found: Vec<&str> = named_paths(text).into_iter().map(|(_, p)| p).collect();
    assert_eq!(
        found,
        ["tests/core/lens.rs", "docs/limits.md", "api/openapi.yaml"]
    );
}

/// Files move; the comments, docs and scripts that name them must move with them (a reader sent
/// to a test file by its name before the tests were gathered into four binaries finds nothing).
#[test]
fn every_path_the_tree_names_exists() {
    let mut files = Vec::new();
    for dir in [
        "src",
        "tests",
        "docs",
        "calibration",
        "scripts",
        "shaders",
        "examples",
        "api",
        "console",
    ] {
        text_files(&root().join(dir), &mut files);
    }
    files.extend(["README.md", "Cargo.toml"].map(|f| root().join(f)));
    let (mut named, mut missing) = (0, Vec::new());
    for f in files {
        let text = std::fs::read_to_string(&f).unwrap();
        for (line, path) in named_paths(&text) {
            named += 1;
            // Tests name their fixtures relative to `calibration/fixtures/`.
            let exists = root().join(path).exists()
                || root().join("calibration/fixtures").join(path).exists();
            if !exists {
                let rel = f.strip_prefix(root()).unwrap();
                missing.push(format!("{}:{line}: {path}", rel.display()));
            }
        }
    }
    assert!(named > 200, "the scan found only {named} paths");
    assert!(
        missing.is_empty(),
        "paths that do not exist:\n{}",
        missing.join("\n")
    );
}

/// Licences whose terms let a crate licensed `MIT OR Apache-2.0` be used and shipped in
/// binaries under either licence (permissive, or file-level copyleft with no duty on our code).
const COMPATIBLE: &[&str] = &[
    "MIT",
    "Apache-2.0",
    "Apache-2.0 WITH LLVM-exception",
    "BSD-2-Clause",
    "BSD-3-Clause",
    "ISC",
    "Zlib",
    "0BSD",
    "Unlicense",
    "CC0-1.0",
    "BSL-1.0",
    "Unicode-3.0",
    "MPL-2.0",
];

/// Whether an SPDX expression (`A OR (B AND C)`, `A WITH exception`, and the old `A/B`) can be
/// satisfied by [`COMPATIBLE`] licences alone. Precedence as SPDX: WITH, then AND, then OR.
fn compatible(expr: &str) -> bool {
    fn or(t: &[String], i: &mut usize) -> bool {
        let mut ok = and(t, i);
        while t.get(*i).is_some_and(|w| w == "OR") {
            *i += 1;
            ok |= and(t, i);
        }
        ok
    }
    fn and(t: &[String], i: &mut usize) -> bool {
        let mut ok = term(t, i);
        while t.get(*i).is_some_and(|w| w == "AND") {
            *i += 1;
            ok &= term(t, i);
        }
        ok
    }
    fn term(t: &[String], i: &mut usize) -> bool {
        let word = t.get(*i).cloned().unwrap_or_default();
        *i += 1;
        if word == "(" {
            let ok = or(t, i);
            assert_eq!(
                t.get(*i).map(String::as_str),
                Some(")"),
                "unbalanced: {t:?}"
            );
            *i += 1;
            return ok;
        }
        let mut id = word;
        if t.get(*i).is_some_and(|w| w == "WITH") {
            id = format!("{id} WITH {}", t[*i + 1]);
            *i += 2;
        }
        COMPATIBLE.contains(&id.as_str())
    }
    let spaced = expr
        .replace('/', " OR ")
        .replace('(', " ( ")
        .replace(')', " ) ");
    let tokens: Vec<String> = spaced.split_whitespace().map(str::to_string).collect();
    let mut i = 0;
    let ok = or(&tokens, &mut i);
    assert_eq!(i, tokens.len(), "`{expr}` did not parse to its end");
    ok
}

#[test]
fn the_licence_check_reads_spdx_expressions() {
    assert!(compatible("MIT OR Apache-2.0"));
    assert!(compatible("Apache-2.0/MIT"));
    assert!(compatible("(MIT OR Apache-2.0) AND Unicode-3.0"));
    assert!(compatible(
        "Apache-2.0 WITH LLVM-exception OR Apache-2.0 OR MIT"
    ));
    assert!(compatible("MIT OR Apache-2.0 OR LGPL-2.1-or-later"));
    assert!(!compatible("GPL-3.0-only"));
    assert!(!compatible("MIT AND GPL-2.0-or-later"));
    assert!(!compatible("(MIT OR Apache-2.0) AND LGPL-2.1-only"));
    assert!(!compatible("GPL-2.0 WITH Classpath-exception-2.0"));
}

/// The crate is offered as `MIT OR Apache-2.0`, so every crate built into it must allow that:
/// each dependency's licence (as its manifest declares it) is checked against [`COMPATIBLE`].
#[test]
fn every_dependency_allows_the_crates_licence() {
    let manifest = std::fs::read_to_string(root().join("Cargo.toml")).unwrap();
    assert!(manifest.contains("license = \"MIT OR Apache-2.0\""));
    for file in ["LICENSE-MIT", "LICENSE-APACHE"] {
        assert!(root().join(file).is_file(), "{file} is missing");
    }
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let out = std::process::Command::new(cargo)
        .args(["metadata", "--format-version", "1", "--locked"])
        .args(["--filter-platform", "x86_64-unknown-linux-gnu"])
        .current_dir(root())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let meta: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    // The packages of the resolved graph for this platform, dev-dependencies included.
    let used: BTreeSet<&str> = meta["resolve"]["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| n["id"].as_str().unwrap())
        .collect();
    let mut checked = 0;
    let mut refused = Vec::new();
    for p in meta["packages"].as_array().unwrap() {
        if !used.contains(p["id"].as_str().unwrap()) || p["name"] == "omniwarp" {
            continue;
        }
        checked += 1;
        match p["license"].as_str() {
            Some(l) if compatible(l) => {}
            other => refused.push(format!("{} {}: {other:?}", p["name"], p["version"])),
        }
    }
    assert!(refused.is_empty(), "licences not compatible: {refused:#?}");
    assert!(checked > 100, "only {checked} packages checked");
}
