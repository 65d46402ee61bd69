//! The rig document's JSON Schema (`api/rig.schema.json`), generated from the very types that
//! parse it, so the two cannot drift: a test compares the published file with [`text`]. Parse
//! errors take the schema's description of the field they name ([`describe`]), so a mistyped
//! field says what belongs there. Editors and other tools validate rig files with the file; the
//! checks the schema cannot say (ids unique, vectors not parallel, limits against each other)
//! stay with [`super::Rig::from_doc`], which names the field the same way.

use super::RigDoc;
use serde_json::Value;

/// The schema as JSON.
pub fn schema() -> Value {
    let mut s = serde_json::to_value(schemars::schema_for!(RigDoc)).expect("schemas serialise");
    s["title"] = "omniwarp rig document, format 1".into();
    tidy(&mut s);
    s
}

/// The schema as `api/rig.schema.json` holds it: pretty-printed, ending in a newline.
pub fn text() -> String {
    serde_json::to_string_pretty(&schema()).expect("schemas serialise") + "\n"
}

/// Descriptions come from the code's doc comments: their rustdoc links are plain code here and
/// their lines one line.
fn tidy(v: &mut Value) {
    match v {
        Value::Object(map) => {
            for (k, child) in map.iter_mut() {
                match child {
                    Value::String(text) if k == "description" => {
                        // Lines wrapped for the source joined; paragraphs kept.
                        *text = text
                            .replace("[`", "`")
                            .replace("`]", "`")
                            .replace("\n\n", "\u{0}")
                            .replace('\n', " ")
                            .replace('\u{0}', "\n\n");
                    }
                    _ => tidy(child),
                }
            }
        }
        Value::Array(items) => items.iter_mut().for_each(tidy),
        _ => {}
    }
}

/// The schema's description of the field at JSON `pointer` (`/channels/1/lens/model`) in the
/// document `doc` (which alternative a tagged part is, e.g. the screen's `kind`, is read from
/// it), when the schema has one: the field's own, else its type's.
pub fn describe(pointer: &str, doc: &Value) -> Option<String> {
    let root = schema();
    let (mut at, mut here) = (&root, Some(doc));
    for part in pointer.split('/').filter(|p| !p.is_empty()) {
        at = step(&root, at, part, here)?;
        here = here.and_then(|v| match v {
            Value::Array(items) => part.parse::<usize>().ok().and_then(|k| items.get(k)),
            _ => v.get(part),
        });
    }
    description(&root, at)
}

/// The definition a `$ref` names, or `node` itself.
fn resolve<'a>(root: &'a Value, node: &'a Value) -> &'a Value {
    match node.get("$ref").and_then(Value::as_str) {
        Some(r) => r
            .strip_prefix("#/$defs/")
            .and_then(|name| root["$defs"].get(name))
            .unwrap_or(node),
        None => node,
    }
}

/// The schema of `part` inside `node`: a property, an array's item, or either in one of the
/// alternatives (`anyOf`, `oneOf`: a nullable field, a tagged screen), the one whose `kind`
/// the document `here` has first.
fn step<'a>(
    root: &'a Value,
    node: &'a Value,
    part: &str,
    here: Option<&Value>,
) -> Option<&'a Value> {
    let node = resolve(root, node);
    if let Some(p) = node.get("properties").and_then(|p| p.get(part)) {
        return Some(p);
    }
    if let Ok(k) = part.parse::<usize>() {
        if let Some(item) = node.get("prefixItems").and_then(|i| i.get(k)) {
            return Some(item);
        }
        if let Some(item) = node.get("items").filter(|i| i.is_object()) {
            return Some(item);
        }
    }
    let kind = here.and_then(|v| v.get("kind"));
    let mut alternatives: Vec<&Value> = ["anyOf", "oneOf"]
        .iter()
        .filter_map(|k| node.get(*k).and_then(Value::as_array))
        .flatten()
        .collect();
    // The alternative the document's tag names first.
    alternatives.sort_by_key(|alt| {
        let tag = resolve(root, alt).pointer("/properties/kind/const");
        !(kind.is_some() && tag == kind)
    });
    alternatives
        .into_iter()
        .find_map(|alt| step(root, alt, part, here))
}

fn description(root: &Value, node: &Value) -> Option<String> {
    node.get("description")
        .or_else(|| resolve(root, node).get("description"))
        .and_then(Value::as_str)
        .map(str::to_string)
}
