//! A function a reader can see at once: no function outside tests is over 80 lines, in any
//! crate of the workspace (its files as `tidy` finds them from `cargo metadata`).

use crate::tidy::{workspace, workspace_rust_files};

/// The longest a function may be, from its `fn` line to its closing brace.
const MAX_LINES: usize = 80;

/// Each function of `text` that is not test code, as (name, first line (1-based), lines).
/// Test code is a `#[cfg(test)]` module (to the file's end, where such modules stand) and
/// every file under `tests/`. A function ends at the first line that is its indentation and a
/// closing brace, as `cargo fmt` writes it; a declaration without a body is not one.
fn functions(text: &str) -> Vec<(String, usize, usize)> {
    let lines: Vec<&str> = text.lines().collect();
    let end = lines
        .windows(2)
        .position(|w| w[0].trim() == "#[cfg(test)]" && is_mod(w[1]))
        .unwrap_or(lines.len());
    let mut out = Vec::new();
    let mut i = 0;
    while i < end {
        let Some((indent, name)) = fn_start(lines[i]) else {
            i += 1;
            continue;
        };
        let Some(open) = (i..end).find(|&j| lines[j].contains('{') || lines[j].ends_with(';'))
        else {
            break;
        };
        if !lines[open].contains('{') || one_line_body(lines[open]) {
            i = open + 1;
            continue;
        }
        let close = format!("{indent}}}");
        let last = (open + 1..end)
            .find(|&j| lines[j] == close)
            .unwrap_or(end - 1);
        out.push((name, i + 1, last - i + 1));
        i = last + 1;
    }
    out
}

fn is_mod(line: &str) -> bool {
    let t = line.trim_start();
    t.starts_with("mod ") || t.starts_with("pub mod ") || t.starts_with("pub(crate) mod ")
}

fn one_line_body(line: &str) -> bool {
    line.trim_end().ends_with('}') && line.matches('{').count() == line.matches('}').count()
}

/// The indentation and name of a function that starts on `line`.
fn fn_start(line: &str) -> Option<(String, String)> {
    let indent = &line[..line.len() - line.trim_start().len()];
    let mut words = line.split_whitespace();
    let qualifiers = [
        "pub",
        "pub(crate)",
        "pub(super)",
        "const",
        "async",
        "unsafe",
        "extern",
    ];
    let mut word = words.next()?;
    while qualifiers.contains(&word) || word.starts_with('"') {
        word = words.next()?;
    }
    if word != "fn" {
        return None;
    }
    let name = words.next()?.split(['<', '(']).next()?.to_owned();
    Some((indent.to_owned(), name))
}

#[test]
fn no_function_outside_tests_is_over_80_lines() {
    let files = workspace_rust_files();
    let mut seen = 0;
    let mut long = Vec::new();
    for f in &files {
        let rel = f.strip_prefix(workspace()).unwrap();
        if rel.components().any(|c| c.as_os_str() == "tests") {
            continue;
        }
        for (name, line, n) in functions(&std::fs::read_to_string(f).unwrap()) {
            seen += 1;
            if n > MAX_LINES {
                long.push(format!("{}:{line} {name} ({n} lines)", rel.display()));
            }
        }
    }
    assert!(seen > 1000, "found only {seen} functions");
    assert!(long.is_empty(), "shorten these functions: {long:?}");
}

#[test]
fn the_function_check_measures_bodies_and_skips_declarations_and_test_modules() {
    let body: String = (0..81).map(|i| format!("    let x{i} = {i};\n")).collect();
    let text = format!(
        "pub(crate) unsafe fn long<T>(\n    a: T,\n) {{\n{body}}}\n\
         fn short() -> u8 {{ 1 }}\n\
         trait T {{\n    fn declared(&self);\n    fn given(&self) {{\n        ()\n    }}\n}}\n\
         #[cfg(test)]\nmod tests {{\n    fn in_test() {{\n{body}    }}\n}}\n"
    );
    let found = functions(&text);
    assert_eq!(
        found,
        vec![("long".to_owned(), 1, 85), ("given".to_owned(), 89, 3)]
    );
}
