//! The lightmap binding of a baked glb, read back as a client reads it: the UV set that
//! `MOZ_lightmap.texCoord` names, the texture of `MOZ_lightmap.index` with its page and
//! encoding (from the texture's `extras.penumbra`), and `MOZ_lightmap.intensity`.
//! [`crate::render`] and [`crate::reference`] read baked files through it.

use crate::error::{Error, Result};
use crate::lightmap::Encoding;
use crate::load::Gltf;
use crate::scene::Instance;
use glam::DVec2;
use gltf::accessor::Dimensions;

/// How one primitive samples its lightmap.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Binding {
    /// The UV set, `TEXCOORD_<tex_coord>` (`MOZ_lightmap.texCoord`; 1 when absent, the set
    /// lightmaps conventionally use and the one the writer fills).
    pub(crate) tex_coord: u32,
    /// That set's UV per glTF vertex, normalized.
    pub(crate) uv: Vec<DVec2>,
    /// The lightmap texture (`MOZ_lightmap.index`).
    pub(crate) texture: usize,
    /// Irradiance H (W/m²) of a full-scale texel (`MOZ_lightmap.intensity`, 1 when absent).
    pub(crate) intensity: f64,
    /// The light groups' layers of this page (`MOZ_lightmap.extras.penumbra.layers`): per
    /// group, its texture and intensity.
    pub(crate) layers: std::collections::BTreeMap<String, (usize, f64)>,
    /// The directional lightmap's ratio pages of this page
    /// (`MOZ_lightmap.extras.penumbra.directional`): the textures of axes `x`, `y`, `z`.
    pub(crate) directional: Option<[usize; 3]>,
}

/// The lightmap binding of a scene instance's primitive: `None` when its material has no
/// `MOZ_lightmap`; an error when the primitive lacks the UV set the extension names.
pub(crate) fn binding(gltf: &Gltf, inst: &Instance) -> Result<Option<Binding>> {
    let Some(moz) = inst
        .gltf_material
        .and_then(|m| gltf.json["materials"][m]["extensions"]["MOZ_lightmap"].as_object())
    else {
        return Ok(None);
    };
    let (tex_coord, uv) = uv_set(gltf, inst, moz, 1, "MOZ_lightmap")?;
    let layers = moz
        .get("extras")
        .and_then(|e| e["penumbra"]["layers"].as_array())
        .into_iter()
        .flatten()
        .filter_map(|l| {
            let group = l["group"].as_str()?.to_string();
            let texture = l["index"].as_u64()? as usize;
            Some((group, (texture, l["intensity"].as_f64().unwrap_or(1.0))))
        })
        .collect();
    let directional = moz.get("extras").and_then(|e| {
        let d = &e["penumbra"]["directional"];
        let axis = |a: &str| d[a]["index"].as_u64().map(|t| t as usize);
        Some([axis("x")?, axis("y")?, axis("z")?])
    });
    Ok(Some(Binding {
        tex_coord,
        uv,
        texture: moz.get("index").and_then(|v| v.as_u64()).unwrap_or(0) as usize,
        intensity: moz.get("intensity").and_then(|v| v.as_f64()).unwrap_or(1.0),
        layers,
        directional,
    }))
}

/// The material's `normalTexture` of a scene instance's primitive, as a [`Binding`] whose
/// `intensity` is the texture's `scale` (1 when absent): `None` when its material has none.
pub(crate) fn normal_map(gltf: &Gltf, inst: &Instance) -> Result<Option<Binding>> {
    texture_info(gltf, inst, "normalTexture", "scale")
}

/// The material's `occlusionTexture` of a scene instance's primitive, as a [`Binding`] whose
/// `intensity` is the texture's `strength` (1 when absent): `None` when its material has none.
pub(crate) fn occlusion(gltf: &Gltf, inst: &Instance) -> Result<Option<Binding>> {
    texture_info(gltf, inst, "occlusionTexture", "strength")
}

