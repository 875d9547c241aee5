//! Checks of the glTF JSON that must hold before the `gltf` crate sees it.
//!
//! **Shapes.** serde accepts a JSON array where a struct is expected (as a sequence of its
//! fields), so `"materials": [[]]` parses, and the writer, which edits the JSON in place, would
//! then find an array where it adds `extensions`. So every element of the top-level arrays,
//! every primitive, and every member that the specification defines as an object
//! (`extensions`, `pbrMetallicRoughness`, texture infos, `attributes`, ...) must be an object.
//!
//! **Indices.**
//! `gltf-json` (1.4) indexes `accessors` with a primitive's `POSITION` value while validating,
//! without a bounds check, and our writer edits the JSON by the indices it finds there; both
//! panic on an index past the end of its array. So every index field of the core specification
//! (and of `KHR_lights_punctual`) is checked here first: an unsigned integer, at most
//! `u32::MAX`, and less than the length of the array it points into. Each error names the item
//! (`meshes[0].primitives[1].attributes.POSITION`) and the array.

use serde_json::Value;

/// A problem found: the item's JSON path, and what is wrong with it.
#[derive(Debug)]
pub(crate) struct Invalid {
    pub(crate) item: String,
    pub(crate) reason: String,
}

/// Top-level arrays whose elements are objects.
const OBJECT_ARRAYS: [&str; 13] = [
    "accessors",
    "animations",
    "buffers",
    "bufferViews",
    "cameras",
    "images",
    "materials",
    "meshes",
    "nodes",
    "samplers",
    "scenes",
    "skins",
    "textures",
];

/// Members that are objects wherever they appear.
const OBJECT_MEMBERS: [&str; 13] = [
    "asset",
    "extensions",
    "pbrMetallicRoughness",
    "baseColorTexture",
    "metallicRoughnessTexture",
    "normalTexture",
    "occlusionTexture",
    "emissiveTexture",
    "attributes",
    "sparse",
    "perspective",
    "orthographic",
    "KHR_lights_punctual",
];

/// Checks the shapes, then every index of `root` against the array it points into.
pub(super) fn check(root: &Value) -> Result<(), Invalid> {
    shapes(root, &mut String::new())?;
    for key in OBJECT_ARRAYS {
        for (i, v) in items(root, key) {
            if !v.is_object() {
                return Err(not_object(&format!("{key}[{i}]"), v));
            }
        }
    }
    for (i, mesh) in items(root, "meshes") {
        for (p, prim) in items(mesh, "primitives") {
            if !prim.is_object() {
                return Err(not_object(&format!("meshes[{i}].primitives[{p}]"), prim));
            }
        }
    }
    indices(root)
}

fn not_object(item: &str, v: &Value) -> Invalid {
    let found = match v {
        Value::Array(_) => "an array",
        Value::String(_) => "a string",
        Value::Number(_) => "a number",
        Value::Bool(_) => "a boolean",
        Value::Null => "null",
        Value::Object(_) => "an object",
    };
    Invalid {
        item: item.to_string(),
        reason: format!("must be a JSON object, found {found}"),
    }
}

/// [`OBJECT_MEMBERS`] anywhere in the tree; `at` is the path so far.
fn shapes(v: &Value, at: &mut String) -> Result<(), Invalid> {
    let len = at.len();
    match v {
        Value::Object(m) => {
            for (k, x) in m {
                at.push_str(if at.is_empty() { "" } else { "." });
                at.push_str(k);
                if OBJECT_MEMBERS.contains(&k.as_str()) && !x.is_object() {
                    return Err(not_object(at, x));
                }
                shapes(x, at)?;
                at.truncate(len);
            }
        }
        Value::Array(a) => {
            for (i, x) in a.iter().enumerate() {
                at.push_str(&format!("[{i}]"));
                shapes(x, at)?;
                at.truncate(len);
            }
        }
        _ => {}
    }
    Ok(())
}

