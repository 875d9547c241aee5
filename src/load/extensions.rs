//! glTF extensions: which penumbra reads, which it keeps without needing them, which it refuses.
//!
//! The `gltf` crate refuses any file that requires an extension it was not built with, before
//! penumbra sees the file. So the loader parses without that check and decides here. Every
//! extension of the input stays in the output as it was, except those the writer undoes:
//! meshopt-compressed buffer views are written decoded, and nodes with GPU instances become
//! one node per instance ([`crate::write`]).
//!
//! - **Read**: the geometry and lights penumbra bakes (`KHR_mesh_quantization`'s integer
//!   attributes, `EXT_meshopt_compression`'s encoded views, `EXT_mesh_gpu_instancing`'s
//!   instances, `EXT_texture_webp` images, `KHR_texture_transform` on base-colour textures,
//!   punctual lights, emissive strength).
//! - **Kept**: what a client shows but the diffuse light does not depend on (clearcoat, sheen,
//!   specular, variants, ...), or what penumbra approximates with a warning (a KTX2 texture's
//!   colour is its material's factor).
//! - **Refused**, with the way out: Draco, whose geometry penumbra cannot decode.
//! - **Unknown** and required: refused, naming it. Unknown and only used: kept, with a warning.

use super::validate::Invalid;
use serde_json::Value;

/// How penumbra treats one extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Support {
    /// Read and honoured.
    Read,
    /// Kept in the output; the bake does not need it.
    Kept,
    /// Kept in the output; the bake approximates it, and says how in a warning.
    Approximated(&'static str),
    /// Refused when required, with the way out.
    Refused(&'static str),
}

/// The extensions penumbra knows, and what it does with each.
const KNOWN: &[(&str, Support)] = &[
    ("KHR_lights_punctual", Support::Read),
    ("KHR_materials_emissive_strength", Support::Read),
    ("KHR_mesh_quantization", Support::Read),
    ("EXT_meshopt_compression", Support::Read),
    ("KHR_meshopt_compression", Support::Read),
    ("EXT_mesh_gpu_instancing", Support::Read),
    ("EXT_texture_webp", Support::Read),
    ("KHR_texture_transform", Support::Read),
    (
        "KHR_texture_basisu",
        Support::Approximated(
            "KTX2 (Basis Universal) images are not decoded: a material's colour is its factor alone",
        ),
    ),
    (
        "EXT_texture_avif",
        Support::Approximated(
            "AVIF images are not decoded: a material's colour is its factor alone",
        ),
    ),
    ("KHR_materials_transmission", Support::Read),
    (
        "KHR_materials_volume",
        Support::Approximated("volumes are baked as opaque surfaces"),
    ),
    (
        "KHR_materials_diffuse_transmission",
        Support::Approximated("diffuse transmission is baked as an opaque surface"),
    ),
    (
        "KHR_materials_pbrSpecularGlossiness",
        Support::Approximated(
            "the metallic-roughness colour is baked; the specular-glossiness one is not read",
        ),
    ),
    ("KHR_materials_clearcoat", Support::Kept),
    ("KHR_materials_sheen", Support::Kept),
    ("KHR_materials_specular", Support::Kept),
    ("KHR_materials_ior", Support::Kept),
    ("KHR_materials_iridescence", Support::Kept),
    ("KHR_materials_anisotropy", Support::Kept),
    ("KHR_materials_dispersion", Support::Kept),
    ("KHR_materials_unlit", Support::Kept),
    ("KHR_materials_variants", Support::Kept),
    ("KHR_animation_pointer", Support::Kept),
    ("KHR_node_visibility", Support::Kept),
    ("KHR_xmp_json_ld", Support::Kept),
    ("KHR_xmp", Support::Kept),
    ("EXT_lights_image_based", Support::Kept),
    ("MSFT_lod", Support::Kept),
    ("MSFT_texture_dds", Support::Kept),
    ("MOZ_lightmap", Support::Kept),
    (
        "KHR_draco_mesh_compression",
        Support::Refused(
            "penumbra cannot decode Draco geometry; re-encode it with meshopt, which it reads: \
             `npx @gltf-transform/cli meshopt IN.glb OUT.glb`",
        ),
    ),
];

/// What penumbra does with extension `name`; `None` when it does not know it.
pub(crate) fn support(name: &str) -> Option<Support> {
    KNOWN.iter().find(|(n, _)| *n == name).map(|&(_, s)| s)
}

/// The extensions a file lists in `key` (`extensionsUsed` or `extensionsRequired`).
fn listed<'a>(json: &'a Value, key: &str) -> impl Iterator<Item = &'a str> {
    json[key]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(Value::as_str)
}

/// Whether the file declares extension `name` (in `extensionsUsed` or `extensionsRequired`).
pub(crate) fn declares(json: &Value, name: &str) -> bool {
    listed(json, "extensionsUsed")
        .chain(listed(json, "extensionsRequired"))
        .any(|e| e == name)
}

