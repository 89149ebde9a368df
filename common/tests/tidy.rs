//! Checks of the workspace's own habits (after rust-analyzer's tidy): every Rust file says what
//! it is for, and the core keeps its invariants (no I/O, iceoryx2 only in `wire.rs`, no
//! dependency on the other crates of the workspace).

use std::path::{Path, PathBuf};

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
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

#[test]
fn every_rust_file_opens_with_a_doc_line() {
    let mut files = Vec::new();
    for krate in ["common", "actor", "learner", "expert", "deploy"] {
        for sub in ["src", "tests", "benches"] {
            rust_files(&workspace().join(krate).join(sub), &mut files);
        }
    }
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

#[test]
fn the_core_does_no_io_and_only_wire_knows_iceoryx2() {
    let mut files = Vec::new();
    rust_files(&workspace().join("common/src"), &mut files);
    let forbidden = [
        "std::fs",
        "File::",
        "Instant::now",
        "SystemTime",
        "env::var",
        "std::net",
        "std::thread",
        "tokio",
    ];
    for f in &files {
        let text = std::fs::read_to_string(f).unwrap();
        let name = f.strip_prefix(workspace()).unwrap().display().to_string();
        if name.ends_with("common/src/wire.rs") {
            continue;
        }
        assert!(
            !text.contains("iceoryx2::"),
            "{name} uses iceoryx2: only common/src/wire.rs may"
        );
        for word in forbidden {
            assert!(
                !text.contains(word),
                "{name} uses `{word}`: the core does no I/O"
            );
        }
    }
    let manifest = std::fs::read_to_string(workspace().join("common/Cargo.toml")).unwrap();
    for krate in ["alfd-actor", "alfd-learner", "alfd-expert", "alfd-deploy"] {
        assert!(
            !manifest.contains(krate),
            "common must not depend on {krate}"
        );
    }
}
