//! Numbers with two or more decimals quoted in the prose of README, EXPERIMENTS, BENCHMARKS and
//! the manual come from committed results: each is found in a file under `results/`, rounded to
//! the prose's decimals. So do the intervals quoted in whole numbers ("−136 [−147, −127]": an
//! interval of the results rounded to integers) and the counts ("15 of 30": "15 of 30" or
//! "15/30" in a results file). Code spans (`beta2 = 0.999`) are settings, not results, and are skipped;
//! so are the generated parts and code blocks, which `alfd docs --check` keeps equal to their
//! sources.

use std::collections::HashSet;
use std::path::PathBuf;

use crate::manual::{chapters, prose, results_texts};
use crate::tidy::workspace;

/// The fewest decimals a quoted number needs to be checked: counts, years and settings such as
/// "0.5" are not results.
const DECIMALS: usize = 2;

/// `text` without its inline code spans.
fn without_code_spans(text: &str) -> String {
    text.split('`').step_by(2).collect::<Vec<_>>().join(" ")
}

/// Every number of `text` with at least [`DECIMALS`] decimals, as prose writes it ("−0.015",
/// "+4.497", "1,347.50"), normalised to `-0.015`, `4.497`, `1347.50`.
fn decimals_in(text: &str) -> Vec<String> {
    let chars: Vec<char> = text.chars().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < chars.len() {
        let starts = chars[i].is_ascii_digit()
            && (i == 0 || !(chars[i - 1].is_alphanumeric() || ".,_".contains(chars[i - 1])));
        if !starts {
            i += 1;
            continue;
        }
        // A sign directly before, itself not after a word or number ("0.50-0.68" is a range).
        let negative = i > 0
            && "-−".contains(chars[i - 1])
            && (i < 2 || !(chars[i - 2].is_alphanumeric() || chars[i - 2] == '.'));
        let mut j = i;
        while j < chars.len() && (chars[j].is_ascii_digit() || chars[j] == ',') {
            j += 1;
        }
        if j >= chars.len() || chars[j] != '.' {
            i = j;
            continue;
        }
        let whole: String = chars[i..j].iter().filter(|c| **c != ',').collect();
        let mut k = j + 1;
        while k < chars.len() && chars[k].is_ascii_digit() {
            k += 1;
        }
        let ends = k >= chars.len() || !(chars[k].is_alphanumeric() || chars[k] == '_');
        let more_dots = k < chars.len()
            && chars[k] == '.'
            && chars.get(k + 1).is_some_and(char::is_ascii_digit);
        if k - j > DECIMALS && ends && !more_dots {
            let sign = if negative { "-" } else { "" };
            out.push(format!(
                "{sign}{whole}.{}",
                chars[j + 1..k].iter().collect::<String>()
            ));
        }
        i = k;
    }
    out
}

/// Every decimal number of the committed results, formatted with 2 to 6 decimals.
fn results_values() -> HashSet<String> {
    let mut values = HashSet::new();
    for text in results_texts() {
        let tokens = text.split(|c: char| !(c.is_ascii_digit() || ".eE+-".contains(c)));
        for v in tokens
            .filter(|t| t.contains('.'))
            .filter_map(|t| t.parse::<f64>().ok())
        {
            for d in DECIMALS..=6 {
                values.insert(format!("{v:.d$}"));
            }
        }
    }
    values
}

/// The numbers of `text` with their places: (start, end, value), in characters; a sign counts
/// when not after a word or a number, commas group thousands.
fn numbers_in(chars: &[char]) -> Vec<(usize, usize, f64)> {
    let mut out = Vec::new();
    let mut i = 0;
    while i < chars.len() {
        let after_word =
            |k: usize| k > 0 && (chars[k - 1].is_alphanumeric() || ".,_".contains(chars[k - 1]));
        if !chars[i].is_ascii_digit() || after_word(i) {
            i += 1;
            continue;
        }
        let signed = i > 0 && "-−+".contains(chars[i - 1]) && !after_word(i - 1);
        let start = if signed { i - 1 } else { i };
        let mut j = i;
        loop {
            let digit_next = chars.get(j + 1).is_some_and(char::is_ascii_digit);
            match chars.get(j) {
                Some(c) if c.is_ascii_digit() => j += 1,
                Some(',' | '.') if digit_next => j += 1,
                _ => break,
            }
        }
        let body: String = chars[i..j].iter().filter(|c| **c != ',').collect();
        if let Ok(v) = body.parse::<f64>() {
            let negative = signed && chars[i - 1] != '+';
            out.push((start, j, if negative { -v } else { v }));
        }
        i = j;
    }
    out
}

/// README, EXPERIMENTS, BENCHMARKS and the manual's chapters: each one's name and its prose
/// without code spans.
fn documents() -> Vec<(String, String)> {
    let mut docs: Vec<PathBuf> = ["README.md", "EXPERIMENTS.md", "BENCHMARKS.md"]
        .iter()
        .map(|d| workspace().join(d))
        .collect();
    docs.extend(chapters());
    docs.iter()
        .map(|doc| {
            let text = without_code_spans(&prose(&std::fs::read_to_string(doc).unwrap()));
            let name = doc.strip_prefix(workspace()).unwrap().display().to_string();
            (name, text)
        })
        .collect()
}

