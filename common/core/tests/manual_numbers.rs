//! Numbers quoted in the prose of README, EXPERIMENTS, BENCHMARKS and the manual come from
//! committed results. Each is looked up in the results files its section (the text from one
//! heading to the next) names (a file, a directory, or a pattern such as
//! `results/experts-returns-*/ranking.md`), or in any results file when the section names none:
//! - a number with two or more decimals, rounded to the prose's decimals; settings and versions
//!   with decimals are listed in `NOT_RESULTS`;
//! - an interval quoted in whole numbers ("−136 [−147, −127]"), as an interval of the file
//!   rounded to integers, and a count ("15 of 30"), as "15 of 30" or "15/30".
//!
//! A number with one decimal, and a whole number but 0, is checked only in a section that cites
//! results files (settings listed in `NOT_RESULTS_ONE_DECIMAL` and `NOT_RESULTS_WHOLE`): every
//! such value from −200 to 100, and most whole numbers, occur in some results file, so a lookup
//! in all of them could not fail. A section that cites none quotes no whole number but 0, nor one
//! with one decimal, but the settings listed in `UNCITED_SETTINGS`. Ordinals ("26th"), sizes
//! ("15×15"), exponents ("1e-30"), names ("AVX-512", "exit code 2") and references ("figure 6",
//! "eq. 4") are not results. A whole number below 100 is in most results files somewhere, so its
//! lookup catches a number no cited file holds, not one that holds it in another place. Code
//! spans (`beta2 = 0.999`) are settings, not results, and are skipped; so are the generated
//! parts and code blocks, which `alfd docs --check` keeps equal to their sources.

use std::collections::HashSet;

use crate::manual::{chapters, prose, results_files};
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
    with_decimals(text, DECIMALS)
}

