//! The configuration reference: every key of an experiment config, its type, default and
//! meaning, made from the config types themselves (their doc comments and serde defaults, read
//! through their JSON schema), so that the documented keys cannot drift from the code.

use std::fmt::Write as _;

use serde_json::{Map, Value};

use super::ExperimentConfig;

/// The reference as Markdown: one table of the top-level keys, then one per section.
pub fn markdown() -> String {
    let schema = serde_json::to_value(schemars::schema_for!(ExperimentConfig))
        .expect("a JSON schema always serialises");
    let defs = schema.get("$defs").and_then(Value::as_object).cloned();
    let defs = defs.unwrap_or_default();
    let props = properties(&schema);
    let mut top = Vec::new();
    let mut sections = Vec::new();
    for (key, prop) in &props {
        let target = resolve(prop, &defs);
        if target.get("properties").is_some() {
            sections.push((key.clone(), prop.clone(), target.clone()));
        } else {
            top.push(row(key, prop, required(&schema, key), &defs));
        }
    }
    let mut md = String::new();
    table(&mut md, "top level", None, &top);
    for (name, prop, target) in sections {
        let rows: Vec<String> = properties(&target)
            .iter()
            .map(|(k, p)| row(&format!("{name}.{k}"), p, required(&target, k), &defs))
            .collect();
        let about = description(&prop).or_else(|| description(&target));
        table(&mut md, &format!("[{name}]"), about.as_deref(), &rows);
    }
    md
}

fn table(md: &mut String, title: &str, about: Option<&str>, rows: &[String]) {
    let _ = writeln!(
        md,
        "**{title}**{}\n",
        about.map(|a| format!(": {a}")).unwrap_or_default()
    );
    let _ = writeln!(md, "| key | type | default | meaning |\n|---|---|---|---|");
    for r in rows {
        let _ = writeln!(md, "{r}");
    }
    md.push('\n');
}

fn properties(v: &Value) -> Vec<(String, Value)> {
    v.get("properties")
        .and_then(Value::as_object)
        .map(|m| m.iter().map(|(k, v)| (k.clone(), v.clone())).collect())
        .unwrap_or_default()
}

/// The schema a `$ref` points to (or the value itself).
fn resolve<'a>(v: &'a Value, defs: &'a Map<String, Value>) -> &'a Value {
    v.get("$ref")
        .and_then(Value::as_str)
        .and_then(|r| r.strip_prefix("#/$defs/"))
        .and_then(|name| defs.get(name))
        .unwrap_or(v)
}

fn required(object: &Value, key: &str) -> bool {
    object
        .get("required")
        .and_then(Value::as_array)
        .is_some_and(|r| r.iter().any(|k| k == key))
}

fn row(key: &str, prop: &Value, required: bool, defs: &Map<String, Value>) -> String {
    let (ty, variants) = type_of(prop, defs);
    let default = match prop.get("default") {
        Some(Value::Null) => "absent".to_owned(),
        Some(d) => format!("`{}`", toml_literal(d)),
        None if required => "required".to_owned(),
        // A default the written config leaves out: the type's zero.
        None if ty.ends_with("or absent") => "absent".to_owned(),
        None if ty.starts_with("integer") => "`0`".to_owned(),
        None if ty == "number" => "`0.0`".to_owned(),
        None if ty == "boolean" => "`false`".to_owned(),
        None => "—".to_owned(),
    };
    let mut meaning = description(prop).unwrap_or_default();
    if !variants.is_empty() {
        if !meaning.is_empty() {
            meaning.push(' ');
        }
        meaning.push_str(&variants.join(" "));
    }
    format!(
        "| `{key}` | {ty} | {default} | {} |",
        meaning.replace('|', "\\|")
    )
}

/// The type's name, and the documented values of an enumeration (`` `name`: meaning ``).
fn type_of(prop: &Value, defs: &Map<String, Value>) -> (String, Vec<String>) {
    if let Some(any) = prop.get("anyOf").and_then(Value::as_array) {
        let inner: Vec<&Value> = any
            .iter()
            .filter(|v| v.get("type") != Some(&"null".into()))
            .collect();
        if let [one] = inner[..] {
            let (t, variants) = type_of(one, defs);
            return (format!("{t} or absent"), variants);
        }
    }
    let target = resolve(prop, defs);
    if let Some(values) = enum_values(target) {
        let names: Vec<String> = values.iter().map(|(n, _)| format!("`{n}`")).collect();
        let variants = values
            .into_iter()
            .filter_map(|(n, d)| d.map(|d| format!("`{n}`: {d}")))
            .collect();
        return (format!("one of {}", names.join(", ")), variants);
    }
    let ty = match target.get("type") {
        Some(Value::String(t)) => simple(t, target, defs),
        Some(Value::Array(ts)) => {
            let t: Vec<&str> = ts
                .iter()
                .filter_map(Value::as_str)
                .filter(|t| *t != "null")
                .collect();
            let name = t
                .first()
                .map_or("any".to_owned(), |t| simple(t, target, defs));
            if ts.iter().any(|t| t == "null") {
                format!("{name} or absent")
            } else {
                name
            }
        }
        _ => "any".to_owned(),
    };
    (ty, Vec::new())
}

