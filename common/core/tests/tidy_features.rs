//! The main job's build stays whole: `deploy/run.sh` builds `alfd` without the `hosts` feature
//! (no zenoh bridge), without `minari` (no Arrow) and without `pages` (no web server). Outside
//! the bridge's own crate only the files listed here may name `alfd_bridge` in code, each behind
//! the feature (a module declared under `#[cfg(feature = "hosts")]`, items or lines gated in the
//! file, or a binary whose `required-features` has it). A new file that needs the bridge is
//! gated and added here.

use crate::tidy::{code_only, workspace, workspace_rust_files};

/// The files outside `common/bridge` whose code names `alfd_bridge`, and how each is gated.
const GATED: [(&str, &str); 7] = [
    ("deploy/launcher/src/remote.rs", "the module, in lib.rs"),
    ("deploy/launcher/src/error.rs", "the `Bridge` variant"),
    (
        "deploy/cli/src/cmd_join/host.rs",
        "the module, in cmd_join.rs",
    ),
    ("deploy/cli/src/cmd_certs.rs", "`make`"),
    (
        "deploy/cli/src/link_flags.rs",
        "the import and `impl LinkFlags`",
    ),
    ("deploy/cli/src/setup.rs", "the line in `reason`"),
    ("deploy/cli/src/bin/alfd-bench-ipc.rs", "required-features"),
];

/// The files outside `tests/` and outside `skip` (a path prefix) whose code names any of
/// `names`, sorted.
fn naming(skip: &str, names: &[&str]) -> Vec<String> {
    let mut found: Vec<String> = workspace_rust_files()
        .iter()
        .filter_map(|f| {
            let rel = f.strip_prefix(workspace()).unwrap().to_string_lossy();
            let skipped = rel.contains("/tests/") || (!skip.is_empty() && rel.starts_with(skip));
            let code = code_only(&std::fs::read_to_string(f).unwrap());
            (!skipped && names.iter().any(|n| code.contains(n))).then(|| rel.into_owned())
        })
        .collect();
    found.sort();
    found
}

#[test]
fn outside_the_bridge_only_files_behind_the_hosts_feature_name_it() {
    let naming = naming("common/bridge/", &["alfd_bridge"]);
    let mut listed: Vec<String> = GATED.iter().map(|(f, _)| (*f).to_owned()).collect();
    listed.sort();
    assert_eq!(
        naming, listed,
        "files whose code names alfd_bridge: gate each behind the `hosts` feature and list it"
    );
    let read = |rel: &str| std::fs::read_to_string(workspace().join(rel)).unwrap();
    let declared_gated = |parent: &str, module: &str| {
        read(parent).contains(&format!("#[cfg(feature = \"hosts\")]\nmod {module};"))
    };
    assert!(declared_gated("deploy/launcher/src/lib.rs", "remote"));
    assert!(declared_gated("deploy/cli/src/cmd_join.rs", "host"));
    for file in [
        "deploy/launcher/src/error.rs",
        "deploy/cli/src/cmd_certs.rs",
        "deploy/cli/src/link_flags.rs",
        "deploy/cli/src/setup.rs",
    ] {
        let gated = read(file).contains("feature = \"hosts\"");
        assert!(gated, "{file} gates nothing on `hosts`");
    }
    let manifest = read("deploy/cli/Cargo.toml");
    let bench = manifest
        .split("[[bin]]")
        .find(|b| b.contains("alfd-bench-ipc"));
    assert!(bench.is_some_and(|b| b.contains("required-features = [\"hosts\"]")));
}

/// Arrow (Minari datasets) is read and written only in the lab's `minari/arrow_io.rs`, which
/// the lab declares under its `minari` feature, as `deploy/run.sh` builds the main job without.
#[test]
fn only_the_gated_minari_module_names_arrow() {
    let naming = naming("", &["arrow_array", "arrow_schema", "arrow_ipc"]);
    assert_eq!(naming, ["deploy/lab/src/minari/arrow_io.rs"]);
    let minari = std::fs::read_to_string(workspace().join("deploy/lab/src/minari.rs")).unwrap();
    assert!(minari.contains("#[cfg(feature = \"minari\")]\nmod arrow_io;"));
}

/// The web pages' server (axum on tokio) is named only in the two page modules, each declared
/// under its crate's feature (`page` in the expert, `pages` in `alfd`), as `deploy/run.sh`
/// builds the main job without them.
#[test]
fn only_the_gated_page_modules_name_axum_and_tokio() {
    let naming = naming("", &["axum::", "tokio::", "futures_util::"]);
    assert_eq!(
        naming,
        [
            "deploy/cli/src/cmd_watch/page.rs",
            "expert/src/human/server.rs"
        ]
    );
    let read = |rel: &str| std::fs::read_to_string(workspace().join(rel)).unwrap();
    assert!(read("expert/src/human/mod.rs").contains("#[cfg(feature = \"page\")]\nmod server;"));
    assert!(read("deploy/cli/src/cmd_watch.rs").contains("#[cfg(feature = \"pages\")]\nmod page;"));
}

/// The fences of the code blocks in doc comments that open one (every other fence closes it).
fn opening_fences(text: &str) -> Vec<String> {
    let mut open = false;
    let mut found = Vec::new();
    for line in text.lines() {
        let t = line.trim_start();
        let Some(doc) = t.strip_prefix("///").or_else(|| t.strip_prefix("//!")) else {
            continue;
        };
        let Some(lang) = doc.trim_start().strip_prefix("```") else {
            continue;
        };
        if !open {
            found.push(lang.trim().to_string());
        }
        open = !open;
    }
    found
}

/// `deploy/test.sh` runs no doc tests (rustdoc takes about 40 s to find none): so no doc comment
/// holds a Rust example. Every code block in one names a language that is not Rust.
#[test]
fn no_doc_comment_holds_a_rust_example_since_the_suite_runs_no_doc_tests() {
    assert_eq!(
        opening_fences(
            "/// ```\n/// x\n/// ```\n//! ```text\n//! y\n//! ```\n/// ```rust,no_run\n"
        ),
        ["", "text", "rust,no_run"]
    );
    let rust: Vec<String> = workspace_rust_files()
        .iter()
        .flat_map(|f| {
            let rel = f.strip_prefix(workspace()).unwrap().display().to_string();
            opening_fences(&std::fs::read_to_string(f).unwrap())
                .into_iter()
                .filter(|lang| {
                    let first = lang.split(',').next().unwrap_or("");
                    [
                        "",
                        "rust",
                        "no_run",
                        "ignore",
                        "should_panic",
                        "compile_fail",
                    ]
                    .contains(&first)
                })
                .map(move |lang| format!("{rel}: ```{lang}"))
        })
        .collect();
    assert!(
        rust.is_empty(),
        "Rust examples in doc comments, which deploy/test.sh does not run: {rust:?} \
         (name the block's language, such as `text`, or run the doc tests there)"
    );
}