/// Refuses a file that requires an extension penumbra refuses or does not know.
pub(super) fn check_required(json: &Value) -> Result<(), Invalid> {
    for (i, name) in listed(json, "extensionsRequired").enumerate() {
        let reason = match support(name) {
            Some(Support::Refused(way_out)) => format!("requires {name}: {way_out}"),
            None => format!(
                "requires {name}, which penumbra does not know, so it cannot tell whether the \
                 scene it bakes is the one the file shows; if the file is complete without it, \
                 remove it from extensionsRequired"
            ),
            Some(_) => continue,
        };
        return Err(Invalid {
            item: format!("extensionsRequired[{i}]"),
            reason,
        });
    }
    Ok(())
}

/// One warning per extension the file uses that the bake approximates or does not know.
pub(super) fn warnings(json: &Value) -> Vec<String> {
    let mut out = Vec::new();
    let mut seen = std::collections::BTreeSet::new();
    for name in listed(json, "extensionsUsed").chain(listed(json, "extensionsRequired")) {
        if !seen.insert(name) {
            continue;
        }
        match support(name) {
            Some(Support::Approximated(how)) => out.push(format!("{name}: {how}")),
            None => out.push(format!(
                "{name} is not known to penumbra: kept in the output, not used by the bake"
            )),
            _ => {}
        }
    }
    out
}

/// The JSON as the `gltf` crate is given it: the same, except that a texture whose image is
/// only in an extension (`EXT_texture_webp`, `KHR_texture_basisu`, `EXT_texture_avif`) gets
/// that image as its `source`, which the crate requires. WebP comes first, as the one of them
/// penumbra decodes. The file's own JSON, which the writer edits, keeps them as they were.
pub(super) fn for_parsing(json: &Value) -> Value {
    let mut copy = json.clone();
    if let Some(textures) = copy.get_mut("textures").and_then(Value::as_array_mut) {
        for t in textures {
            if t.get("source").is_some() {
                continue;
            }
            let from_extension = ["EXT_texture_webp", "KHR_texture_basisu", "EXT_texture_avif"]
                .iter()
                .find_map(|e| t["extensions"][e]["source"].as_u64());
            if let (Some(s), Some(o)) = (from_extension, t.as_object_mut()) {
                o.insert("source".into(), s.into());
            }
        }
    }
    // The crate's own check of this list is what refuses unknown extensions; penumbra has
    // decided above.
    if let Some(o) = copy.as_object_mut() {
        o.remove("extensionsRequired");
    }
    copy
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn required_extensions_are_refused_by_name_unless_penumbra_reads_or_keeps_them() {
        let ok = json!({"extensionsRequired": ["KHR_mesh_quantization", "EXT_meshopt_compression",
            "EXT_texture_webp", "KHR_texture_basisu", "EXT_mesh_gpu_instancing"]});
        assert!(check_required(&ok).is_ok());
        let draco =
            json!({"extensionsRequired": ["KHR_mesh_quantization", "KHR_draco_mesh_compression"]});
        let e = check_required(&draco).unwrap_err();
        assert_eq!(e.item, "extensionsRequired[1]");
        assert!(e.reason.contains("KHR_draco_mesh_compression") && e.reason.contains("meshopt"));
        let unknown = json!({"extensionsRequired": ["EXT_made_up"]});
        let e = check_required(&unknown).unwrap_err();
        assert!(e.reason.contains("EXT_made_up") && e.reason.contains("extensionsRequired"));
        // Only used, an unknown extension is kept with a warning.
        let used = json!({"extensionsUsed": ["EXT_made_up", "KHR_materials_clearcoat", "KHR_texture_basisu"]});
        assert!(check_required(&used).is_ok());
        let w = warnings(&used);
        assert_eq!(w.len(), 2, "{w:?}");
        assert!(w[0].contains("EXT_made_up") && w[1].contains("KHR_texture_basisu"));
    }

    #[test]
    fn a_texture_whose_image_is_in_an_extension_gets_it_as_its_source_for_parsing() {
        let json = json!({
            "extensionsRequired": ["EXT_texture_webp"],
            "textures": [
                {"extensions": {"EXT_texture_webp": {"source": 2}}},
                {"source": 0, "extensions": {"EXT_texture_webp": {"source": 1}}},
                {"extensions": {"KHR_texture_basisu": {"source": 3}}},
            ]
        });
        let p = for_parsing(&json);
        assert_eq!(p["textures"][0]["source"], 2);
        assert_eq!(
            p["textures"][1]["source"], 0,
            "a fallback image stays the source"
        );
        assert_eq!(p["textures"][2]["source"], 3);
        assert!(p.get("extensionsRequired").is_none());
        assert!(
            json["textures"][0].get("source").is_none(),
            "the file's JSON is unchanged"
        );
    }
}