fn simple(t: &str, target: &Value, defs: &Map<String, Value>) -> String {
    match t {
        "integer" => match target.get("minimum").and_then(Value::as_f64) {
            Some(m) if m >= 0.0 => "integer ≥ 0".to_owned(),
            _ => "integer".to_owned(),
        },
        "number" => "number".to_owned(),
        "array" => {
            let n = target
                .get("minItems")
                .filter(|&m| Some(m) == target.get("maxItems"));
            if let (Some(n), Some(item)) = (n.and_then(Value::as_u64), target.get("items")) {
                let t = type_of(item, defs).0;
                return format!("[{}]", vec![t; n as usize].join(", "));
            }
            let items = target
                .get("prefixItems")
                .or_else(|| target.get("items"))
                .map(|i| match i {
                    Value::Array(a) => a
                        .iter()
                        .map(|v| type_of(v, defs).0)
                        .collect::<Vec<_>>()
                        .join(", "),
                    v => type_of(v, defs).0,
                })
                .unwrap_or_default();
            format!("[{items}]")
        }
        "object" => "table".to_owned(),
        other => other.to_owned(),
    }
}

/// The values of an enumeration of strings, with their doc comments.
fn enum_values(v: &Value) -> Option<Vec<(String, Option<String>)>> {
    if let Some(values) = v.get("enum").and_then(Value::as_array) {
        return Some(
            values
                .iter()
                .filter_map(Value::as_str)
                .map(|s| (s.to_owned(), None))
                .collect(),
        );
    }
    let one_of = v.get("oneOf").and_then(Value::as_array)?;
    let mut out = Vec::new();
    for variant in one_of {
        let d = description(variant);
        if let Some(c) = variant.get("const").and_then(Value::as_str) {
            out.push((c.to_owned(), d));
        } else if let Some(vs) = variant.get("enum").and_then(Value::as_array) {
            for s in vs.iter().filter_map(Value::as_str) {
                out.push((s.to_owned(), d.clone()));
            }
        } else {
            return None;
        }
    }
    Some(out)
}

/// A doc comment as one line, rustdoc links made plain code.
fn description(v: &Value) -> Option<String> {
    let d = v.get("description")?.as_str()?;
    let line = d.split_whitespace().collect::<Vec<_>>().join(" ");
    let mut out = String::with_capacity(line.len());
    let mut rest = line.as_str();
    // "[`name`]" and "[`name`](...)" become "`name`", with any path before the last `::` dropped.
    while let Some(i) = rest.find("[`") {
        out.push_str(&rest[..i]);
        let after = &rest[i + 1..];
        match after.find("`]") {
            Some(j) => {
                let code = &after[1..j];
                let code = code.rsplit("::").next().unwrap_or(code);
                let _ = write!(out, "`{code}`");
                rest = &after[j + 2..];
            }
            None => {
                out.push_str("[`");
                rest = after.get(1..).unwrap_or("");
            }
        }
    }
    out.push_str(rest);
    for (name, value) in [
        (
            "MAX_REPLAY_CAPACITY",
            super::MAX_REPLAY_CAPACITY.to_string(),
        ),
        ("MAX_BATCH_SIZE", super::MAX_BATCH_SIZE.to_string()),
        ("MAX_HIDDEN", super::MAX_HIDDEN.to_string()),
        ("MAX_QUEUE_LEN", super::MAX_QUEUE_LEN.to_string()),
        ("MAX_N_STEP", super::MAX_N_STEP.to_string()),
    ] {
        out = out.replace(&format!("`{name}`"), &value);
    }
    Some(out)
}

/// A default as TOML writes it.
fn toml_literal(v: &Value) -> String {
    match v {
        Value::String(s) => format!("\"{s}\""),
        Value::Array(a) => format!(
            "[{}]",
            a.iter().map(toml_literal).collect::<Vec<_>>().join(", ")
        ),
        Value::Number(n) => match n.as_f64() {
            Some(f) if n.is_f64() && f.fract() == 0.0 && f.abs() < 1e15 => format!("{f:.1}"),
            _ => n.to_string(),
        },
        other => other.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_key_of_a_written_config_is_in_the_reference_with_its_default() {
        let md = markdown();
        for key in [
            "`seed`",
            "`agent.prior_scale`",
            "`query.rule`",
            "`query.gap`",
            "`shaping.kind`",
            "`evaluation.every`",
            "`env.kwargs`",
        ] {
            assert!(md.contains(key), "{key} missing from\n{md}");
        }
        let row = |key: &str| {
            md.lines()
                .find(|l| l.starts_with(&format!("| `{key}` |")))
                .unwrap_or_else(|| panic!("no row {key}"))
                .to_owned()
        };
        for (key, part) in [
            ("query.percentile", "| `99.0` |"),
            ("query.rule", "`js-paced`"),
            ("query.rule", "`never`: Never: pure RL."),
            ("budget.total", "| `100` |"),
            ("agent.kind", "| required |"),
            ("agent.prior_seed", "| absent |"),
            ("agent.n_step", "| `1` |"),
            ("agent.prior_scale", "| `0.0` |"),
            ("agent.target_bounds", "[number, number] or absent"),
            ("agent.hidden", "1 to 1024"),
        ] {
            assert!(row(key).contains(part), "{key}: {}", row(key));
        }
        assert!(!md.contains("schedule_steps"), "a key TOML never holds");
        // Every key a shipped preset sets is documented.
        let preset: toml::Table =
            include_str!("../../../../deploy/configs/recommended/cartpole.toml")
                .parse()
                .unwrap();
        for (k, v) in &preset {
            match v {
                toml::Value::Table(t) => {
                    for sub in t.keys() {
                        row(&format!("{k}.{sub}"));
                    }
                }
                _ => {
                    row(k);
                }
            }
        }
    }
}
