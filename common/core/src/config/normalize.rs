//! What the raw TOML table is given before it is read as a config: older names, defaults that
//! depend on other keys.

use super::{invalid, Result};

/// An `expert.name` not given becomes the environment's reference expert, so that a config that
/// asks for no demonstrations (B = 0, rule `never`) need not name one.
pub(super) fn default_expert_of_env(table: &mut toml::Table) {
    let env = table
        .get("env")
        .and_then(|e| e.get("name"))
        .and_then(toml::Value::as_str);
    let name = match env {
        Some("cliffwalk") => "cliffwalk-optimal",
        Some("mountaincar") => "mountaincar-energy",
        Some("acrobot") => "acrobot-energy",
        Some("deepsea") => "deepsea-optimal",
        _ => return,
    };
    let expert = table
        .entry("expert")
        .or_insert_with(|| toml::Value::Table(toml::Table::new()));
    if let toml::Value::Table(expert) = expert {
        expert
            .entry("name")
            .or_insert_with(|| toml::Value::String(name.to_owned()));
    }
}

/// `query.mode`, the older name of `query.rule`, read as `query.rule` (both at once are refused).
pub(super) fn rename_query_mode(table: &mut toml::Table) -> Result<()> {
    let Some(toml::Value::Table(query)) = table.get_mut("query") else {
        return Ok(());
    };
    if let Some(mode) = query.remove("mode") {
        if query.contains_key("rule") {
            return Err(invalid(
                "query.mode",
                "is the older name of `query.rule`: give one of them",
            ));
        }
        query.insert("rule".to_owned(), mode);
    }
    Ok(())
}