/// Every number of `text` with at least `fewest` decimals, normalised as [`decimals_in`] says.
fn with_decimals(text: &str, fewest: usize) -> Vec<String> {
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
        if k - j > fewest && ends && !more_dots {
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

/// `text` with each run of white space (a line break included) one space.
fn words(text: &str) -> String {
    text.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// The text between two numbers, each run of white space (a line break included) one space.
fn gap(chars: &[char]) -> String {
    let text: String = chars.iter().collect();
    let mut out = words(&text);
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

/// The intervals of a results file's `text` rounded to whole numbers (half away from zero and
/// half up), and its counts, "N of M" or "N/M".
fn intervals_and_counts_of(text: &str) -> (HashSet<[i64; 3]>, HashSet<[i64; 2]>) {
    let (mut intervals, mut counts) = (HashSet::new(), HashSet::new());
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
    (intervals, counts)
}

/// Of `files` (path, what was read of it), those a section citing `cited` may quote: the ones
/// it names, or all when it names none.
fn scoped<'a, T>(files: &'a [(String, T)], cited: &[String]) -> Vec<&'a T> {
    files
        .iter()
        .filter(|(path, _)| cited.is_empty() || cited.iter().any(|c| cites(c, path)))
        .map(|(_, t)| t)
        .collect()
}

/// Every section of README, EXPERIMENTS, BENCHMARKS and the manual's chapters: its document's
/// name, the results paths it cites, and its prose without code spans.
fn prose_sections() -> Vec<(String, Vec<String>, String)> {
    let docs = ["README.md", "EXPERIMENTS.md", "BENCHMARKS.md"].map(|d| workspace().join(d));
    let mut out = Vec::new();
    for doc in docs.into_iter().chain(chapters()) {
        let name = doc.strip_prefix(workspace()).unwrap().display().to_string();
        for section in sections(&std::fs::read_to_string(&doc).unwrap()) {
            let text = without_code_spans(&prose(&section));
            out.push((name.clone(), cited_paths(&section), text));
        }
    }
    out
}

#[test]
fn every_whole_number_interval_and_count_quoted_in_prose_is_in_a_results_file_its_section_cites() {
    let (i, c) = whole_intervals_and_counts(
        "at −136\n[−147, −127] (15 of\n30), 0.5 [0.25, 1] and +4 [3, 5] in 2,000 of 20,000 steps",
    );
    assert_eq!(i, [[-136, -147, -127], [4, 3, 5]]);
    assert_eq!(c, [[15, 30], [2000, 20000]]);
    let files: Vec<(String, _)> = results_files()
        .into_iter()
        .map(|(path, text)| (path, intervals_and_counts_of(&text)))
        .collect();
    let (mut quoted, mut missing) = (0, Vec::new());
    for (name, cited, text) in prose_sections() {
        let found = scoped(&files, &cited);
        let (intervals, counts) = whole_intervals_and_counts(&text);
        for [x, l, h] in intervals {
            quoted += 1;
            if !found.iter().any(|(i, _)| i.contains(&[x, l, h])) {
                missing.push(format!("{name}: {x} [{l}, {h}]"));
            }
        }
        for [n, m] in counts {
            quoted += 1;
            if !found.iter().any(|(_, c)| c.contains(&[n, m])) {
                missing.push(format!("{name}: {n} of {m}"));
            }
        }
    }
    assert!(quoted >= 60, "only {quoted} read: the reader is broken");
    assert!(
        missing.is_empty(),
        "whole-number intervals and counts in prose that no results file their section cites \
         holds:\n{}",
        missing.join("\n")
    );
}

/// Settings and versions quoted in prose with two or more decimals, which are not results: the
/// document and the words around the number, as written (line breaks as spaces).
const NOT_RESULTS: [(&str, &str); 15] = [
    ("README.md", "toolchain 1.89"),
    ("README.md", "Python 3.10+"),
    ("docs/src/install.md", "toolchain (1.89"),
    ("docs/src/install.md", "Python 3.10+"),
    ("docs/src/across-hosts.md", "zenoh 1.10"),
    ("BENCHMARKS.md", "Linux 6.12"),
    ("BENCHMARKS.md", "probability 0.05 a step"),
    ("BENCHMARKS.md", "ε from 1 to 0.05"),
    ("BENCHMARKS.md", "with Python 3.11 and"),
    ("EXPERIMENTS.md", "learning rate 0.001"),
    ("EXPERIMENTS.md", "ε from 1 to 0.05"),
    ("EXPERIMENTS.md", "λ = 0.75"),
    ("EXPERIMENTS.md", "+0.75 on top of"),
    ("EXPERIMENTS.md", "to 0 or to 0.00005"),
    ("EXPERIMENTS.md", "τ = 0.002"),
];

/// Whether the results file `path` is what `cited` names: the file, a directory holding it, or
/// a pattern whose `*` stands for any part of one name.
fn cites(cited: &str, path: &str) -> bool {
    let cited = cited.trim_end_matches(['/', '.', ',', ';', ':', ')']);
    let (want, have): (Vec<&str>, Vec<&str>) =
        (cited.split('/').collect(), path.split('/').collect());
    want.len() <= have.len() && want.iter().zip(&have).all(|(w, h)| matches_name(w, h))
}

/// Whether `name` matches `pattern`, whose `*` stands for any run of characters.
fn matches_name(pattern: &str, name: &str) -> bool {
    match pattern.split_once('*') {
        None => pattern == name,
        Some((head, tail)) => name.strip_prefix(head).is_some_and(|rest| {
            (0..=rest.len())
                .filter(|&i| rest.is_char_boundary(i))
                .any(|i| matches_name(tail, &rest[i..]))
        }),
    }
}

/// Every path under `results/` that `text` names.
fn cited_paths(text: &str) -> Vec<String> {
    let allowed = |c: char| c.is_ascii_alphanumeric() || "-_./*".contains(c);
    text.match_indices("results/")
        .filter(|(at, _)| !text[..*at].ends_with(|c: char| c.is_ascii_alphanumeric()))
        .map(|(at, _)| text[at..].chars().take_while(|&c| allowed(c)).collect())
        .collect()
}

/// A document's sections (split at its headings outside code blocks), each whole.
fn sections(text: &str) -> Vec<String> {
    let (mut out, mut current, mut fenced) = (Vec::new(), String::new(), false);
    for line in text.lines() {
        if line.starts_with("```") {
            fenced = !fenced;
        }
        if !fenced && line.starts_with('#') && !current.is_empty() {
            out.push(std::mem::take(&mut current));
        }
        current.push_str(line);
        current.push('\n');
    }
    out.push(current);
    out
}

/// Every decimal number of `text`, formatted with 1 to 6 decimals.
fn values_of(text: &str) -> HashSet<String> {
    let mut values = HashSet::new();
    let tokens = text.split(|c: char| !(c.is_ascii_digit() || ".eE+-".contains(c)));
    for v in tokens
        .filter(|t| t.contains('.'))
        .filter_map(|t| t.parse::<f64>().ok())
    {
        for d in 1..=6 {
            values.insert(format!("{v:.d$}"));
        }
    }
    values
}

#[test]
fn every_number_with_decimals_quoted_in_prose_is_in_a_results_file_its_section_cites() {
    assert_eq!(
        decimals_in("final −0.015 [+4.497, 1,347.50] at 0.5, v0.3.6, x1.25, 0.50-0.68, 12 345.67 and 12.345."),
        ["-0.015", "4.497", "1347.50", "0.50", "0.68", "345.67", "12.345"]
    );
    assert_eq!(without_code_spans("a `beta2 = 0.999` b"), "a   b");
    assert!(cites("results/a/", "results/a/summary.md") && !cites("results/a", "results/ab/x.md"));
    assert!(cites(
        "results/x-*/ranking.md",
        "results/x-acrobot/ranking.md"
    ));
    assert!(!cites(
        "results/x-*/ranking.md",
        "results/x-acrobot/runs.csv"
    ));
    assert_eq!(
        cited_paths("see `results/a/b.md`, and results/c."),
        ["results/a/b.md", "results/c."]
    );
    let (quoted, citing, missing) = unfound(&decimals_in, false, &NOT_RESULTS);
    assert!(
        quoted >= 200 && citing >= 40,
        "only {quoted} numbers read ({citing} sections with citations): the reader is broken"
    );
    assert!(
        missing.is_empty(),
        "numbers in prose that no results file its section cites holds (to the prose's decimals; \
         a setting or version goes in NOT_RESULTS):\n{}",
        missing.join("\n")
    );
}

/// The numbers `pick` takes from each section's prose (only the sections that cite results files
/// with `citing_only`), each looked up in the results files its section cites: how many were
/// read, how many sections cite files, and those found in none (the settings of `not_results`
/// aside), named with their document and heading.
fn unfound(
    pick: &dyn Fn(&str) -> Vec<String>,
    citing_only: bool,
    not_results: &[(&str, &str)],
) -> (usize, usize, Vec<String>) {
    unfound_in(pick, &values_of, citing_only, not_results)
}

/// Whether `number` of document `name` is a setting of `not_results`: an entry of that document
/// holds it and the section's `words` hold the entry.
fn listed(not_results: &[(&str, &str)], name: &str, words: &str, number: &str) -> bool {
    not_results.iter().any(|(d, around)| {
        let plain = around.replace(',', "").replace('−', "-");
        *d == name && (around.contains(number) || plain.contains(number)) && words.contains(around)
    })
}

/// [`unfound`] with the values of each results file read by `values`.
fn unfound_in(
    pick: &dyn Fn(&str) -> Vec<String>,
    values: &dyn Fn(&str) -> HashSet<String>,
    citing_only: bool,
    not_results: &[(&str, &str)],
) -> (usize, usize, Vec<String>) {
    let files: Vec<(String, HashSet<String>)> = results_files()
        .into_iter()
        .map(|(path, text)| (path, values(&text)))
        .collect();
    let (mut quoted, mut citing, mut missing) = (0, 0, Vec::new());
    for (name, cited, text) in prose_sections() {
        citing += usize::from(!cited.is_empty());
        if citing_only && cited.is_empty() {
            continue;
        }
        let found = scoped(&files, &cited);
        let words = words(&text);
        for number in pick(&text) {
            quoted += 1;
            let setting = listed(not_results, &name, &words, &number);
            if !setting && !found.iter().any(|v| v.contains(&number)) {
                let heading = text.lines().find(|l| !l.is_empty()).unwrap_or_default();
                missing.push(format!("{name} ({heading}): {number}"));
            }
        }
    }
    (quoted, citing, missing)
}

/// Settings quoted with one decimal in sections that cite results files: the document and the
/// words around the number, as written (line breaks as spaces).
const NOT_RESULTS_ONE_DECIMAL: [(&str, &str); 7] = [
    ("docs/src/across-hosts.md", "TLS 1.3"),
    ("docs/src/datasets.md", "(minari 0.4-0.5;"),
    ("docs/src/faults.md", "SIGCONT 0.3-3 s"),
    ("docs/src/faults.md", "filled for 0.3-3 s"),
    ("docs/src/faults.md", "held 1.2-3 s"),
    ("docs/src/faults.md", "for 0.6-6 s"),
    ("docs/src/faults.md", "every 0.2 s for 90 s"),
];

/// The numbers of `text` with exactly one decimal.
fn one_decimals(text: &str) -> Vec<String> {
    let numbers = with_decimals(text, 1).into_iter();
    numbers
        .filter(|n| n.split_once('.').is_some_and(|(_, d)| d.len() == 1))
        .collect()
}

/// One decimal is checked only where a section cites its results files: looked up in any file,
/// such a number would always be found (see the module's documentation).
#[test]
fn every_number_with_one_decimal_in_a_section_citing_results_is_in_the_files_it_cites() {
    assert_eq!(
        with_decimals("at 0.5 s, 12.25 and 1,347.5 (v0.3.6)", 1),
        ["0.5", "12.25", "1347.5"]
    );
    let (quoted, _, missing) = unfound(&one_decimals, true, &NOT_RESULTS_ONE_DECIMAL);
    assert!(
        quoted >= 50,
        "only {quoted} numbers read: the reader is broken"
    );
    assert!(
        missing.is_empty(),
        "numbers with one decimal in prose that no results file their section cites holds (a \
         setting goes in NOT_RESULTS_ONE_DECIMAL):\n{}",
        missing.join("\n")
    );
}

/// The whole numbers of `text` other than 0 that read as results: not
/// part of a decimal, a year, a range ("seeds 1000-1009"), a compound ("a 10,000-transition
/// buffer"), a setting ("B = 300"), a count ("15 of 30", checked on its own), an ordinal, a size,
/// an exponent's mantissa or power, a name ("AVX-512") or a reference ("figure 6", "eq. 4");
/// normalised (`-140`, `2833`).
fn nonzero_wholes(text: &str) -> Vec<String> {
    let body: String = text
        .lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| format!("{l}\n"))
        .collect();
    let chars: Vec<char> = body.chars().collect();
    let before = |s: usize, n: usize| chars[s.saturating_sub(n)..s].iter().collect::<String>();
    let after = |e: usize, n: usize| {
        chars[e..(e + n).min(chars.len())]
            .iter()
            .collect::<String>()
    };
    let mut out = Vec::new();
    for (s, e, v) in numbers_in(&chars) {
        let decimal = chars[s..e].contains(&'.');
        let year = (1990.0..=2030.0).contains(&v);
        let hyphen_after = after(e, 2).starts_with('-') && after(e, 2).len() == 2;
        let range_end =
            before(s, 2).ends_with('-') && before(s, 2).starts_with(|c: char| c.is_ascii_digit());
        let setting = before(s, 2) == "= ";
        let count = after(e, 4) == " of " || before(s, 4) == " of ";
        // "26th", "15×15", "1e-30", "AVX-512", "DeepSea(50)": an ordinal, a size, an exponent,
        // part of a name.
        let ordinal = ["th", "st", "nd", "rd"].contains(&after(e, 2).as_str());
        let size = after(e, 1) == "×" || before(s, 1) == "×";
        let lead = before(s, 2);
        let named = lead.starts_with(char::is_alphabetic) && (lead.ends_with(['-', '+', '(']));
        let exponent = after(e, 2).starts_with('e')
            && after(e, 2).ends_with(|c: char| c.is_ascii_digit() || "-+".contains(c));
        let word_before = before(s, 14).split_whitespace().last().map(|w| {
            w.trim_matches(|c: char| !c.is_alphanumeric())
                .to_lowercase()
        });
        let reference =
            before(s, 1) == " " && word_before.is_some_and(|w| REFERENCES.contains(&w.as_str()));
        let skipped = [
            hyphen_after,
            range_end,
            setting,
            count,
            ordinal,
            size,
            named,
            exponent,
            reference,
        ];
        if decimal || year || v == 0.0 || skipped.contains(&true) {
            continue;
        }
        out.push(format!("{}", v as i64));
    }
    out
}

/// The words before a number that make it a reference or a name, not a result ("figure 6",
/// "eq. 4", "exit code 2").
const REFERENCES: [&str; 12] = [
    "figure",
    "fig",
    "eq",
    "algorithm",
    "section",
    "sections",
    "table",
    "chapter",
    "line",
    "code",
    "exit",
    "exits",
];

/// Every number of `text` rounded to a whole one (half away from zero): each field between
/// commas, and each number as prose writes it ("2,048").
fn wholes_of(text: &str) -> HashSet<String> {
    let tokens = text.split(|c: char| !(c.is_ascii_digit() || ".eE+-".contains(c)));
    let chars: Vec<char> = text.chars().collect();
    let prose = numbers_in(&chars).into_iter().map(|(_, _, v)| v);
    tokens
        .filter_map(|t| t.parse::<f64>().ok())
        .chain(prose)
        .filter(|v| v.abs() < 1e15)
        .map(|v| format!("{}", v.round() as i64))
        .collect()
}

/// Settings and design counts quoted as whole numbers in sections that cite results files: the
/// document and the words around the number, as written (line breaks as spaces).
const NOT_RESULTS_WHOLE: [(&str, &str); 36] = [
    ("EXPERIMENTS.md", "for 600 episodes; the experts"),
    ("EXPERIMENTS.md", "2-step returns; 6 heads; the MSE"),
    ("docs/src/across-hosts.md", "has been silent for 5 s"),
    ("README.md", "expert, 50,000 environment steps"),
    ("README.md", "the full 1000 steps"),
    ("docs/src/install.md", "expert, 50,000 environment steps"),
    ("EXPERIMENTS.md", "spread over its 60,000 steps"),
    ("EXPERIMENTS.md", "Thresholds: −140 on MountainCar"),
    ("EXPERIMENTS.md", "−100 on Acrobot"),
    ("EXPERIMENTS.md", "episodes end after 500 steps"),
    ("EXPERIMENTS.md", "for the 1000 expert"),
    ("EXPERIMENTS.md", "the paper's 180"),
    ("EXPERIMENTS.md", "well before 20,000"),
    ("EXPERIMENTS.md", "its 3,360 runs (8 sweeps"),
    ("EXPERIMENTS.md", "(840 runs of about"),
    ("BENCHMARKS.md", "on 1,010, in process"),
    ("BENCHMARKS.md", "at a time up to 1,000,000"),
    ("BENCHMARKS.md", "about 16,600 steps with"),
    ("BENCHMARKS.md", "every 200 µs"),
    ("BENCHMARKS.md", "replay 10,000"),
    ("BENCHMARKS.md", "time constant 1,000 steps"),
    ("BENCHMARKS.md", "every 1,000 steps"),
    (
        "docs/src/troubleshooting.md",
        "up to 1,000,000 on 512 landmarks",
    ),
    ("EXPERIMENTS.md", "(bursts of 30)"),
    ("EXPERIMENTS.md", "bursts of 30 steps"),
    ("EXPERIMENTS.md", "scale 3, 10 and 30"),
    ("EXPERIMENTS.md", "weight of 2; 25% of every batch"),
    ("EXPERIMENTS.md", "B = 300; 25% of every batch"),
    ("BENCHMARKS.md", "lower priority (nice 10)"),
    ("BENCHMARKS.md", "copied every 50 updates"),
    ("docs/src/across-hosts.md", "(at most 16 actors"),
    ("docs/src/faults.md", "left 30 s after the end"),
    ("docs/src/faults.md", "at least 30 faults"),
    ("docs/src/faults.md", "handshake timeout and 10 s"),
    ("docs/src/faults.md", "for 90 s of a"),
    ("docs/src/faults.md", "a 96 MB tmpfs"),
];

#[test]
fn every_whole_number_in_a_section_citing_results_is_in_the_files_it_cites() {
    let sample = "at −140, 2,833 and 12 steps in 2026, seeds 1000-1009, a 10,000-step run, \
                  B = 300, 15 of 300 and 120.5, the 26th, 15×15, below 1e-30, AVX-512, \
                  DeepSea(50), figure 6, (eq. 4), exit code 2, 0 and 7";
    assert_eq!(nonzero_wholes(sample), ["-140", "2833", "12", "7"]);
    assert!(
        wholes_of("x,-140.4,2833\n").is_superset(&HashSet::from(["-140".into(), "2833".into()]))
    );
    let (quoted, _, missing) = unfound_in(&nonzero_wholes, &wholes_of, true, &NOT_RESULTS_WHOLE);
    assert!(
        quoted >= 100,
        "only {quoted} numbers read: the reader is broken"
    );
    assert!(
        missing.is_empty(),
        "whole numbers in prose that no results file their section cites holds \
         (a setting goes in NOT_RESULTS_WHOLE):\n{}",
        missing.join("\n")
    );
}

/// Settings, sizes, limits, versions and formulas quoted as whole numbers or with one decimal in
/// sections that cite no results file: the document and the words around the number, as
/// written.
const UNCITED_SETTINGS: [(&str, &str); 53] = [
    ("README.md", "Apache License 2.0"),
    (
        "docs/src/outputs.md",
        "waits up to 2 s for room when the launcher falls 8192 records behind",
    ),
    (
        "docs/src/experts.md",
        "within 200 ms (its process paused, say) is not synced again for 2 s",
    ),
    ("docs/src/experts.md", "300000, 5 minutes"),
    ("docs/src/experts.md", "b = (K q - 1) / (K - 1)"),
    ("docs/src/experts.md", "b = (K a - 1) / (K - 1)"),
    ("docs/src/experts.md", "grow as 1 / b²"),
    ("docs/src/experts.md", "a name never listed costs 1."),
    ("docs/src/faults.md", "(default 5)"),
    (
        "docs/src/experts.md",
        "whenever that changes and every 50 ms",
    ),
    ("docs/src/experts.md", "states of at most 53 values"),
    ("EXPERIMENTS.md", "margin 0.8)"),
    ("EXPERIMENTS.md", "KRR model of them (λ = 0.5)"),
    ("docs/src/configuration.md", "(sections 5.1.2, 5.3)"),
    ("docs/src/configuration.md", "with probability 0.5."),
    (
        "docs/src/experts.md",
        "0.5 before the expert's first rating",
    ),
    ("docs/src/outputs.md", "(every 0.5 s)"),
    ("EXPERIMENTS.md", "limit of 1,000 (figure 4"),
    ("EXPERIMENTS.md", "after 300 episodes, the mean"),
    ("EXPERIMENTS.md", "gradient norm ≤ 10, learning"),
    ("EXPERIMENTS.md", "starting at 1,000 steps"),
    ("EXPERIMENTS.md", "the last 1,000 divergences"),
    ("EXPERIMENTS.md", "the first 30,000 stored"),
    ("EXPERIMENTS.md", "clamped to [0, 200]"),
    ("EXPERIMENTS.md", "(50,000 steps, expert"),
    ("EXPERIMENTS.md", "(60,000 steps, the scripted"),
    ("EXPERIMENTS.md", "all three uses, 25% of every batch"),
    ("EXPERIMENTS.md", "all three uses, 10% of every batch"),
    ("EXPERIMENTS.md", "(100,000 steps, the scripted"),
    ("EXPERIMENTS.md", "from 1000 up (1000"),
    ("EXPERIMENTS.md", "(from reset seed 100)"),
    ("EXPERIMENTS.md", "δ = 10 or 30, each"),
    ("EXPERIMENTS.md", "far above 200"),
    ("BENCHMARKS.md", "one kind, 24 GiB"),
    ("docs/src/configuration.md", "γ = 0.99, 3000 episodes"),
    ("docs/src/configuration.md", "L_q = 1000, p_r = 99"),
    ("docs/src/experts.md", "at most 64 values"),
    ("docs/src/experts.md", "(mode 0600"),
    ("docs/src/experts.md", "is 128 random bits"),
    ("docs/src/experts.md", "gets 403"),
    ("docs/src/experts.md", "(default 300000"),
    ("docs/src/experts.md", "with a 95% interval"),
    ("docs/src/faults.md", "(every 100 ms"),
    ("docs/src/faults.md", "(default 10,000)"),
    ("docs/src/multi-process.md", "sends 2,500 values"),
    ("docs/src/multi-process.md", "or 32 with"),
    ("docs/src/multi-process.md", "every 200 µs"),
    ("docs/src/multi-process.md", "a 100 µs slice"),
    ("docs/src/outputs.md", "of the last 50 episodes"),
    ("docs/src/outputs.md", "of the last 100 episodes"),
    ("docs/src/outputs.md", "request gets 403"),
    ("docs/src/sweeps.md", "is a 95% percentile"),
    ("docs/src/sweeps.md", "(1000 [1000, 1000])"),
];

#[test]
fn a_section_citing_no_results_file_quotes_no_whole_number_nor_one_decimal_but_its_settings() {
    let sections = prose_sections();
    let stale: Vec<_> = UNCITED_SETTINGS
        .iter()
        .filter(|(doc, around)| {
            !sections.iter().any(|(name, cited, text)| {
                let words = words(text);
                name == doc && cited.is_empty() && words.contains(around)
            })
        })
        .collect();
    assert!(
        stale.is_empty(),
        "UNCITED_SETTINGS entries in no section that cites nothing: {stale:?}"
    );
    let mut missing = Vec::new();
    for (name, cited, text) in sections {
        let heading = text.lines().find(|l| !l.is_empty()).unwrap_or_default();
        // A table of contents repeats the headings, which are not prose.
        if !cited.is_empty() || heading.trim_start_matches('#').trim() == "Contents" {
            continue;
        }
        let words = words(&text);
        for number in nonzero_wholes(&text).into_iter().chain(one_decimals(&text)) {
            if !listed(&UNCITED_SETTINGS, &name, &words, &number) {
                missing.push(format!("{name} ({heading}): {number}"));
            }
        }
    }
    assert!(
        missing.is_empty(),
        "whole numbers and numbers with one decimal in sections that cite no \
         results file (a result: cite the file it comes from; a setting: UNCITED_SETTINGS):\n{}",
        missing.join("\n")
    );
}
