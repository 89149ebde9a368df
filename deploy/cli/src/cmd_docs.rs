//! `alfd docs`: the generated parts of the Markdown documents, re-made from the committed files
//! they quote, so that a results table cannot go stale.
//!
//! A generated part sits between two markers:
//!
//! ```text
//! <!-- generated from results/study-mountaincar/summary.md, section "Query rules by budget" -->
//! ...replaced by the section's text...
//! <!-- end generated -->
//! ```
//!
//! The source is a path from the repository's root; `, section "NAME"` takes the part of a
//! Markdown file under its heading `## NAME` (to the next heading of that level or higher),
//! without it the whole file. The source [`CONFIG_REFERENCE`] is the configuration reference
//! made from the config types (`alfd config reference`). The documents are README.md,
//! EXPERIMENTS.md, BENCHMARKS.md and the manual's chapters (`docs/src/*.md`). `alfd docs` rewrites them; `alfd docs --check` changes
//! nothing and fails (exit code 1) naming each part that differs.

use std::path::{Path, PathBuf};

use anyhow::Context as _;

use crate::usage::usage;

/// The documents at the repository's root that may have generated parts; the manual's chapters
/// (`docs/src/*.md`, see [`documents`]) may too.
pub const DOCUMENTS: [&str; 3] = ["README.md", "EXPERIMENTS.md", "BENCHMARKS.md"];
/// The manual's chapters, beside [`DOCUMENTS`].
pub const CHAPTERS: &str = "docs/src";

/// Every document `alfd docs` reads under `root`: [`DOCUMENTS`], then the chapters in name order.
pub fn documents(root: &Path) -> anyhow::Result<Vec<String>> {
    let mut docs: Vec<String> = DOCUMENTS.iter().map(|d| (*d).to_owned()).collect();
    let dir = root.join(CHAPTERS);
    let entries = std::fs::read_dir(&dir)
        .map_err(|e| usage(format!("cannot read {}: {e}", dir.display())))?;
    let mut chapters: Vec<String> = entries
        .flatten()
        .filter_map(|e| e.file_name().into_string().ok())
        .filter(|n| n.ends_with(".md"))
        .map(|n| format!("{CHAPTERS}/{n}"))
        .collect();
    chapters.sort();
    docs.extend(chapters);
    Ok(docs)
}

const BEGIN: &str = "<!-- generated from ";
/// The source name of the configuration reference.
pub const CONFIG_REFERENCE: &str = "`alfd config reference`";
const END: &str = "<!-- end generated -->";

#[derive(Debug, clap::Args)]
pub struct DocsArgs {
    /// Only check: exit 1, naming each generated part that differs from its source.
    #[arg(long)]
    pub check: bool,
    /// The repository's root (default: the current directory).
    #[arg(long, default_value = ".")]
    pub root: PathBuf,
}

pub fn run(args: DocsArgs) -> anyhow::Result<()> {
    let mut stale = Vec::new();
    for doc in documents(&args.root)? {
        let doc = doc.as_str();
        let path = args.root.join(doc);
        let text = std::fs::read_to_string(&path)
            .map_err(|e| usage(format!("cannot read {}: {e}", path.display())))?;
        let made = generate(&text, |src| read_source(&args.root, src))
            .with_context(|| format!("in {}", path.display()))?;
        if made.text != text {
            if args.check {
                stale.extend(made.changed.iter().map(|s| format!("{doc}: {s}")));
            } else {
                std::fs::write(&path, &made.text)
                    .with_context(|| format!("cannot write {}", path.display()))?;
                println!("{doc}: {} generated parts re-made", made.changed.len());
            }
        }
    }
    if !stale.is_empty() {
        anyhow::bail!(
            "generated parts differ from their sources (run `alfd docs`):\n  {}",
            stale.join("\n  ")
        );
    }
    Ok(())
}

/// A source named in a marker: a file and maybe one of its sections.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Source {
    pub path: String,
    pub section: Option<String>,
    /// `, table` after the section: only the section's first Markdown table.
    pub table: bool,
}

impl Source {
    /// Reads `results/x/summary.md, section "Name" -->` (the marker's rest).
    fn parse(rest: &str) -> anyhow::Result<Self> {
        let rest = rest
            .trim()
            .strip_suffix("-->")
            .context("a generated marker must end with -->")?
            .trim();
        let (rest, table) = match rest.strip_suffix(", table") {
            Some(r) => (r.trim_end(), true),
            None => (rest, false),
        };
        Ok(match rest.split_once(", section ") {
            Some((path, section)) => Source {
                path: path.trim().to_owned(),
                section: Some(
                    section
                        .trim()
                        .strip_prefix('"')
                        .and_then(|s| s.strip_suffix('"'))
                        .with_context(|| format!("the section in `{rest}` must be quoted"))?
                        .to_owned(),
                ),
                table,
            },
            None => Source {
                path: rest.to_owned(),
                section: None,
                table,
            },
        })
    }
}

fn read_source(root: &Path, src: &Source) -> anyhow::Result<String> {
    if src.path == CONFIG_REFERENCE {
        return Ok(alfd_common::config::reference::markdown());
    }
    let path = root.join(&src.path);
    let text = std::fs::read_to_string(&path)
        .map_err(|e| usage(format!("cannot read {}: {e}", path.display())))?;
    let part = match &src.section {
        None => text,
        Some(name) => section(&text, name)
            .ok_or_else(|| usage(format!("{} has no section \"{name}\"", path.display())))?,
    };
    if !src.table {
        return Ok(part);
    }
    first_table(&part).ok_or_else(|| usage(format!("{}: no table in {src:?}", path.display())))
}

