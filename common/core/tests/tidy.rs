//! Checks of the workspace's own habits (after rust-analyzer's tidy): every Rust file says what
//! it is for, the core does no I/O, and the dependency graph keeps its shape (the core reaches
//! neither iceoryx2, zenoh nor tracing-subscriber; only `alfd-wire` depends on iceoryx2, only
//! `alfd-bridge` on zenoh), read from
//! `cargo metadata`.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use serde_json::Value;

pub(crate) fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .and_then(Path::parent)
        .unwrap()
        .to_path_buf()
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let p = e.path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// The workspace's member crates, each as its folder relative to the workspace, read from
/// `cargo metadata --no-deps`, so that a crate added to the workspace is checked without a
/// change here.
fn workspace_members() -> Vec<String> {
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| env!("CARGO").into());
    let manifest = workspace().join("Cargo.toml");
    let output = std::process::Command::new(&cargo)
        .args([
            "metadata",
            "--format-version",
            "1",
            "--no-deps",
            "--offline",
        ])
        .arg("--manifest-path")
        .arg(&manifest)
        .output()
        .expect("run cargo metadata");
    assert!(
        output.status.success(),
        "cargo metadata failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    let meta: Value = serde_json::from_slice(&output.stdout).expect("cargo metadata JSON");
    let root = workspace();
    meta["packages"]
        .as_array()
        .expect("packages")
        .iter()
        .map(|p| {
            let manifest = PathBuf::from(p["manifest_path"].as_str().expect("manifest_path"));
            let dir = manifest.parent().expect("a manifest's folder");
            let rel = dir
                .strip_prefix(&root)
                .expect("a member inside the workspace");
            rel.to_string_lossy().into_owned()
        })
        .collect()
}

#[test]
fn the_file_checks_walk_every_member_crate() {
    let members = workspace_members();
    for krate in [
        "common/core",
        "deploy/launcher",
        "deploy/lab",
        "deploy/cli",
        "actor",
    ] {
        assert!(
            members.iter().any(|m| m == krate),
            "{krate} missing from {members:?}"
        );
    }
}

/// Every `.rs` file of the workspace's crates.
pub(crate) fn workspace_rust_files() -> Vec<PathBuf> {
    let mut files = Vec::new();
    for krate in workspace_members() {
        for sub in ["src", "tests", "benches"] {
            rust_files(&workspace().join(&krate).join(sub), &mut files);
        }
    }
    files
}

/// The core's top-level module of `file` (`agent` for `src/agent/neural.rs`, `math` for
/// `src/math.rs`).
fn core_module(src: &Path, file: &Path) -> String {
    let first = file.strip_prefix(src).unwrap().components().next().unwrap();
    let name = first.as_os_str().to_string_lossy();
    name.trim_end_matches(".rs").to_owned()
}

