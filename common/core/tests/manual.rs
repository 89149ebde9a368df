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

/// A number as prose writes it (the minus sign `−` or `-`, a `+`, thousands commas), if it is one.
fn number(token: &str) -> Option<(f64, usize)> {
    let t: String = token
        .trim_start_matches('+')
        .replace('−', "-")
        .replace(',', "");
    let ok = t.chars().any(|c| c.is_ascii_digit())
        && t.chars()
            .all(|c| c.is_ascii_digit() || c == '.' || c == '-');
    let decimals = t.split_once('.').map_or(0, |(_, d)| d.len());
    ok.then(|| t.parse().ok().map(|v| (v, decimals))).flatten()
}

/// Every `value [low, high]` of `text`, each number with its decimals.
fn intervals(text: &str) -> Vec<[(f64, usize); 3]> {
    let mut out = Vec::new();
    let mut rest = text;
    while let Some(i) = rest.find(" [") {
        let before = rest[..i].rsplit(|c: char| c.is_whitespace() || c == '|' || c == '(');
        let inside = rest[i + 2..].split(']').next().unwrap_or("");
        rest = &rest[i + 2..];
        let Some(value) = before.into_iter().next().and_then(number) else {
            continue;
        };
        let parts: Vec<&str> = inside.split(", ").collect();
        if let [lo, hi] = parts[..] {
            if let (Some(lo), Some(hi)) = (number(lo), number(hi)) {
                out.push([value, lo, hi]);
            }
        }
    }
    out
}

/// `text` without its generated parts and code blocks.
pub(crate) fn prose(text: &str) -> String {
    let mut out = String::new();
    let (mut generated, mut fenced) = (false, false);
    for line in text.lines() {
        if line.starts_with("<!-- generated from") {
            generated = true;
        }
        if line.starts_with("```") {
            fenced = !fenced;
        }
        if !generated && !fenced && !line.starts_with("```") {
            out.push_str(line);
            out.push('\n');
        }
        if line.starts_with("<!-- end generated -->") {
            generated = false;
        }
    }
    out
}

/// Every Markdown, CSV, text and JSON file under `results/`: its path from the workspace, its text.
pub(crate) fn results_files() -> Vec<(String, String)> {
    let mut files = Vec::new();
    let mut dirs = vec![workspace().join("results")];
    while let Some(dir) = dirs.pop() {
        for e in std::fs::read_dir(&dir).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                dirs.push(p);
            } else if p
                .extension()
                .is_some_and(|x| ["md", "csv", "txt", "json"].contains(&x.to_str().unwrap()))
            {
                let rel = p.strip_prefix(workspace()).unwrap().display().to_string();
                files.push((rel, std::fs::read_to_string(&p).unwrap_or_default()));
            }
        }
    }
    files
}

#[test]
fn every_interval_quoted_in_prose_is_in_a_committed_results_file() {
    let found: Vec<[f64; 3]> = results_files()
        .iter()
        .flat_map(|(_, text)| intervals(text))
        .map(|t| t.map(|(v, _)| v))
        .collect();
    let mut docs: Vec<PathBuf> = ["README.md", "EXPERIMENTS.md", "BENCHMARKS.md"]
        .iter()
        .map(|d| workspace().join(d))
        .collect();
    docs.extend(chapters());
    let mut missing = Vec::new();
    let mut quoted = 0;
    for doc in &docs {
        for t in intervals(&prose(&std::fs::read_to_string(doc).unwrap())) {
            quoted += 1;
            // A results value rounded to the prose's decimals.
            let same = |r: &[f64; 3]| {
                (0..3).all(|i| format!("{:.*}", t[i].1, r[i]) == format!("{:.*}", t[i].1, t[i].0))
            };
            if !found.iter().any(same) {
                let name = doc.strip_prefix(workspace()).unwrap().display();
                missing.push(format!("{name}: {} [{}, {}]", t[0].0, t[1].0, t[2].0));
            }
        }
    }
    assert!(
        quoted >= 100,
        "only {quoted} intervals read: the reader is broken"
    );
    assert!(
        missing.is_empty(),
        "intervals in prose that no file under results/ holds:\n{}",
        missing.join("\n")
    );
    assert_eq!(
        intervals("mean −2.1 [−8.6, +4.3] and (11,155 [10,351, 12,762]) | x [a, b]"),
        [
            [(-2.1, 1), (-8.6, 1), (4.3, 1)],
            [(11155.0, 0), (10351.0, 0), (12762.0, 0)]
        ]
    );
}