/// Checks every index of `root` against the array it points into.
fn indices(root: &Value) -> Result<(), Invalid> {
    let len = |key: &str| root.get(key).and_then(Value::as_array).map_or(0, Vec::len);
    let lights = root
        .pointer("/extensions/KHR_lights_punctual/lights")
        .and_then(Value::as_array)
        .map_or(0, Vec::len);
    let mut c = Checker { errors: None };

    c.index(root.get("scene"), "scene", "scenes", len("scenes"));
    for (i, scene) in items(root, "scenes") {
        for (k, n) in items(scene, "nodes") {
            c.index(
                Some(n),
                &format!("scenes[{i}].nodes[{k}]"),
                "nodes",
                len("nodes"),
            );
        }
    }
    for (i, node) in items(root, "nodes") {
        let at = format!("nodes[{i}]");
        for (k, n) in items(node, "children") {
            c.index(
                Some(n),
                &format!("{at}.children[{k}]"),
                "nodes",
                len("nodes"),
            );
        }
        c.index(
            node.get("mesh"),
            &format!("{at}.mesh"),
            "meshes",
            len("meshes"),
        );
        c.index(
            node.get("skin"),
            &format!("{at}.skin"),
            "skins",
            len("skins"),
        );
        c.index(
            node.get("camera"),
            &format!("{at}.camera"),
            "cameras",
            len("cameras"),
        );
        c.index(
            node.pointer("/extensions/KHR_lights_punctual/light"),
            &format!("{at}.extensions.KHR_lights_punctual.light"),
            "KHR_lights_punctual lights",
            lights,
        );
    }
    for (i, mesh) in items(root, "meshes") {
        for (p, prim) in items(mesh, "primitives") {
            let at = format!("meshes[{i}].primitives[{p}]");
            if let Some(attrs) = prim.get("attributes").and_then(Value::as_object) {
                for (name, a) in attrs {
                    let item = format!("{at}.attributes.{name}");
                    c.index(Some(a), &item, "accessors", len("accessors"));
                }
            }
            c.index(
                prim.get("indices"),
                &format!("{at}.indices"),
                "accessors",
                len("accessors"),
            );
            let item = format!("{at}.material");
            c.index(prim.get("material"), &item, "materials", len("materials"));
            for (t, target) in items(prim, "targets") {
                if let Some(attrs) = target.as_object() {
                    for (name, a) in attrs {
                        let item = format!("{at}.targets[{t}].{name}");
                        c.index(Some(a), &item, "accessors", len("accessors"));
                    }
                }
            }
        }
    }
    for (i, acc) in items(root, "accessors") {
        let at = format!("accessors[{i}]");
        let views = len("bufferViews");
        c.index(
            acc.get("bufferView"),
            &format!("{at}.bufferView"),
            "bufferViews",
            views,
        );
        for part in ["indices", "values"] {
            c.index(
                acc.pointer(&format!("/sparse/{part}/bufferView")),
                &format!("{at}.sparse.{part}.bufferView"),
                "bufferViews",
                views,
            );
        }
    }
    for (i, view) in items(root, "bufferViews") {
        let item = format!("bufferViews[{i}].buffer");
        c.index(view.get("buffer"), &item, "buffers", len("buffers"));
    }
    for (i, image) in items(root, "images") {
        let item = format!("images[{i}].bufferView");
        let views = len("bufferViews");
        c.index(image.get("bufferView"), &item, "bufferViews", views);
        // glTF requires it with a bufferView; the gltf crate unwraps it.
        let typed = image.get("mimeType").is_some_and(Value::is_string);
        if image.get("bufferView").is_some() && !typed {
            c.fail(
                &format!("images[{i}]"),
                "has a bufferView but no mimeType".into(),
            );
        }
    }
    for (i, tex) in items(root, "textures") {
        let at = format!("textures[{i}]");
        c.index(
            tex.get("sampler"),
            &format!("{at}.sampler"),
            "samplers",
            len("samplers"),
        );
        c.index(
            tex.get("source"),
            &format!("{at}.source"),
            "images",
            len("images"),
        );
    }
    for (i, mat) in items(root, "materials") {
        for path in [
            "/pbrMetallicRoughness/baseColorTexture",
            "/pbrMetallicRoughness/metallicRoughnessTexture",
            "/normalTexture",
            "/occlusionTexture",
            "/emissiveTexture",
        ] {
            if let Some(info) = mat.pointer(path) {
                let at = format!("materials[{i}]{}", path.replace('/', "."));
                c.index(
                    info.get("index"),
                    &format!("{at}.index"),
                    "textures",
                    len("textures"),
                );
                // A texture coordinate set: any u32 parses, but the writer renumbers sets.
                c.index(
                    info.get("texCoord"),
                    &format!("{at}.texCoord"),
                    "TEXCOORD sets",
                    64,
                );
            }
        }
    }
    for (i, skin) in items(root, "skins") {
        let at = format!("skins[{i}]");
        let item = format!("{at}.inverseBindMatrices");
        c.index(
            skin.get("inverseBindMatrices"),
            &item,
            "accessors",
            len("accessors"),
        );
        c.index(
            skin.get("skeleton"),
            &format!("{at}.skeleton"),
            "nodes",
            len("nodes"),
        );
        for (k, j) in items(skin, "joints") {
            c.index(Some(j), &format!("{at}.joints[{k}]"), "nodes", len("nodes"));
        }
    }
    for (i, anim) in items(root, "animations") {
        let at = format!("animations[{i}]");
        let samplers = anim
            .get("samplers")
            .and_then(Value::as_array)
            .map_or(0, Vec::len);
        for (k, ch) in items(anim, "channels") {
            let item = format!("{at}.channels[{k}].sampler");
            c.index(ch.get("sampler"), &item, "animation samplers", samplers);
            let item = format!("{at}.channels[{k}].target.node");
            c.index(ch.pointer("/target/node"), &item, "nodes", len("nodes"));
        }
        for (k, s) in items(anim, "samplers") {
            for key in ["input", "output"] {
                let item = format!("{at}.samplers[{k}].{key}");
                c.index(s.get(key), &item, "accessors", len("accessors"));
            }
        }
    }
    match c.errors {
        Some(e) => Err(e),
        None => Ok(()),
    }
}