/// The first Markdown table of `text`: its consecutive lines that start with `|`.
pub fn first_table(text: &str) -> Option<String> {
    let rows: Vec<&str> = text
        .lines()
        .skip_while(|l| !l.starts_with('|'))
        .take_while(|l| l.starts_with('|'))
        .collect();
    (!rows.is_empty()).then(|| rows.join("\n"))
}

/// The text under the heading `#… name` of `markdown`, to the next heading of its level or
/// higher, trimmed of blank lines at both ends.
pub fn section(markdown: &str, name: &str) -> Option<String> {
    let mut lines = markdown.lines();
    let level = lines.by_ref().find_map(|l| {
        let hashes = l.chars().take_while(|&c| c == '#').count();
        (hashes > 0 && l[hashes..].trim() == name).then_some(hashes)
    })?;
    let body: Vec<&str> = lines
        .take_while(|l| {
            let hashes = l.chars().take_while(|&c| c == '#').count();
            !(hashes > 0 && hashes <= level && l[hashes..].starts_with(' '))
        })
        .collect();
    Some(body.join("\n").trim_matches('\n').to_owned())
}

/// The document with its generated parts re-made, and which parts changed.
#[derive(Debug)]
pub struct Generated {
    pub text: String,
    pub changed: Vec<String>,
}

/// Re-makes every generated part of `doc`, reading sources with `read`.
pub fn generate(
    doc: &str,
    mut read: impl FnMut(&Source) -> anyhow::Result<String>,
) -> anyhow::Result<Generated> {
    let mut out = String::with_capacity(doc.len());
    let mut changed = Vec::new();
    let mut lines = doc.split_inclusive('\n').enumerate();
    while let Some((i, line)) = lines.next() {
        out.push_str(line);
        let Some(rest) = line.trim_end().strip_prefix(BEGIN) else {
            continue;
        };
        let src = Source::parse(rest).with_context(|| format!("line {}", i + 1))?;
        let mut old = String::new();
        let mut closed = false;
        for (_, l) in lines.by_ref() {
            if l.trim_end() == END {
                closed = true;
                let new = format!("{}\n", read(&src)?.trim_end());
                if new != old {
                    changed.push(match &src.section {
                        Some(s) => format!("line {}: {} \"{s}\"", i + 1, src.path),
                        None => format!("line {}: {}", i + 1, src.path),
                    });
                }
                out.push_str(&new);
                out.push_str(l);
                break;
            }
            old.push_str(l);
        }
        anyhow::ensure!(closed, "line {}: no `{END}` after this marker", i + 1);
    }
    Ok(Generated { text: out, changed })
}

#[cfg(test)]
mod tests {
    use super::*;

    const SUMMARY: &str = "# T\n\nintro\n\n## Query rules by budget\n\n| a |\n|---|\n| 1 |\n\n### sub\n\nmore\n\n## Runs\n\nx\n";

    #[test]
    fn a_section_runs_to_the_next_heading_of_its_level() {
        assert_eq!(
            section(SUMMARY, "Query rules by budget").unwrap(),
            "| a |\n|---|\n| 1 |\n\n### sub\n\nmore"
        );
        assert_eq!(section(SUMMARY, "Runs").unwrap(), "x");
        assert_eq!(section(SUMMARY, "Nothing"), None);
    }

    #[test]
    fn generated_parts_are_replaced_and_reported() {
        let doc = "text\n<!-- generated from r/s.md, section \"Runs\" -->\nold\n<!-- end generated -->\ntail\n";
        let read = |s: &Source| {
            assert_eq!(s.path, "r/s.md");
            Ok(section(SUMMARY, s.section.as_deref().unwrap()).unwrap())
        };
        let g = generate(doc, read).unwrap();
        assert_eq!(
            g.text,
            "text\n<!-- generated from r/s.md, section \"Runs\" -->\nx\n<!-- end generated -->\ntail\n"
        );
        assert_eq!(g.changed, vec!["line 2: r/s.md \"Runs\"".to_owned()]);
        // Generated again: nothing changes.
        let again = generate(&g.text, read).unwrap();
        assert_eq!((again.text, again.changed.len()), (g.text, 0));
    }

    #[test]
    fn a_table_marker_takes_the_section_s_first_table() {
        let src = Source::parse("r/s.md, section \"Query rules by budget\", table -->").unwrap();
        assert_eq!(
            (src.path.as_str(), src.section.as_deref(), src.table),
            ("r/s.md", Some("Query rules by budget"), true)
        );
        let part = section(SUMMARY, "Query rules by budget").unwrap();
        assert_eq!(first_table(&part).unwrap(), "| a |\n|---|\n| 1 |");
        assert_eq!(first_table("no table here"), None);
        assert!(!Source::parse("r/s.md -->").unwrap().table);
    }

    #[test]
    fn an_unclosed_marker_or_an_unquoted_section_is_an_error() {
        let read = |_: &Source| Ok(String::new());
        let e = generate("<!-- generated from a.md -->\nx\n", read).unwrap_err();
        assert!(e.to_string().contains("end generated"), "{e}");
        let e = generate(
            "<!-- generated from a.md, section Runs -->\n<!-- end generated -->\n",
            read,
        )
        .unwrap_err();
        assert!(format!("{e:#}").contains("quoted"), "{e:#}");
    }
}
