//! The documents and the manual (`docs/`, an mdBook): every link resolves, every chapter is in
//! the book's summary once.

use std::path::PathBuf;

use super::tidy::workspace;

/// The manual's chapters, `docs/src/*.md`, in name order.
pub(crate) fn chapters() -> Vec<PathBuf> {
    let mut out: Vec<PathBuf> = std::fs::read_dir(workspace().join("docs/src"))
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "md"))
        .collect();
    out.sort();
    out
}

/// The targets of a Markdown text's inline links and images (`](target)`), outside code.
fn link_targets(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut fenced = false;
    for line in text.lines() {
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
        }
        if fenced {
            continue;
        }
        // Code spans are not links.
        let plain: String = line.split('`').step_by(2).collect::<Vec<_>>().join(" ");
        let mut rest = plain.as_str();
        while let Some(i) = rest.find("](") {
            let after = &rest[i + 2..];
            let end = after.find(')').unwrap_or(after.len());
            out.push(after[..end].to_owned());
            rest = &after[end..];
        }
    }
    out
}

/// GitHub's and mdBook's anchor of a heading: lower case, spaces to `-`, other punctuation
/// dropped.
fn slug(heading: &str) -> String {
    heading
        .trim()
        .to_lowercase()
        .chars()
        .filter_map(|c| match c {
            ' ' => Some('-'),
            c if c.is_alphanumeric() || c == '-' || c == '_' => Some(c),
            _ => None,
        })
        .collect()
}

#[test]
fn every_link_of_the_documents_and_the_manual_resolves() {
    let mut docs: Vec<PathBuf> = [
        "README.md",
        "EXPERIMENTS.md",
        "BENCHMARKS.md",
        "ARCHITECTURE.md",
    ]
    .iter()
    .map(|d| workspace().join(d))
    .collect();
    docs.extend(chapters());
    let mut broken = Vec::new();
    for doc in &docs {
        let text = std::fs::read_to_string(doc).unwrap();
        for target in link_targets(&text) {
            if target.starts_with("http://") || target.starts_with("https://") {
                continue;
            }
            let (file, anchor) = target.split_once('#').unwrap_or((&target, ""));
            let path = if file.is_empty() {
                doc.clone()
            } else {
                doc.parent().unwrap().join(file)
            };
            let name = doc.strip_prefix(workspace()).unwrap().display();
            if !path.exists() {
                broken.push(format!("{name}: `{target}` does not exist"));
                continue;
            }
            if !anchor.is_empty() && path.extension().is_some_and(|e| e == "md") {
                let heads = std::fs::read_to_string(&path).unwrap();
                let found = heads
                    .lines()
                    .filter_map(|l| l.strip_prefix('#'))
                    .any(|h| slug(h.trim_start_matches('#')) == anchor);
                if !found {
                    broken.push(format!("{name}: `{target}` has no such heading"));
                }
            }
        }
    }
    assert!(broken.is_empty(), "broken links:\n{}", broken.join("\n"));
}

#[test]
fn the_manual_s_summary_lists_every_chapter_once() {
    let summary = std::fs::read_to_string(workspace().join("docs/src/SUMMARY.md")).unwrap();
    let listed = link_targets(&summary);
    for chapter in chapters() {
        let name = chapter.file_name().unwrap().to_str().unwrap().to_owned();
        if name == "SUMMARY.md" {
            continue;
        }
        let times = listed.iter().filter(|t| **t == name).count();
        assert_eq!(times, 1, "docs/src/SUMMARY.md lists {name} {times} times");
    }
    assert_eq!(slug("Configuration reference"), "configuration-reference");
    assert_eq!(
        link_targets("a [b](c.md#d) `[e](f)` ![g](h.png)"),
        ["c.md#d", "h.png"]
    );
}

#[test]
fn experiments_and_benchmarks_list_every_section_in_their_contents() {
    for doc in ["EXPERIMENTS.md", "BENCHMARKS.md"] {
        let text = std::fs::read_to_string(workspace().join(doc)).unwrap();
        let contents = text
            .split("## Contents\n")
            .nth(1)
            .unwrap_or_else(|| panic!("{doc} has no `## Contents`"));
        let contents = &contents[..contents.find("\n## ").unwrap_or(contents.len())];
        let listed = link_targets(contents);
        let mut fenced = false;
        for line in text.lines() {
            if line.starts_with("```") {
                fenced = !fenced;
            }
            let Some(head) = line.strip_prefix("## ").filter(|_| !fenced) else {
                continue;
            };
            if head == "Contents" {
                continue;
            }
            let anchor = format!("#{}", slug(head));
            assert!(
                listed.contains(&anchor),
                "{doc}: `{head}` is not in its contents"
            );
        }
    }
}