/// The elements of `value[key]` with their positions (none when it is not an array).
fn items<'a>(value: &'a Value, key: &str) -> impl Iterator<Item = (usize, &'a Value)> {
    value
        .get(key)
        .and_then(Value::as_array)
        .into_iter()
        .flatten()
        .enumerate()
}

/// Keeps the first problem found.
struct Checker {
    errors: Option<Invalid>,
}

impl Checker {
    /// Records a problem unless one is already recorded.
    fn fail(&mut self, item: &str, reason: String) {
        if self.errors.is_none() {
            self.errors = Some(Invalid {
                item: item.to_string(),
                reason,
            });
        }
    }

    /// `value`, if present, must index an array of `len` elements (`what` names it).
    fn index(&mut self, value: Option<&Value>, item: &str, what: &str, len: usize) {
        let Some(v) = value else { return };
        if self.errors.is_some() {
            return;
        }
        let reason = match v.as_u64() {
            Some(i) if i > u64::from(u32::MAX) => format!("index {i} is larger than 2^32 - 1"),
            Some(i) if i as usize >= len => {
                format!("index {i} is out of range ({len} {what})")
            }
            Some(_) => return,
            None => format!("{v} is not an index (a non-negative integer)"),
        };
        self.fail(item, reason);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn check(v: Value) -> Option<String> {
        super::check(&v)
            .err()
            .map(|e| format!("{}: {}", e.item, e.reason))
    }

    #[test]
    fn every_index_is_checked_against_its_array() {
        let ok = json!({
            "scene": 0, "scenes": [{"nodes": [0]}],
            "nodes": [{"mesh": 0}],
            "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "material": 0}]}],
            "materials": [{}], "accessors": [{"bufferView": 0}],
            "bufferViews": [{"buffer": 0}], "buffers": [{}]
        });
        assert_eq!(check(ok.clone()), None);
        let mut v = ok.clone();
        v["meshes"][0]["primitives"][0]["attributes"]["POSITION"] = json!(99);
        assert_eq!(
            check(v).as_deref(),
            Some(
                "meshes[0].primitives[0].attributes.POSITION: index 99 is out of range (1 accessors)"
            )
        );
        let mut v = ok.clone();
        v.as_object_mut().unwrap().remove("accessors");
        assert!(check(v).unwrap().contains("(0 accessors)"));
        let mut v = ok.clone();
        v["meshes"][0]["primitives"][0]["material"] = json!(9223372036854775808u64);
        assert!(check(v).unwrap().contains("larger than 2^32 - 1"));
        let mut v = ok.clone();
        v["meshes"][0]["primitives"][0]["material"] = json!(-1);
        assert!(check(v).unwrap().contains("not an index"));
        let mut v = ok.clone();
        v["bufferViews"][0]["buffer"] = json!(1.5);
        assert!(check(v).unwrap().starts_with("bufferViews[0].buffer"));
        // Shapes: an array where an object belongs parses with serde, so it is refused here.
        let mut v = ok.clone();
        v["materials"][0] = json!([]);
        assert_eq!(
            check(v).as_deref(),
            Some("materials[0]: must be a JSON object, found an array")
        );
        let mut v = ok;
        v["materials"][0]["extensions"] = json!([1]);
        assert_eq!(
            check(v).as_deref(),
            Some("materials[0].extensions: must be a JSON object, found an array")
        );
    }
}