/// The material's texture reference `what` (a core `textureInfo`) of a scene instance's
/// primitive, as a [`Binding`] whose `intensity` is its `factor` property (1 when absent).
fn texture_info(gltf: &Gltf, inst: &Instance, what: &str, factor: &str) -> Result<Option<Binding>> {
    let Some(info) = inst
        .gltf_material
        .and_then(|m| gltf.json["materials"][m][what].as_object())
    else {
        return Ok(None);
    };
    let (tex_coord, uv) = uv_set(gltf, inst, info, 0, what)?;
    Ok(Some(Binding {
        tex_coord,
        uv,
        texture: info.get("index").and_then(|v| v.as_u64()).unwrap_or(0) as usize,
        intensity: info.get(factor).and_then(|v| v.as_f64()).unwrap_or(1.0),
        layers: Default::default(),
        directional: None,
    }))
}

/// The UV set that a texture reference (`info`, of the property `what`) names in its
/// `texCoord` (`default` when absent), read from the instance's primitive.
fn uv_set(
    gltf: &Gltf,
    inst: &Instance,
    info: &serde_json::Map<String, serde_json::Value>,
    default: u64,
    what: &str,
) -> Result<(u32, Vec<DVec2>)> {
    let item = format!("mesh {} primitive {}", inst.mesh, inst.primitive);
    let prim = gltf
        .document
        .meshes()
        .nth(inst.mesh)
        .and_then(|m| m.primitives().nth(inst.primitive))
        .ok_or_else(|| bad(gltf, item.clone(), "missing primitive".into()))?;
    let tex_coord = u32::try_from(
        info.get("texCoord")
            .and_then(|v| v.as_u64())
            .unwrap_or(default),
    )
    .map_err(|_| bad(gltf, item.clone(), format!("{what}.texCoord is too large")))?;
    let acc = prim
        .get(&gltf::Semantic::TexCoords(tex_coord))
        .ok_or_else(|| {
            let reason = format!("{what} names TEXCOORD_{tex_coord}, which it does not have");
            bad(gltf, item.clone(), reason)
        })?;
    let uv = gltf
        .read_floats(&acc, Dimensions::Vec2)?
        .chunks_exact(2)
        .map(|c| DVec2::new(c[0], c[1]))
        .collect();
    Ok((tex_coord, uv))
}

/// The encoding of a lightmap texture, from its `extras.penumbra.encoding` (absent: linear, the
/// plain reading of 8-bit values). An unknown name is an error.
pub(crate) fn texture_encoding(gltf: &Gltf, texture: usize) -> Result<Encoding> {
    match gltf.json["textures"][texture]["extras"]["penumbra"]["encoding"].as_str() {
        None => Ok(Encoding::Linear),
        Some(name) => Encoding::from_name(name).ok_or_else(|| {
            let reason =
                format!("extras.penumbra.encoding {name:?} is neither \"srgb\" nor \"linear\"");
            bad(gltf, format!("texture {texture}"), reason)
        }),
    }
}

/// The page of a lightmap texture, from its `extras.penumbra.page` (absent: 0).
pub(crate) fn texture_page(gltf: &Gltf, texture: usize) -> usize {
    gltf.json["textures"][texture]["extras"]["penumbra"]["page"]
        .as_u64()
        .unwrap_or(0) as usize
}

/// The encoded image bytes of a texture's source (embedded or a file beside the glTF).
pub(crate) fn texture_bytes(gltf: &Gltf, texture: usize) -> Result<Vec<u8>> {
    let tex = gltf
        .document
        .textures()
        .nth(texture)
        .ok_or_else(|| bad(gltf, format!("texture {texture}"), "does not exist".into()))?;
    Ok(match tex.source().source() {
        gltf::image::Source::View { view, .. } => gltf.view_bytes(&view, "lightmap")?.to_vec(),
        gltf::image::Source::Uri { uri, .. } => gltf.uri_bytes(uri, "lightmap")?,
    })
}

fn bad(gltf: &Gltf, item: String, reason: String) -> Error {
    Error::BadItem {
        path: gltf.path.clone(),
        item,
        reason,
    }
}