/// The text between two numbers, each run of white space (a line break included) one space.
fn gap(chars: &[char]) -> String {
    let text: String = chars.iter().collect();
    let mut out = text.split_whitespace().collect::<Vec<_>>().join(" ");
    if text.starts_with(char::is_whitespace) {
        out.insert(0, ' ');
    }
    if text.ends_with(char::is_whitespace) && text.trim() != "" {
        out.push(' ');
    }
    out
}

/// The whole-number intervals of `text` ("−136 [−147, −127]") and its counts ("15 of 30"), each
/// number without decimals.
fn whole_intervals_and_counts(text: &str) -> (Vec<[i64; 3]>, Vec<[i64; 2]>) {
    let chars: Vec<char> = text.chars().collect();
    let between = |a: usize, b: usize| gap(&chars[a..b]);
    let whole = |(s, e, _): (usize, usize, f64)| !chars[s..e].contains(&'.');
    let n = numbers_in(&chars);
    let (mut intervals, mut counts) = (Vec::new(), Vec::new());
    for w in n.windows(3) {
        let closes = chars.get(w[2].1) == Some(&']');
        if w.iter().all(|&x| whole(x))
            && closes
            && between(w[0].1, w[1].0) == " ["
            && between(w[1].1, w[2].0) == ", "
        {
            intervals.push([w[0].2, w[1].2, w[2].2].map(|v| v as i64));
        }
    }
    for w in n.windows(2) {
        if w.iter().all(|&x| whole(x)) && between(w[0].1, w[1].0) == " of " {
            counts.push([w[0].2 as i64, w[1].2 as i64]);
        }
    }
    (intervals, counts)
}

/// The intervals of the committed results rounded to whole numbers (half away from zero and
/// half up), and their counts, "N of M" or "N/M".
fn results_intervals_and_counts() -> (HashSet<[i64; 3]>, HashSet<[i64; 2]>) {
    let (mut intervals, mut counts) = (HashSet::new(), HashSet::new());
    for text in results_texts() {
        let chars: Vec<char> = text.chars().collect();
        let between = |a: usize, b: usize| gap(&chars[a..b]);
        let n = numbers_in(&chars);
        for w in n.windows(3) {
            if between(w[0].1, w[1].0) == " [" && between(w[1].1, w[2].0) == ", " {
                let v = [w[0].2, w[1].2, w[2].2];
                intervals.insert(v.map(|x| x.round() as i64));
                intervals.insert(v.map(|x| (x + 0.5).floor() as i64));
            }
        }
        for w in n.windows(2) {
            if [" of ", "/"].contains(&between(w[0].1, w[1].0).as_str()) {
                counts.insert([w[0].2 as i64, w[1].2 as i64]);
            }
        }
    }
    (intervals, counts)
}

#[test]
fn every_whole_number_interval_and_count_quoted_in_prose_is_in_a_committed_results_file() {
    let (i, c) = whole_intervals_and_counts(
        "at −136\n[−147, −127] (15 of\n30), 0.5 [0.25, 1] and +4 [3, 5] in 2,000 of 20,000 steps",
    );
    assert_eq!(i, [[-136, -147, -127], [4, 3, 5]]);
    assert_eq!(c, [[15, 30], [2000, 20000]]);
    let (found_intervals, found_counts) = results_intervals_and_counts();
    let (mut quoted, mut missing) = (0, Vec::new());
    for (doc, text) in documents() {
        let (intervals, counts) = whole_intervals_and_counts(&text);
        let name = &doc;
        for [x, l, h] in intervals {
            quoted += 1;
            if !found_intervals.contains(&[x, l, h]) {
                missing.push(format!("{name}: {x} [{l}, {h}]"));
            }
        }
        for [n, m] in counts {
            quoted += 1;
            if !found_counts.contains(&[n, m]) {
                missing.push(format!("{name}: {n} of {m}"));
            }
        }
    }
    assert!(quoted >= 60, "only {quoted} read: the reader is broken");
    assert!(
        missing.is_empty(),
        "whole-number intervals and counts in prose that no file under results/ holds:\n{}",
        missing.join("\n")
    );
}

#[test]
fn every_number_with_decimals_quoted_in_prose_is_in_a_committed_results_file() {
    assert_eq!(
        decimals_in("final −0.015 [+4.497, 1,347.50] at 0.5, v0.3.6, x1.25, 0.50-0.68, 12 345.67 and 12.345."),
        ["-0.015", "4.497", "1347.50", "0.50", "0.68", "345.67", "12.345"]
    );
    assert_eq!(without_code_spans("a `beta2 = 0.999` b"), "a   b");
    let found = results_values();
    let (mut quoted, mut missing) = (0, Vec::new());
    for (doc, text) in documents() {
        for number in decimals_in(&text) {
            quoted += 1;
            if !found.contains(&number) {
                missing.push(format!("{doc}: {number}"));
            }
        }
    }
    assert!(
        quoted >= 200,
        "only {quoted} numbers read: the reader is broken"
    );
    assert!(
        missing.is_empty(),
        "numbers in prose that no file under results/ holds (to the prose's decimals):\n{}",
        missing.join("\n")
    );
}
