//! `docs/reference/config.md`: every section and key of the configuration,
//! from its schema (the doc comments of `crossroads_config`) and the
//! built-in defaults.

use std::fmt::Write as _;

use anyhow::Context;
use crossroads_config::{Config, ENV_PREFIX};
use serde_json::{Map, Value};

/// The configuration reference as Markdown.
pub fn reference() -> anyhow::Result<String> {
    let schema = crossroads_config::schema();
    let root = schema.as_value();
    let defs = root
        .get("$defs")
        .and_then(Value::as_object)
        .context("the schema has no $defs")?;
    let defaults = toml::Value::try_from(Config::default()).context("the defaults as TOML")?;
    let mut w = String::new();
    w.push_str(
        "# Configuration reference\n\n\
         Generated from the code by `crossroads docs`; do not edit (a test fails when \
         this page differs from what the code generates). How the layers combine \
         (defaults, a built-in experiment, the file, `CROSSROADS_*` variables, `--set`) \
         is in [the configuration guide](../configuration.md); `crossroads config show` \
         prints the effective values of a run.\n\n\
         The defaults below are the built-in ones: a built-in experiment \
         (`configs/experiments/`, which `crossroads train` starts from) overrides some \
         of them. Every key can also be set as an environment variable, \
         `CROSSROADS_<SECTION>__<KEY>` (double underscore between the parts).\n",
    );
    let sections = properties(root);
    for (name, prop) in &sections {
        section(&mut w, name, prop, defs, defaults.get(name.as_str()))?;
    }
    Ok(w)
}

fn section(
    w: &mut String,
    name: &str,
    prop: &Value,
    defs: &Map<String, Value>,
    defaults: Option<&toml::Value>,
) -> anyhow::Result<()> {
    let def = resolve(prop, defs).with_context(|| format!("section {name}"))?;
    let _ = writeln!(w, "\n## `[{name}]`\n");
    let about = description(prop).or_else(|| description(def));
    if let Some(about) = about {
        let _ = writeln!(w, "{about}\n");
    }
    w.push_str("| key | type | default | meaning |\n| --- | --- | --- | --- |\n");
    let mut nested = Vec::new();
    for (key, p) in properties(def) {
        let target = resolve(p, defs).unwrap_or(p);
        if target.get("properties").is_some() {
            nested.push((
                format!("{name}.{key}"),
                p,
                defaults.and_then(|d| d.get(&key)),
            ));
            continue;
        }
        let env = format!(
            "{ENV_PREFIX}{}__{}",
            name.replace('.', "__").to_uppercase(),
            key.to_uppercase()
        );
        let default = defaults
            .and_then(|d| d.get(&key))
            .map_or_else(|| "unset".to_owned(), |v| format!("`{}`", inline(v)));
        let mut meaning = description(p).unwrap_or_default();
        if let Some(values) = choices(p, defs, &meaning) {
            let _ = write!(meaning, " One of: {values}.");
        }
        let _ = writeln!(
            w,
            "| `{key}` | {} | {default} | {} (`{env}`) |",
            type_name(p, defs),
            cell(meaning.trim())
        );
    }
    for (name, p, d) in nested {
        section(w, &name, p, defs, d)?;
    }
    Ok(())
}

/// An object schema's properties, in order (the schema's maps are sorted
/// by key).
fn properties(schema: &Value) -> Vec<(String, &Value)> {
    schema
        .get("properties")
        .and_then(Value::as_object)
        .map(|m| m.iter().map(|(k, v)| (k.clone(), v)).collect())
        .unwrap_or_default()
}

/// Follows `$ref` (directly, or inside `allOf`/`anyOf` beside `null`).
fn resolve<'a>(schema: &'a Value, defs: &'a Map<String, Value>) -> Option<&'a Value> {
    if let Some(r) = schema.get("$ref").and_then(Value::as_str) {
        return defs.get(r.rsplit('/').next()?);
    }
    for key in ["allOf", "anyOf", "oneOf"] {
        if let Some(list) = schema.get(key).and_then(Value::as_array) {
            for s in list {
                if s.get("$ref").is_some() {
                    return resolve(s, defs);
                }
            }
        }
    }
    Some(schema)
}

fn description(schema: &Value) -> Option<String> {
    schema
        .get("description")
        .and_then(Value::as_str)
        .map(|d| d.split_whitespace().collect::<Vec<_>>().join(" "))
}

/// The type of a key in words: integer, number, string, boolean, a list,
/// optional where null is allowed.
fn type_name(schema: &Value, defs: &Map<String, Value>) -> String {
    let target = resolve(schema, defs).unwrap_or(schema);
    let mut optional = false;
    let mut names = Vec::new();
    let mut push = |t: &str, names: &mut Vec<String>| match t {
        "null" => optional = true,
        "array" => names.push("list".to_owned()),
        other => names.push(other.to_owned()),
    };
    match target.get("type") {
        Some(Value::String(t)) => push(t, &mut names),
        Some(Value::Array(ts)) => {
            for t in ts.iter().filter_map(Value::as_str) {
                push(t, &mut names);
            }
        }
        _ => {
            if target.get("oneOf").or(target.get("enum")).is_some() {
                names.push("string".to_owned());
            }
        }
    }
    for key in ["anyOf", "oneOf"] {
        if let Some(list) = schema.get(key).and_then(Value::as_array)
            && list
                .iter()
                .any(|s| s.get("type") == Some(&Value::from("null")))
        {
            optional = true;
        }
    }
    if names == ["list"]
        && let Some(items) = target.get("items")
    {
        names = vec![format!("list of {}", type_name(items, defs))];
    }
    let name = if names.is_empty() {
        "value".to_owned()
    } else {
        names.join(" or ")
    };
    if optional {
        format!("{name}, optional")
    } else {
        name
    }
}

/// The allowed values of an enumeration, with their meaning where the
/// variant has a doc comment; none where the key's own `meaning` already
/// names each of them.
fn choices(schema: &Value, defs: &Map<String, Value>, meaning: &str) -> Option<String> {
    let target = resolve(schema, defs)?;
    if let Some(values) = target.get("enum").and_then(Value::as_array) {
        let names: Vec<String> = values
            .iter()
            .filter_map(Value::as_str)
            .map(|v| format!("`{v}`"))
            .collect();
        return (!names.is_empty()).then(|| names.join(", "));
    }
    let variants = target.get("oneOf").and_then(Value::as_array)?;
    let named = |v: &Value| {
        v.get("const")
            .and_then(Value::as_str)
            .is_some_and(|name| meaning.contains(&format!("`{name}`")))
    };
    if variants.iter().all(named) {
        return None;
    }
    let names: Vec<String> = variants
        .iter()
        .filter_map(|v| {
            let name = v
                .get("const")
                .or_else(|| v.get("enum").and_then(|e| e.get(0)))
                .and_then(Value::as_str)?;
            Some(match description(v) {
                Some(d) => format!("`{name}` ({})", d.trim_end_matches('.')),
                None => format!("`{name}`"),
            })
        })
        .collect();
    (!names.is_empty()).then(|| names.join(", "))
}

/// A TOML value on one line.
fn inline(v: &toml::Value) -> String {
    match v {
        toml::Value::String(s) => format!("{s:?}"),
        other => other.to_string(),
    }
}

/// Text safe inside a Markdown table cell.
fn cell(text: &str) -> String {
    text.replace('|', "\\|")
}