/// Which of the core's top-level modules each one names (`crate::NAME`) outside its tests.
fn core_imports() -> BTreeMap<String, BTreeSet<String>> {
    let src = workspace().join("common/core/src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    let modules: BTreeSet<String> = files.iter().map(|f| core_module(&src, f)).collect();
    let mut edges: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for f in &files {
        let from = core_module(&src, f);
        let text = std::fs::read_to_string(f).unwrap();
        let code = text.split("#[cfg(test)]").next().unwrap_or("");
        for (i, _) in code.match_indices("crate::") {
            let to: String = code[i + "crate::".len()..]
                .chars()
                .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                .collect();
            if to != from && modules.contains(&to) {
                edges.entry(from.clone()).or_default().insert(to);
            }
        }
    }
    edges
}

/// A circle in `edges`, as the modules along it, if there is one.
fn circle(edges: &BTreeMap<String, BTreeSet<String>>) -> Option<Vec<String>> {
    fn visit(
        m: &str,
        edges: &BTreeMap<String, BTreeSet<String>>,
        path: &mut Vec<String>,
        done: &mut BTreeSet<String>,
    ) -> Option<Vec<String>> {
        if let Some(i) = path.iter().position(|p| p == m) {
            let mut c = path[i..].to_vec();
            c.push(m.to_owned());
            return Some(c);
        }
        if done.contains(m) {
            return None;
        }
        path.push(m.to_owned());
        for next in edges.get(m).into_iter().flatten() {
            if let Some(c) = visit(next, edges, path, done) {
                return Some(c);
            }
        }
        path.pop();
        done.insert(m.to_owned());
        None
    }
    let mut done = BTreeSet::new();
    edges
        .keys()
        .find_map(|m| visit(m, edges, &mut Vec::new(), &mut done))
}

/// The core's modules import one another in one direction: no circle among its top-level
/// modules (`config` reads no environment, `math` no network).
#[test]
fn the_cores_modules_import_one_another_in_one_direction() {
    let edges = core_imports();
    assert!(
        edges.len() > 10,
        "found the imports of {} modules",
        edges.len()
    );
    assert!(edges["runner"].contains("environment_loop"), "{edges:?}");
    assert_eq!(
        circle(&edges),
        None,
        "a circle of imports among the core's modules"
    );
    // The check finds a circle where there is one.
    let mut with = edges.clone();
    with.entry("math".into())
        .or_default()
        .insert("runner".into());
    with.entry("runner".into())
        .or_default()
        .insert("math".into());
    assert!(circle(&with).is_some());
}

/// A file a reader can hold in their head: the crates' files stay under 1,000 lines.
#[test]
fn no_source_file_is_over_a_thousand_lines() {
    let files = workspace_rust_files();
    assert!(files.len() > 30, "found only {} files", files.len());
    let long: Vec<_> = files
        .iter()
        .map(|f| (f, std::fs::read_to_string(f).unwrap().lines().count()))
        .filter(|(_, n)| *n > 1000)
        .map(|(f, n)| {
            format!(
                "{} ({n} lines)",
                f.strip_prefix(workspace()).unwrap().display()
            )
        })
        .collect();
    assert!(long.is_empty(), "split these files: {long:?}");
}

#[test]
fn every_rust_file_opens_with_a_doc_line() {
    let files = workspace_rust_files();
    assert!(files.len() > 30, "found only {} files", files.len());
    let missing: Vec<_> = files
        .iter()
        .filter(|f| {
            !std::fs::read_to_string(f)
                .unwrap()
                .trim_start()
                .starts_with("//!")
        })
        .map(|f| f.strip_prefix(workspace()).unwrap().display().to_string())
        .collect();
    assert!(
        missing.is_empty(),
        "files without a `//!` line: {missing:?}"
    );
}

// ---------------------------------------------------------------------------------------------
// The core does no I/O
// ---------------------------------------------------------------------------------------------

/// Paths the core may not name (from the crate root), with what they would bring in. A path is
/// refused when it starts with one of these, in code or in a `use` (groups expanded), whatever
/// the spacing; comments and string literals are not code.
const FORBIDDEN_PATHS: &[(&[&str], &str)] = &[
    (&["std", "fs"], "files"),
    (&["std", "net"], "sockets"),
    (&["std", "thread"], "threads"),
    (&["std", "process"], "processes"),
    (&["std", "env"], "environment variables"),
    (&["tokio"], "an async runtime"),
    (&["iceoryx2"], "the transport (only alfd-wire knows it)"),
    (
        &["zenoh"],
        "the transport across hosts (only alfd-bridge knows it)",
    ),
    (&["tracing_subscriber"], "a log sink"),
];

/// Names the core may not use in any path, however they were imported.
const FORBIDDEN_NAMES: &[(&str, &str)] = &[
    ("File", "files"),
    ("OpenOptions", "files"),
    ("Instant", "clocks"),
    ("SystemTime", "clocks"),
];

/// `text` without comments, string literals and character literals (each replaced by a space),
/// so that what is left is code.
pub(crate) fn code_only(text: &str) -> String {
    let c: Vec<char> = text.chars().collect();
    let mut out = String::with_capacity(text.len());
    let mut i = 0;
    while i < c.len() {
        let next = c.get(i + 1).copied();
        if c[i] == '/' && next == Some('/') {
            while i < c.len() && c[i] != '\n' {
                i += 1;
            }
        } else if c[i] == '/' && next == Some('*') {
            let mut depth = 0;
            while i < c.len() {
                if c[i] == '/' && c.get(i + 1) == Some(&'*') {
                    depth += 1;
                    i += 2;
                } else if c[i] == '*' && c.get(i + 1) == Some(&'/') {
                    depth -= 1;
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    i += 1;
                }
            }
            out.push(' ');
        } else if c[i] == 'r'
            && (next == Some('"') || next == Some('#'))
            && !(i > 0 && (c[i - 1].is_alphanumeric() || c[i - 1] == '_'))
        {
            // A raw string: r"..." or r#"..."#.
            let mut j = i + 1;
            let mut hashes = 0;
            while c.get(j) == Some(&'#') {
                hashes += 1;
                j += 1;
            }
            if c.get(j) != Some(&'"') {
                out.push(c[i]);
                i += 1;
                continue;
            }
            j += 1;
            loop {
                if j >= c.len() {
                    break;
                }
                if c[j] == '"' && (1..=hashes).all(|h| c.get(j + h) == Some(&'#')) {
                    j += 1 + hashes;
                    break;
                }
                j += 1;
            }
            i = j;
            out.push(' ');
        } else if c[i] == '"' {
            i += 1;
            while i < c.len() && c[i] != '"' {
                if c[i] == '\\' {
                    i += 1;
                }
                i += 1;
            }
            i += 1;
            out.push(' ');
        } else if c[i] == '\'' && next == Some('\\') {
            // An escaped character literal: '\n', '\'', '\u{..}'.
            i += 2;
            while i < c.len() && c[i] != '\'' {
                i += 1;
            }
            i += 1;
            out.push(' ');
        } else if c[i] == '\'' && c.get(i + 2) == Some(&'\'') {
            i += 3;
            out.push(' ');
        } else {
            // Lifetimes ('a) and everything else.
            out.push(c[i]);
            i += 1;
        }
    }
    out
}

#[derive(Debug, Clone, PartialEq)]
enum Token {
    Ident(String),
    PathSep,
    Punct(char),
}

fn tokens(code: &str) -> Vec<Token> {
    let c: Vec<char> = code.chars().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < c.len() {
        if c[i].is_alphabetic() || c[i] == '_' {
            let start = i;
            while i < c.len() && (c[i].is_alphanumeric() || c[i] == '_') {
                i += 1;
            }
            out.push(Token::Ident(c[start..i].iter().collect()));
        } else if c[i] == ':' && c.get(i + 1) == Some(&':') {
            out.push(Token::PathSep);
            i += 2;
        } else if c[i].is_whitespace() {
            i += 1;
        } else {
            out.push(Token::Punct(c[i]));
            i += 1;
        }
    }
    out
}

/// Expands a `use` tree starting at `t[*i]` under `prefix` into full paths; stops after the
/// tree (at `,`, `}` or `;`, not consumed).
fn use_tree(t: &[Token], i: &mut usize, prefix: Vec<String>, out: &mut Vec<Vec<String>>) {
    let mut path = prefix;
    loop {
        match t.get(*i) {
            Some(Token::Ident(w)) if w == "as" => {
                *i += 2; // the alias names the same path
            }
            Some(Token::Ident(w)) => {
                if w != "self" {
                    path.push(w.clone());
                }
                *i += 1;
            }
            Some(Token::PathSep) => *i += 1,
            Some(Token::Punct('*')) => *i += 1,
            Some(Token::Punct('{')) => {
                *i += 1;
                loop {
                    match t.get(*i) {
                        Some(Token::Punct('}')) => {
                            *i += 1;
                            break;
                        }
                        Some(Token::Punct(',')) => *i += 1,
                        None => break,
                        _ => use_tree(t, i, path.clone(), out),
                    }
                }
                return;
            }
            _ => {
                out.push(path);
                return;
            }
        }
    }
}

/// Every path `code` names: the expanded `use` declarations and every `a::b::c` in the code,
/// each without a leading `::`.
fn paths(code: &str) -> Vec<Vec<String>> {
    let t = tokens(code);
    let mut out = Vec::new();
    let mut i = 0;
    while i < t.len() {
        if t[i] == Token::Ident("use".to_owned()) {
            i += 1;
            use_tree(&t, &mut i, Vec::new(), &mut out);
            continue;
        }
        if let Token::Ident(w) = &t[i] {
            let mut path = vec![w.clone()];
            i += 1;
            while let (Some(Token::PathSep), Some(Token::Ident(w))) = (t.get(i), t.get(i + 1)) {
                path.push(w.clone());
                i += 2;
            }
            out.push(path);
        } else {
            i += 1;
        }
    }
    out
}

/// What in `text` breaks the core's no-I/O rule, one line per finding.
fn io_findings(text: &str) -> Vec<String> {
    let mut found = BTreeSet::new();
    for path in paths(&code_only(text)) {
        for (forbidden, what) in FORBIDDEN_PATHS {
            if path.len() >= forbidden.len()
                && path.iter().zip(forbidden.iter()).all(|(a, b)| a == b)
            {
                found.insert(format!("`{}` ({what})", path.join("::")));
            }
        }
        for (name, what) in FORBIDDEN_NAMES {
            if path.iter().any(|segment| segment == name) {
                found.insert(format!("`{}` ({what})", path.join("::")));
            }
        }
    }
    found.into_iter().collect()
}

#[test]
fn the_io_check_sees_through_groups_spacing_and_aliases_but_not_comments() {
    for code in [
        "use std::{fs, io};",
        "use std::{collections::HashMap, fs::{self, File as F}};",
        "fn f() { std :: fs :: read(\"x\"); }",
        "fn f() { ::std::fs::read(\"x\"); }",
        "use std::time::{Duration, Instant};",
        "fn f() { let t = std::time::SystemTime::now(); }",
        "use std::env::var as get;",
        "use std::thread;",
        "fn f() { iceoryx2::prelude::set_log_level(); }",
        "use tracing_subscriber::fmt;",
    ] {
        assert!(!io_findings(code).is_empty(), "not caught: {code}");
    }
    for code in [
        "// std::fs and Instant::now in a comment\nfn f() {}",
        "/// Reads no files (std::fs), no clocks (SystemTime).\nfn f() {}",
        "fn f() -> &'static str { \"std::fs::read\" }",
        "const S: &str = r#\"File::open(\"x\")\"#; fn f(c: char) -> bool { c == '\"' }",
        "use crate::env::CartPole; fn f() { env::CartPole::new(); }",
        "struct Profile; fn f() { let profile_file = 1; }",
        "use std::time::Duration; use std::collections::HashMap;",
    ] {
        assert_eq!(io_findings(code), Vec::<String>::new(), "flagged: {code}");
    }
}

/// `findings` over every file of the core (`common/core/src`), each prefixed with the file's path.
fn core_findings(findings: fn(&str) -> Vec<String>) -> Vec<String> {
    let mut files = Vec::new();
    rust_files(&workspace().join("common/core/src"), &mut files);
    assert!(files.len() > 10, "found only {} files", files.len());
    let mut problems = Vec::new();
    for f in &files {
        let text = std::fs::read_to_string(f).unwrap();
        let name = f.strip_prefix(workspace()).unwrap().display().to_string();
        for finding in findings(&text) {
            problems.push(format!("{name}: {finding}"));
        }
    }
    problems
}

#[test]
fn the_core_does_no_io() {
    let problems = core_findings(io_findings);
    assert!(
        problems.is_empty(),
        "the core does no I/O, but:\n{}",
        problems.join("\n")
    );
}

// ---------------------------------------------------------------------------------------------
// The dependency graph, from `cargo metadata`
// ---------------------------------------------------------------------------------------------

/// The workspace's resolved dependency graph: package names by id, the workspace members, and
/// per package its dependencies (package ids) of every kind (normal, build and dev), so that a
/// test-only dependency counts too.
struct Graph {
    names: BTreeMap<String, String>,
    members: Vec<String>,
    /// Per package id: the ids its own build depends on (no dev-dependencies).
    normal: BTreeMap<String, Vec<String>>,
    deps: BTreeMap<String, Vec<String>>,
}

impl Graph {
    /// Runs `cargo metadata` (offline where it can) on the workspace, for the host's platform:
    /// the dependencies of other platforms are not in the local registry, and none is the
    /// transport or a log sink.
    fn load() -> Graph {
        let cargo = std::env::var_os("CARGO").unwrap_or_else(|| env!("CARGO").into());
        let attempt = |args: &[&str]| {
            std::process::Command::new(&cargo)
                .args(args)
                .output()
                .expect("run cargo")
        };
        let run = |args: &[&str]| -> Vec<u8> {
            let output = attempt(args);
            assert!(
                output.status.success(),
                "cargo {args:?} failed: {}",
                String::from_utf8_lossy(&output.stderr)
            );
            output.stdout
        };
        let version = String::from_utf8(run(&["-vV"])).unwrap();
        let host = version
            .lines()
            .find_map(|l| l.strip_prefix("host: "))
            .expect("a host line in `cargo -vV`")
            .to_owned();
        let manifest = workspace().join("Cargo.toml");
        let metadata = [
            "metadata",
            "--format-version",
            "1",
            "--filter-platform",
            &host,
            "--manifest-path",
            manifest.to_str().unwrap(),
        ];
        // Offline first (the build has fetched what it uses); a registry cache that lacks a
        // package the resolution reads (one the build never compiles) is filled in online.
        let offline = attempt(&[&metadata[..], &["--offline"]].concat());
        let stdout = if offline.status.success() {
            offline.stdout
        } else {
            run(&metadata)
        };
        let meta: Value = serde_json::from_slice(&stdout).expect("cargo metadata JSON");
        let names = meta["packages"]
            .as_array()
            .expect("packages")
            .iter()
            .map(|p| {
                (
                    p["id"].as_str().unwrap().to_owned(),
                    p["name"].as_str().unwrap().to_owned(),
                )
            })
            .collect();
        let members = meta["workspace_members"]
            .as_array()
            .expect("workspace_members")
            .iter()
            .map(|id| id.as_str().unwrap().to_owned())
            .collect();
        let mut deps = BTreeMap::new();
        let mut normal = BTreeMap::new();
        for node in meta["resolve"]["nodes"].as_array().expect("resolve.nodes") {
            let of_node: Vec<String> = node["dependencies"]
                .as_array()
                .expect("dependencies")
                .iter()
                .map(|d| d.as_str().unwrap().to_owned())
                .collect();
            deps.insert(node["id"].as_str().unwrap().to_owned(), of_node);
            // The dependencies a build of the package itself uses (kind null: neither dev nor
            // build).
            let built: Vec<String> = node["deps"]
                .as_array()
                .expect("deps")
                .iter()
                .filter(|d| {
                    d["dep_kinds"]
                        .as_array()
                        .is_some_and(|k| k.iter().any(|k| k["kind"].is_null()))
                })
                .map(|d| d["pkg"].as_str().unwrap().to_owned())
                .collect();
            normal.insert(node["id"].as_str().unwrap().to_owned(), built);
        }
        Graph {
            names,
            members,
            deps,
            normal,
        }
    }

    fn name(&self, id: &str) -> &str {
        &self.names[id]
    }

    fn id(&self, name: &str) -> &str {
        self.members
            .iter()
            .find(|id| self.name(id) == name)
            .unwrap_or_else(|| panic!("{name} is not a workspace member"))
    }

    /// What `name`'s own build depends on directly (no dev-dependencies).
    fn normal(&self, name: &str) -> BTreeSet<&str> {
        self.normal[self.id(name)]
            .iter()
            .map(|d| self.name(d))
            .collect()
    }

    fn direct(&self, name: &str) -> BTreeSet<&str> {
        self.deps[self.id(name)]
            .iter()
            .map(|d| self.name(d))
            .collect()
    }

    /// Every package `name` depends on, directly or not, each with the chain that leads to it.
    fn transitive(&self, name: &str) -> BTreeMap<&str, String> {
        let mut seen: BTreeMap<&str, String> = BTreeMap::new();
        let mut stack = vec![(self.id(name), name.to_owned())];
        let mut visited = BTreeSet::new();
        while let Some((id, chain)) = stack.pop() {
            for d in &self.deps[id] {
                if visited.insert(d.as_str()) {
                    let chain = format!("{chain} -> {}", self.name(d));
                    seen.entry(self.name(d)).or_insert_with(|| chain.clone());
                    stack.push((d.as_str(), chain));
                }
            }
        }
        seen
    }
}

fn is_transport_or_log_sink(package: &str) -> bool {
    package.starts_with("iceoryx2")
        || package.starts_with("zenoh")
        || package == "tracing-subscriber"
}

#[test]
fn the_dependency_graph_keeps_its_shape() {
    let g = Graph::load();

    // The core reaches neither the transport nor a log sink, not even through another crate.
    let core = g.transitive("alfd-common");
    assert!(
        core.contains_key("nalgebra"),
        "the graph is incomplete: {core:?}"
    );
    let bad: Vec<&String> = core
        .iter()
        .filter(|(name, _)| is_transport_or_log_sink(name))
        .map(|(_, chain)| chain)
        .collect();
    assert!(bad.is_empty(), "alfd-common must not depend on: {bad:?}");
    // The same search finds them where they are.
    let harness = g.transitive("alfd-harness");
    assert!(
        harness.contains_key("iceoryx2") && harness.contains_key("tracing-subscriber"),
        "{harness:?}"
    );

    // Only alfd-wire depends on iceoryx2 directly.
    let users: Vec<&str> = g
        .members
        .iter()
        .map(|id| g.name(id))
        .filter(|m| g.direct(m).iter().any(|d| d.starts_with("iceoryx2")))
        .collect();
    assert_eq!(
        users,
        ["alfd-wire"],
        "workspace members depending on iceoryx2"
    );
    // Only alfd-bridge depends on zenoh directly, and on iceoryx2 only through alfd-wire.
    let users: Vec<&str> = g
        .members
        .iter()
        .map(|id| g.name(id))
        .filter(|m| g.direct(m).iter().any(|d| d.starts_with("zenoh")))
        .collect();
    assert_eq!(
        users,
        ["alfd-bridge"],
        "workspace members depending on zenoh"
    );

    // Dependencies inside the workspace point one way: common <- wire <- harness <- binaries.
    let inside = |name: &str| -> BTreeSet<&str> {
        let members: BTreeSet<&str> = g.members.iter().map(|id| g.name(id)).collect();
        g.direct(name)
            .into_iter()
            .filter(|d| members.contains(d))
            .collect()
    };
    assert_eq!(inside("alfd-common"), BTreeSet::new());
    assert_eq!(inside("alfd-wire"), BTreeSet::from(["alfd-common"]));
    assert!(
        inside("alfd-harness").is_subset(&BTreeSet::from(["alfd-common", "alfd-wire"])),
        "{:?}",
        inside("alfd-harness")
    );
    assert_eq!(
        inside("alfd-bridge"),
        BTreeSet::from(["alfd-common", "alfd-wire"])
    );
    // The launcher is a library of the CLI (alfd-deploy), which no other crate depends on.
    assert!(
        inside("alfd-launcher").is_subset(&BTreeSet::from([
            "alfd-common",
            "alfd-wire",
            "alfd-harness",
            "alfd-bridge",
            "alfd-expert"
        ])),
        "{:?}",
        inside("alfd-launcher")
    );
    // The lab (sweeps, statistics, plots, reports) trains through a trait the CLI passes in: it
    // needs no process, wire or launcher.
    assert!(
        inside("alfd-lab").is_subset(&BTreeSet::from([
            "alfd-common",
            "alfd-harness",
            "alfd-wire",
            "alfd-demonstrators"
        ])),
        "{:?}",
        inside("alfd-lab")
    );
    // The demonstrators come without the expert process's page server.
    assert!(
        inside("alfd-demonstrators").is_subset(&BTreeSet::from(["alfd-common", "alfd-harness"])),
        "{:?}",
        inside("alfd-demonstrators")
    );
    for server in ["axum", "tokio"] {
        assert!(
            !g.transitive("alfd-demonstrators").contains_key(server),
            "alfd-demonstrators reaches {server}"
        );
    }
    for m in &g.members {
        assert!(
            !g.direct(g.name(m)).contains("alfd-deploy"),
            "{}",
            g.name(m)
        );
    }

    // Library crates report typed errors (thiserror); anyhow is for the binaries' code.
    for lib in [
        "alfd-common",
        "alfd-wire",
        "alfd-harness",
        "alfd-bridge",
        "alfd-demonstrators",
        "alfd-launcher",
        "alfd-lab",
    ] {
        assert!(!g.normal(lib).contains("anyhow"), "{lib} depends on anyhow");
        assert!(g.normal(lib).contains("thiserror"), "{lib}");
    }
    // The process crates report the harness's typed error (their binaries print it).
    for process in ["alfd-actor", "alfd-learner", "alfd-expert"] {
        assert!(
            !g.normal(process).contains("anyhow"),
            "{process} depends on anyhow"
        );
    }
}

// ---------------------------------------------------------------------------------------------
// The same numbers on every CPU
// ---------------------------------------------------------------------------------------------

/// The platform's transcendental methods, which glibc dispatches by CPU features;
/// the core calls `alfd_common::math` instead.
const PLATFORM_MATH: [&str; 16] = [
    "exp", "exp2", "exp_m1", "ln", "ln_1p", "log", "log2", "log10", "powf", "sin", "cos", "tan",
    "sin_cos", "tanh", "atan2", "hypot",
];

/// Calls of `PLATFORM_MATH` methods in `text` outside its `#[cfg(test)]` part (tests may compare
/// against the platform), one line per finding.
fn platform_math_findings(text: &str) -> Vec<String> {
    let code = code_only(text);
    let code = code.split("#[cfg(test)]").next().unwrap_or_default();
    let mut found = Vec::new();
    for (n, line) in code.lines().enumerate() {
        for name in PLATFORM_MATH {
            let call = format!(".{name}(");
            if line.contains(&call) {
                found.push(format!("line {}: `{call}`", n + 1));
            }
        }
    }
    found
}

#[test]
fn the_platform_math_check_finds_method_calls_but_not_comments_or_tests() {
    assert_eq!(
        platform_math_findings("fn f(x: f64) -> f64 { (-x).exp() }").len(),
        1
    );
    assert_eq!(
        platform_math_findings("let c = theta.cos();\nlet l = p.ln();").len(),
        2
    );
    for code in [
        "// x.exp() in a comment\nfn f() {}",
        "fn f(x: f64) -> f64 { crate::math::exp(x) }",
        "fn f() {}\n#[cfg(test)]\nmod tests { fn g(x: f64) -> f64 { x.exp() } }",
        "fn f() -> &'static str { \"x.sin()\" }",
    ] {
        assert_eq!(platform_math_findings(code), Vec::<String>::new(), "{code}");
    }
}

#[test]
fn the_core_calls_no_platform_transcendentals() {
    let problems = core_findings(platform_math_findings);
    assert!(
        problems.is_empty(),
        "the core calls alfd_common::math (the same bits on every CPU), not the platform's:\n{}",
        problems.join("\n")
    );
}

/// "session 6", "issue 9" and their plurals, in any case: development history, which belongs in
/// git and the issue tracker, not in what a reader of the code or the configs meets.
fn history_findings(text: &str) -> Vec<String> {
    let lower = text.to_lowercase();
    let mut found = Vec::new();
    for word in ["session", "issue"] {
        for (i, _) in lower.match_indices(word) {
            let before = lower[..i].chars().next_back();
            if before.is_some_and(char::is_alphanumeric) {
                continue;
            }
            let rest = lower[i + word.len()..]
                .strip_prefix('s')
                .unwrap_or(&lower[i + word.len()..]);
            if rest
                .strip_prefix(' ')
                .is_some_and(|r| r.starts_with(|c: char| c.is_ascii_digit()))
            {
                let line = lower[..i].matches('\n').count() + 1;
                found.push(format!(
                    "line {line}: {}",
                    &text[i..(i + word.len() + 3).min(text.len())]
                ));
            }
        }
    }
    found
}

#[test]
fn the_history_check_finds_session_and_issue_numbers_only() {
    assert_eq!(history_findings("a\n// Session 7: x").len(), 1);
    assert_eq!(history_findings("issues 3 and 4").len(), 1);
    assert_eq!(history_findings("(issue 14, item 1)").len(), 1);
    assert!(history_findings("the session's id, an issue of size, tissue 3, session_6").is_empty());
}

/// Source files, configs, experiment files and scripts state what is: no "session 6" or
/// "issue 9" in them (nor, through the sources, in `--help`).
#[test]
fn code_configs_scripts_and_documents_carry_no_development_history() {
    let mut files = workspace_rust_files();
    for dir in [
        "deploy/configs",
        "deploy/experiments",
        "deploy/bench",
        "deploy/python",
        "deploy/cli",
    ] {
        let Ok(entries) = std::fs::read_dir(workspace().join(dir)) else {
            continue;
        };
        for e in entries.flatten() {
            let p = e.path();
            let ext = p.extension().and_then(|x| x.to_str()).unwrap_or("");
            if p.is_file() && ["toml", "sh", "py"].contains(&ext) {
                files.push(p);
            }
        }
    }
    for sub in ["deploy/configs/recommended", "deploy/experiments/study"] {
        for e in std::fs::read_dir(workspace().join(sub)).unwrap().flatten() {
            files.push(e.path());
        }
    }
    files.push(workspace().join("Cargo.toml"));
    files.push(workspace().join(".ci/run"));
    // The documents a user reads (CHANGELOG.md is history by nature).
    for doc in [
        "README.md",
        "EXPERIMENTS.md",
        "BENCHMARKS.md",
        "ARCHITECTURE.md",
    ] {
        files.push(workspace().join(doc));
    }
    files.extend(super::manual::chapters());
    let mut found = Vec::new();
    // This file names the words it looks for.
    files.retain(|f| !f.ends_with("common/core/tests/tidy.rs"));
    for f in &files {
        let text = std::fs::read_to_string(f).unwrap_or_default();
        for hit in history_findings(&text) {
            found.push(format!(
                "{}: {hit}",
                f.strip_prefix(workspace()).unwrap().display()
            ));
        }
    }
    assert!(files.len() > 100, "{} files read", files.len());
    assert!(
        found.is_empty(),
        "development history in:\n{}",
        found.join("\n")
    );
}
