//! Writing the lightmapped glb: the input with everything preserved, plus per lightmapped
//! primitive a second UV set (`TEXCOORD_1`, and `TEXCOORD_0` where the input has none), one
//! lightmap PNG per atlas page in the binary chunk, and `MOZ_lightmap` on every lightmapped
//! material.
//!
//! Each page's texture carries the convention of its values in its `extras`:
//! `{"penumbra": {"quantity": "irradiance", "units": "W/m^2", "encoding": "srgb" | "linear",
//! "scale": <intensity>, "page": <p>}}`: decode the 8-bit value with `encoding`'s curve to a
//! linear 0..1 value, times `scale` (= `MOZ_lightmap.intensity`) is the irradiance H in W/m².
//! A primitive whose charts lie on several pages is split into one primitive per page, and a
//! material used on several pages is cloned per page (each clone's `MOZ_lightmap.index` is its
//! page's texture).
//!
//! The back side of a double-sided primitive (with `--double-sided separate`, the default)
//! becomes a primitive of its own, placed right after the front's (after all of the front's
//! per-page parts): its own lightmap UVs, reversed winding, negated normals, and the same
//! lightmapped material as the front, made single-sided (`doubleSided` removed), so each side
//! draws its own light and only its own. With `shared` the back has no texels and no
//! primitive, and the material stays double-sided: an engine shows the front's light on both
//! sides.
//!
//! The writer edits the file's own JSON, so whatever it does not touch (extensions, extras,
//! animations, unknown properties) is kept as it was. All buffers are merged into the one GLB
//! binary chunk and external images are embedded, so the output stands alone. xatlas splits
//! vertices at chart seams, so each lightmapped primitive gets new accessors for all of its
//! attributes, remapped through the atlas's vertex cross-reference. A mesh placed by several
//! nodes is copied so that each placement has its own lightmap space. The bytes are built here;
//! [`crate::files`] writes them (temporary file, then rename), so a failure never leaves a half
//! file. [`binding`] reads the lightmap binding back from a written file.

pub(crate) mod binding;
mod expand;
mod images;
mod pages;
mod probes;

pub use images::exr_bytes;
pub(crate) use images::{grey_png_bytes, png_bytes};

use crate::atlas::{Atlas, AtlasMesh};
use crate::error::{Error, Result};
use crate::lightmap::Encoding;
use crate::load::Gltf;
use crate::scene::{Scene, Side};
use serde_json::{Value, json};
use std::collections::BTreeMap;

/// How a directional lightmap's ratio pages decode, as written into their textures' extras
/// ([`crate::lightmap::directional`]).
pub(crate) const DIRECTIONAL_DECODE: &str = "r = code / 255 * 2 - 1 per channel and axis; \
     H(n) = H * (0.5 + 2 * (r_x n_x + r_y n_y + r_z n_z)) for a unit world-space normal n";

/// The lightmap as it goes into the file.
pub(crate) struct LightmapImage {
    /// PNG bytes (8-bit RGB in `encoding`), one per atlas page, in page order.
    pub(crate) pngs: Vec<Vec<u8>>,
    /// `MOZ_lightmap` intensity, W/m²: irradiance H = decoded texel value (0..1) x intensity.
    pub(crate) intensity: f64,
    /// Transfer curve of the PNGs' 8-bit values.
    pub(crate) encoding: Encoding,
    /// The ambient occlusion (`--ao`), same pages.
    pub(crate) ao: Option<AoImage>,
    /// The light groups' layers ([`crate::scene::mixed`]), same pages and encoding.
    pub(crate) layers: Vec<LayerImage>,
    /// The light probes (`--probes`), written in the root's `extras`.
    pub(crate) probes: Option<crate::probes::Probes>,
    /// The directional lightmap's ratio pages (`--directional`): per axis `x`, `y`, `z`, PNG
    /// bytes ([`crate::lightmap::directional::to_rgb8`]) per page.
    pub(crate) directional: Option<[Vec<Vec<u8>>; 3]>,
}

/// One light group's layer as it goes into the file.
pub(crate) struct LayerImage {
    /// The group's name.
    pub(crate) name: String,
    /// PNG bytes as [`LightmapImage::pngs`], one per page.
    pub(crate) pngs: Vec<Vec<u8>>,
    /// Irradiance H (W/m²) of a full-scale texel of this layer.
    pub(crate) intensity: f64,
}

/// The ambient occlusion as it goes into the file.
pub(crate) struct AoImage {
    /// PNG bytes (8-bit grey, linear: AO = value / 255), one per atlas page, in page order.
    pub(crate) pngs: Vec<Vec<u8>>,
    /// The occlusion distance, scene units.
    pub(crate) distance: f64,
}

const ARRAY_BUFFER: u64 = 34962;
const ELEMENT_ARRAY_BUFFER: u64 = 34963;

/// Accumulates the output binary chunk.
struct Bin {
    data: Vec<u8>,
}

impl Bin {
    /// Appends bytes at an 8-byte aligned offset; returns the offset.
    fn push(&mut self, bytes: &[u8]) -> usize {
        while !self.data.len().is_multiple_of(8) {
            self.data.push(0);
        }
        let at = self.data.len();
        self.data.extend_from_slice(bytes);
        at
    }
}

fn array_mut<'a>(root: &'a mut Value, key: &str) -> &'a mut Vec<Value> {
    let obj = root.as_object_mut().expect("glTF root is an object");
    let v = obj.entry(key).or_insert_with(|| json!([]));
    if !v.is_array() {
        *v = json!([]);
    }
    v.as_array_mut().expect("just made an array")
}

fn push_view(
    root: &mut Value,
    bin: &mut Bin,
    bytes: &[u8],
    stride: Option<usize>,
    target: Option<u64>,
) -> usize {
    let offset = bin.push(bytes);
    let mut view = json!({"buffer": 0, "byteOffset": offset, "byteLength": bytes.len()});
    if let Some(s) = stride {
        view["byteStride"] = json!(s);
    }
    if let Some(t) = target {
        view["target"] = json!(t);
    }
    let views = array_mut(root, "bufferViews");
    views.push(view);
    views.len() - 1
}

/// Adds a PNG as an image in the binary chunk and a texture of it with `sampler` and `extras`;
/// returns the texture's index.
fn push_png_texture(
    root: &mut Value,
    bin: &mut Bin,
    name: &str,
    png: &[u8],
    sampler: usize,
    extras: Value,
) -> usize {
    let view = push_view(root, bin, png, None, None);
    let images = array_mut(root, "images");
    images.push(json!({"name": name, "bufferView": view, "mimeType": "image/png"}));
    let image = images.len() - 1;
    let textures = array_mut(root, "textures");
    textures.push(json!({"name": name, "sampler": sampler, "source": image, "extras": extras}));
    textures.len() - 1
}

fn push_accessor(root: &mut Value, accessor: Value) -> usize {
    let accessors = array_mut(root, "accessors");
    accessors.push(accessor);
    accessors.len() - 1
}

/// Number of components of a glTF accessor type.
fn components(ty: &str) -> usize {
    match ty {
        "SCALAR" => 1,
        "VEC2" => 2,
        "VEC3" => 3,
        "VEC4" | "MAT2" => 4,
        "MAT3" => 9,
        "MAT4" => 16,
        _ => 1,
    }
}

fn component_value(ct: u64, c: &[u8]) -> f64 {
    match ct {
        5120 => c[0] as i8 as f64,
        5121 => c[0] as f64,
        5122 => i16::from_le_bytes([c[0], c[1]]) as f64,
        5123 => u16::from_le_bytes([c[0], c[1]]) as f64,
        5125 => u32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f64,
        _ => f32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f64,
    }
}

fn number(ct: u64, x: f64) -> Value {
    if ct == 5126 {
        json!(x as f32)
    } else {
        json!(x as i64)
    }
}

/// Builds the output glb bytes.
pub(crate) fn build(
    gltf: &Gltf,
    scene: &Scene,
    atlas: &Atlas,
    image: &LightmapImage,
) -> Result<Vec<u8>> {
    let mut root = gltf.json.clone();
    if !root.is_object() {
        return Err(Error::NotGltf {
            path: gltf.path.clone(),
            reason: "the JSON root is not an object".into(),
        });
    }
    let mut bin = Bin { data: Vec::new() };

    // 1. Merge every buffer into the binary chunk (compressed views decoded) and repoint the
    //    buffer views; GPU instances become nodes.
    expand::merge_buffers(gltf, &mut root, &mut bin);
    let instance_node = expand::split_gpu_instances(gltf, &mut root, scene)?;
    // 2. Embed images that live in files or data URIs.
    let n_images = array_mut(&mut root, "images").len();
    for i in 0..n_images {
        let uri = root["images"][i]["uri"].as_str().map(str::to_string);
        if let Some(uri) = uri {
            let item = format!("image {i}");
            let data = gltf.uri_bytes(&uri, &item)?;
            let mime = if data.starts_with(&[0x89, b'P', b'N', b'G']) {
                "image/png"
            } else if data.starts_with(&[0xFF, 0xD8]) {
                "image/jpeg"
            } else if uri.ends_with(".ktx2") {
                "image/ktx2"
            } else if uri.ends_with(".webp") {
                "image/webp"
            } else {
                "application/octet-stream"
            };
            let view = push_view(&mut root, &mut bin, &data, None, None);
            // `uri` was read from this image, so it is an object.
            if let Some(img) = root["images"][i].as_object_mut() {
                img.remove("uri");
                img.insert("bufferView".into(), json!(view));
                img.insert("mimeType".into(), json!(mime));
            }
        }
    }

    // 3. The lightmap textures, with the layers', the directional pages' and the AO's.
    let (moz_of_page, ao_of_page) = pages::textures(&mut root, &mut bin, image, atlas)?;

    if let Some(probes) = &image.probes {
        probes::write(&mut root, &mut bin, probes)?;
    }

    // 4. Which nodes use each mesh, and which of those placements are lightmapped.
    let mut lit_nodes: BTreeMap<usize, BTreeMap<usize, Vec<usize>>> = BTreeMap::new();
    for (i, inst) in scene.instances.iter().enumerate() {
        let node = match inst.gpu_instance {
            Some(k) => instance_node
                .get(&(inst.node, k))
                .copied()
                .unwrap_or(inst.node),
            None => inst.node,
        };
        lit_nodes
            .entry(inst.mesh)
            .or_default()
            .entry(node)
            .or_default()
            .push(i);
    }
    let mut mesh_users: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
    for (n, node) in root["nodes"]
        .as_array()
        .cloned()
        .unwrap_or_default()
        .iter()
        .enumerate()
    {
        if let Some(m) = node["mesh"].as_u64() {
            mesh_users.entry(m as usize).or_default().push(n);
        }
    }

    // 5. Materials used by lightmapped primitives get MOZ_lightmap; a material also used by an
    //    unlit primitive is cloned first.
    let mut lit_material_uses: BTreeMap<Option<usize>, usize> = BTreeMap::new();
    // The pages each material's lightmapped primitives lie on.
    let mut material_pages: BTreeMap<Option<usize>, std::collections::BTreeSet<u32>> =
        BTreeMap::new();
    for (i, inst) in scene.instances.iter().enumerate() {
        let mat = gltf.json["meshes"][inst.mesh]["primitives"][inst.primitive]["material"]
            .as_u64()
            .map(|x| x as usize);
        material_pages
            .entry(mat)
            .or_default()
            .extend(pages_of(&atlas.meshes[i]));
    }
    let mut all_material_uses: BTreeMap<Option<usize>, usize> = BTreeMap::new();
    for (m, users) in &mesh_users {
        let prims = root["meshes"][*m]["primitives"]
            .as_array()
            .cloned()
            .unwrap_or_default();
        for node in users {
            for (p, prim) in prims.iter().enumerate() {
                let mat = prim["material"].as_u64().map(|x| x as usize);
                *all_material_uses.entry(mat).or_default() += 1;
                let lit = lit_nodes
                    .get(m)
                    .and_then(|n| n.get(node))
                    .is_some_and(|insts| insts.iter().any(|&i| scene.instances[i].primitive == p));
                if lit {
                    *lit_material_uses.entry(mat).or_default() += 1;
                }
            }
        }
    }
    // A material that samples a texture through TEXCOORD_1 keeps it: the primitives' own
    // TEXCOORD_1 moves to the first free set, and the material's references follow it.
    let mut moved_uv1: BTreeMap<Option<usize>, u32> = BTreeMap::new();
    for mat in lit_material_uses.keys() {
        if let Some(i) = mat
            && references_tex_coord(&root["materials"][*i], 1)
        {
            let highest = root["meshes"]
                .as_array()
                .into_iter()
                .flatten()
                .flat_map(|m| m["primitives"].as_array().into_iter().flatten())
                .filter(|p| p["material"].as_u64() == Some(*i as u64))
                .flat_map(|p| p["attributes"].as_object().into_iter().flatten())
                .filter_map(|(name, _)| name.strip_prefix("TEXCOORD_")?.parse::<u32>().ok())
                .max()
                .unwrap_or(1);
            moved_uv1.insert(*mat, highest.max(1) + 1);
        }
    }
    // (material, page) -> the material index lightmapped primitives of that page use. The
    // first page keeps the material itself unless an unlit primitive shares it; every other
    // page gets a clone.
    let mut material_map: BTreeMap<(Option<usize>, u32), usize> = BTreeMap::new();
    // Materials whose back sides get primitives of their own (`--double-sided separate`):
    // their lightmapped versions become single-sided, or the front primitive would draw its
    // lightmap on the back too, over the back's own primitive.
    let separate_backs: std::collections::BTreeSet<Option<usize>> = scene
        .instances
        .iter()
        .zip(&atlas.meshes)
        .filter(|(i, am)| i.side == Side::Back && !am.indices.is_empty())
        .map(|(i, _)| {
            gltf.json["meshes"][i.mesh]["primitives"][i.primitive]["material"]
                .as_u64()
                .map(|x| x as usize)
        })
        .collect();
    for (mat, lit) in &lit_material_uses {
        let shared = all_material_uses.get(mat).copied().unwrap_or(0) > *lit;
        let pages: Vec<u32> = material_pages
            .get(mat)
            .map(|p| p.iter().copied().collect())
            .unwrap_or_default();
        let pages = if pages.is_empty() { vec![0] } else { pages };
        for (n, &page) in pages.iter().enumerate() {
            let suffix = match (pages.len(), page) {
                (1, _) | (_, 0) => " (lightmapped)".to_string(),
                (_, p) => format!(" (lightmap page {p})"),
            };
            let index = match mat {
                Some(i) if !shared && n == 0 => *i,
                Some(i) => {
                    let mut copy = gltf.json["materials"][*i].clone();
                    if let Some(name) = copy["name"].as_str() {
                        copy["name"] = json!(format!("{name}{suffix}"));
                    }
                    let mats = array_mut(&mut root, "materials");
                    mats.push(copy);
                    mats.len() - 1
                }
                None => {
                    let mats = array_mut(&mut root, "materials");
                    mats.push(json!({ "name": format!("default{suffix}") }));
                    mats.len() - 1
                }
            };
            let m = &mut root["materials"][index];
            if let Some(&k) = moved_uv1.get(mat) {
                retarget_tex_coord(m, 1, k);
            }
            if !m["extensions"].is_object() {
                m["extensions"] = json!({});
            }
            let moz = moz_of_page
                .get(page as usize)
                .cloned()
                .ok_or_else(|| Error::Image(format!("atlas page {page} has no lightmap image")))?;
            m["extensions"]["MOZ_lightmap"] = moz;
            // A material's own occlusion texture (authored at its own UVs) is kept.
            if let Some(ao) = ao_of_page.get(page as usize)
                && m.get("occlusionTexture").is_none()
            {
                m["occlusionTexture"] = ao.clone();
            }
            if separate_backs.contains(mat)
                && let Some(o) = m.as_object_mut()
            {
                o.remove("doubleSided");
            }
            material_map.insert((*mat, page), index);
        }
    }

    // 6. New primitive data for every lightmapped placement; copies of shared meshes.
    for (mesh, nodes) in &lit_nodes {
        let users = mesh_users.get(mesh).cloned().unwrap_or_default();
        // The original mesh entry is edited in place for the first lightmapped placement when
        // every node using the mesh is lightmapped; every other placement gets a copy.
        let mut in_place_taken = !users.iter().all(|n| nodes.contains_key(n));
        for (node, insts) in nodes {
            let mut mesh_json = gltf.json["meshes"][*mesh].clone();
            // Each lightmapped primitive becomes one primitive per page it lies on, followed
            // by those of its back side (double-sided, `--double-sided separate`; with `shared`
            // the back has no texels and no primitive).
            let mut replaced: BTreeMap<usize, Vec<Value>> = BTreeMap::new();
            for &i in insts {
                let inst = &scene.instances[i];
                if inst.side == Side::Back && atlas.meshes[i].indices.is_empty() {
                    continue;
                }
                let original = &mesh_json["primitives"][inst.primitive];
                let mat = original["material"].as_u64().map(|x| x as usize);
                let uv1_to = moved_uv1.get(&mat).copied();
                let mut parts = Vec::new();
                for (page, part) in split_by_page(&atlas.meshes[i]) {
                    let mut prim = original.clone();
                    rewrite_primitive(
                        gltf, &mut root, &mut bin, &mut prim, inst, &part, atlas, uv1_to,
                    )?;
                    if let Some(&mi) = material_map.get(&(mat, page)) {
                        prim["material"] = json!(mi);
                    }
                    parts.push(prim);
                }
                replaced.entry(inst.primitive).or_default().extend(parts);
            }
            if let Some(prims) = mesh_json["primitives"].as_array_mut() {
                let mut out = Vec::with_capacity(prims.len());
                for (p, prim) in prims.drain(..).enumerate() {
                    match replaced.remove(&p) {
                        Some(parts) => out.extend(parts),
                        None => out.push(prim),
                    }
                }
                *prims = out;
            }
            if !in_place_taken {
                root["meshes"][*mesh] = mesh_json;
                in_place_taken = true;
            } else {
                let meshes = array_mut(&mut root, "meshes");
                meshes.push(mesh_json);
                let new = meshes.len() - 1;
                root["nodes"][*node]["mesh"] = json!(new);
            }
        }
    }

    // 7. One buffer, extension declared as used (not required: the scene renders without it).
    root["buffers"] = json!([{"byteLength": bin.data.len()}]);
    let used = array_mut(&mut root, "extensionsUsed");
    if !used.iter().any(|e| e == "MOZ_lightmap") {
        used.push(json!("MOZ_lightmap"));
    }
    to_glb(&root, bin.data)
}

/// The pages a mesh's triangles lie on, ascending.
fn pages_of(am: &AtlasMesh) -> std::collections::BTreeSet<u32> {
    am.page.iter().copied().collect()
}

/// A mesh's triangles grouped by page: per page (ascending), an [`AtlasMesh`] of that page's
/// triangles (in their order) over the vertices they use (in their order). A mesh on one page
/// (or with no triangles) is returned as is, on its page.
fn split_by_page(am: &AtlasMesh) -> Vec<(u32, AtlasMesh)> {
    let pages = pages_of(am);
    if pages.len() <= 1 {
        return vec![(pages.first().copied().unwrap_or(0), am.clone())];
    }
    pages
        .into_iter()
        .map(|page| {
            let mut remap = vec![u32::MAX; am.xref.len()];
            let mut used: Vec<u32> = am
                .indices
                .chunks_exact(3)
                .zip(&am.page)
                .filter(|(_, p)| **p == page)
                .flat_map(|(t, _)| t.iter().copied())
                .collect();
            used.sort_unstable();
            used.dedup();
            let mut part = AtlasMesh::default();
            for (n, &v) in used.iter().enumerate() {
                remap[v as usize] = n as u32;
                part.xref.push(am.xref[v as usize]);
                part.uv.push(am.uv[v as usize]);
            }
            for (t, _) in am
                .indices
                .chunks_exact(3)
                .zip(&am.page)
                .filter(|(_, p)| **p == page)
            {
                part.indices.extend(t.iter().map(|&v| remap[v as usize]));
                part.page.push(page);
            }
            (page, part)
        })
        .collect()
}

/// Replaces one primitive's attributes by atlas-split copies plus the lightmap UVs.
/// `uv1_to`: move the primitive's own TEXCOORD_1 to `TEXCOORD_<k>` (its material samples it).
#[allow(clippy::too_many_arguments)]
fn rewrite_primitive(
    gltf: &Gltf,
    root: &mut Value,
    bin: &mut Bin,
    prim: &mut Value,
    inst: &crate::scene::Instance,
    am: &AtlasMesh,
    atlas: &Atlas,
    uv1_to: Option<u32>,
) -> Result<()> {
    let attributes = prim["attributes"].as_object().cloned().unwrap_or_default();
    let mut new_attributes = serde_json::Map::new();
    for (name, acc) in &attributes {
        let name = match (name.as_str(), uv1_to) {
            ("TEXCOORD_1", Some(k)) => &format!("TEXCOORD_{k}"),
            ("TEXCOORD_1", None) => continue, // replaced by the lightmap UVs
            _ => name,
        };
        let Some(acc_index) = acc.as_u64() else {
            continue;
        };
        let accessor = gltf
            .document
            .accessors()
            .nth(acc_index as usize)
            .ok_or_else(|| Error::BadItem {
                path: gltf.path.clone(),
                item: format!("attribute {name}"),
                reason: format!("accessor {acc_index} does not exist"),
            })?;
        let (bytes, elem) = gltf.accessor_bytes(&accessor)?;
        let stride = elem.div_ceil(4) * 4;
        let original = &gltf.json["accessors"][acc_index as usize];
        let ct = original["componentType"].as_u64().unwrap_or(5126);
        let ty = original["type"].as_str().unwrap_or("SCALAR").to_string();
        let source = inst.source_vertices();
        let kind = AttributeKind::of(name, ct, original["normalized"].as_bool());
        let mut data = vec![0u8; stride * am.xref.len()];
        for (k, &x) in am.xref.iter().enumerate() {
            let out = &mut data[k * stride..k * stride + elem];
            match (x as usize).checked_sub(source) {
                None => out.copy_from_slice(&bytes[x as usize * elem..(x as usize + 1) * elem]),
                Some(d) => {
                    interpolate(
                        &bytes,
                        elem,
                        ct,
                        components(&ty),
                        kind,
                        &inst.derived[d],
                        out,
                    );
                }
            }
        }
        if inst.side == Side::Back {
            // The back side faces the other way: its normals are negated, and its tangents'
            // handedness (w) too, so the bitangent, and so the normal map, stays as it was.
            let flip: &[usize] = match name.as_str() {
                "NORMAL" => &[0, 1, 2],
                "TANGENT" => &[3],
                _ => &[],
            };
            negate_components(&mut data, stride, elem, ct, flip);
        }
        let view = push_view(
            root,
            bin,
            &data,
            (stride != elem).then_some(stride),
            Some(ARRAY_BUFFER),
        );
        let mut new = json!({
            "bufferView": view,
            "componentType": ct,
            "count": am.xref.len(),
            "type": ty,
        });
        if original["normalized"].as_bool() == Some(true) {
            new["normalized"] = json!(true);
        }
        if let Some(n) = original.get("name") {
            new["name"] = n.clone();
        }
        if original.get("min").is_some() || name == "POSITION" {
            let nc = components(&ty);
            let cs = elem / nc;
            let mut lo = vec![f64::INFINITY; nc];
            let mut hi = vec![f64::NEG_INFINITY; nc];
            for k in 0..am.xref.len() {
                for c in 0..nc {
                    let at = k * stride + c * cs;
                    let v = component_value(ct, &data[at..at + cs]);
                    lo[c] = lo[c].min(v);
                    hi[c] = hi[c].max(v);
                }
            }
            new["min"] = Value::Array(lo.iter().map(|&x| number(ct, x)).collect());
            new["max"] = Value::Array(hi.iter().map(|&x| number(ct, x)).collect());
        }
        new_attributes.insert(name.to_string(), json!(push_accessor(root, new)));
    }
    // Lightmap UVs, normalised to [0,1].
    let (w, h) = (atlas.width as f32, atlas.height as f32);
    let mut uv_bytes = Vec::with_capacity(am.uv.len() * 8);
    let (mut lo, mut hi) = ([f32::INFINITY; 2], [f32::NEG_INFINITY; 2]);
    for uv in &am.uv {
        let n = [uv[0] / w, uv[1] / h];
        for c in 0..2 {
            lo[c] = lo[c].min(n[c]);
            hi[c] = hi[c].max(n[c]);
            uv_bytes.extend_from_slice(&n[c].to_le_bytes());
        }
    }
    let view = push_view(root, bin, &uv_bytes, None, Some(ARRAY_BUFFER));
    let uv_acc = push_accessor(
        root,
        json!({"bufferView": view, "componentType": 5126, "count": am.uv.len(), "type": "VEC2",
               "min": lo, "max": hi, "name": "lightmap UV"}),
    );
    new_attributes.insert("TEXCOORD_1".into(), json!(uv_acc));
    if !new_attributes.contains_key("TEXCOORD_0") {
        // glTF requires TEXCOORD_0 when TEXCOORD_1 is present; the lightmap UVs serve.
        new_attributes.insert("TEXCOORD_0".into(), json!(uv_acc));
    }
    // Indices: the atlas triangles, in the original glTF winding (reversed for a back side:
    // its instance's triangles are, and the mirroring swap is undone the same way).
    let mut indices = am.indices.clone();
    if inst.mirrored {
        for t in indices.chunks_exact_mut(3) {
            t.swap(1, 2);
        }
    }
    let (ct, bytes): (u64, Vec<u8>) = if am.xref.len() <= u16::MAX as usize {
        (
            5123,
            indices
                .iter()
                .flat_map(|&i| (i as u16).to_le_bytes())
                .collect(),
        )
    } else {
        (
            5125,
            indices.iter().flat_map(|&i| i.to_le_bytes()).collect(),
        )
    };
    let view = push_view(root, bin, &bytes, None, Some(ELEMENT_ARRAY_BUFFER));
    let idx_acc = push_accessor(
        root,
        json!({"bufferView": view, "componentType": ct, "count": indices.len(), "type": "SCALAR"}),
    );
    prim["attributes"] = Value::Object(new_attributes);
    prim["indices"] = json!(idx_acc);
    if let Some(obj) = prim.as_object_mut() {
        obj.remove("mode"); // strips and fans are now a triangle list (the default mode)
    }
    Ok(())
}

/// Negates components `which` of every element (`elem` bytes, every `stride` bytes) of
/// component type `ct`: floats and signed normalized integers (other types are left alone;
/// glTF stores normals and tangents only as those).
fn negate_components(data: &mut [u8], stride: usize, elem: usize, ct: u64, which: &[usize]) {
    let size = match ct {
        5126 => 4,
        5122 => 2,
        5120 => 1,
        _ => return,
    };
    for e in data.chunks_exact_mut(stride) {
        for &c in which {
            if (c + 1) * size > elem {
                continue;
            }
            let x = &mut e[c * size..(c + 1) * size];
            match ct {
                5126 => {
                    let v = -f32::from_le_bytes([x[0], x[1], x[2], x[3]]);
                    x.copy_from_slice(&v.to_le_bytes());
                }
                5122 => {
                    let v = i16::from_le_bytes([x[0], x[1]]).saturating_neg();
                    x.copy_from_slice(&v.to_le_bytes());
                }
                _ => x[0] = (x[0] as i8).saturating_neg() as u8,
            }
        }
    }
}

/// How an attribute is carried onto a vertex that [`crate::scene::cut`] added.
#[derive(Clone, Copy, PartialEq)]
enum AttributeKind {
    /// Interpolated, then the xyz part renormalised (`NORMAL`, `TANGENT`: its w, the
    /// handedness, comes from the heaviest corner).
    Direction,
    /// Interpolated (positions, UVs, colours, weights, normalised integers).
    Linear,
    /// Taken from the heaviest corner (`JOINTS_n`, integer ids: a mean means nothing).
    Nearest,
}

impl AttributeKind {
    fn of(name: &str, ct: u64, normalized: Option<bool>) -> AttributeKind {
        if name == "NORMAL" || name == "TANGENT" {
            AttributeKind::Direction
        } else if ct == 5126 || normalized == Some(true) || name.starts_with("WEIGHTS_") {
            AttributeKind::Linear
        } else {
            AttributeKind::Nearest
        }
    }
}

/// Writes into `out` the attribute of a derived vertex: its corners' `elem`-byte elements in
/// `bytes` (`nc` components of type `ct`) combined by its weights as `kind` says.
fn interpolate(
    bytes: &[u8],
    elem: usize,
    ct: u64,
    nc: usize,
    kind: AttributeKind,
    derived: &crate::scene::Derived,
    out: &mut [u8],
) {
    let cs = elem / nc.max(1);
    let value = |v: u32, c: usize| {
        let at = v as usize * elem + c * cs;
        component_value(ct, &bytes[at..at + cs])
    };
    let heaviest = derived
        .weights
        .iter()
        .fold((0, f64::NEG_INFINITY), |best, &(v, w)| {
            if w > best.1 { (v, w) } else { best }
        })
        .0;
    let mut x: Vec<f64> = (0..nc)
        .map(|c| match kind {
            AttributeKind::Nearest => value(heaviest, c),
            _ => derived.weights.iter().map(|&(v, w)| w * value(v, c)).sum(),
        })
        .collect();
    if kind == AttributeKind::Direction {
        let n = x.iter().take(3).map(|a| a * a).sum::<f64>().sqrt();
        if n > 0.0 {
            x.iter_mut().take(3).for_each(|a| *a /= n);
        }
        if nc == 4 {
            x[3] = value(heaviest, 3);
        }
    }
    for (c, v) in x.into_iter().enumerate() {
        let o = &mut out[c * cs..(c + 1) * cs];
        match ct {
            5120 => o[0] = (v.round() as i8) as u8,
            5121 => o[0] = v.round() as u8,
            5122 => o.copy_from_slice(&(v.round() as i16).to_le_bytes()),
            5123 => o.copy_from_slice(&(v.round() as u16).to_le_bytes()),
            5125 => o.copy_from_slice(&(v.round() as u32).to_le_bytes()),
            _ => o.copy_from_slice(&(v as f32).to_le_bytes()),
        }
    }
}

/// True when some texture reference in `v` (an object with `index` and `texCoord`) uses set
/// `set`.
fn references_tex_coord(v: &Value, set: u64) -> bool {
    match v {
        Value::Object(o) => {
            o.get("texCoord").and_then(Value::as_u64) == Some(set) && o.contains_key("index")
                || o.values().any(|x| references_tex_coord(x, set))
        }
        Value::Array(a) => a.iter().any(|x| references_tex_coord(x, set)),
        _ => false,
    }
}

/// Rewrites every texture reference (and `KHR_texture_transform` override) using set `from` to
/// set `to`.
fn retarget_tex_coord(v: &mut Value, from: u64, to: u32) {
    match v {
        Value::Object(o) => {
            if o.get("texCoord").and_then(Value::as_u64) == Some(from) {
                o.insert("texCoord".into(), json!(to));
            }
            for x in o.values_mut() {
                retarget_tex_coord(x, from, to);
            }
        }
        Value::Array(a) => a.iter_mut().for_each(|x| retarget_tex_coord(x, from, to)),
        _ => {}
    }
}

/// glb magic `glTF`, as a little-endian word.
pub(crate) const GLB_MAGIC: u32 = 0x4654_6C67;
/// glb chunk type `JSON`.
pub(crate) const CHUNK_JSON: u32 = 0x4E4F_534A;
/// glb chunk type `BIN\0`.
pub(crate) const CHUNK_BIN: u32 = 0x004E_4942;

/// Assembles a glb container (glTF 2.0, binary): the 12-byte header (magic, version 2, total
/// length), the JSON chunk padded with spaces to a multiple of 4 bytes, then, unless `bin` is
/// empty, the BIN chunk padded with zeros to a multiple of 4 bytes. An error when the whole is
/// over 4 GiB, the most the header's 32-bit length can say.
pub fn to_glb(root: &Value, mut bin: Vec<u8>) -> Result<Vec<u8>> {
    let mut json = serde_json::to_vec(root).expect("a serde_json::Value always serializes");
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let total = glb_length(json.len(), bin.len())?;
    let mut out = Vec::with_capacity(total as usize);
    // The chunk lengths fit: each is below the total.
    for word in [GLB_MAGIC, 2, total, json.len() as u32, CHUNK_JSON] {
        out.extend_from_slice(&word.to_le_bytes());
    }
    out.extend_from_slice(&json);
    if !bin.is_empty() {
        out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
        out.extend_from_slice(&CHUNK_BIN.to_le_bytes());
        out.extend_from_slice(&bin);
    }
    Ok(out)
}

/// The total length of a glb with padded chunks of `json` and `bin` bytes (no BIN chunk when
/// `bin` is 0): header 12, chunk headers 8 each. An error when it does not fit the header's
/// 32 bits.
fn glb_length(json: usize, bin: usize) -> Result<u32> {
    let bin_chunk = if bin == 0 {
        Some(0)
    } else {
        bin.checked_add(8)
    };
    bin_chunk
        .and_then(|b| json.checked_add(12 + 8)?.checked_add(b))
        .and_then(|total| u32::try_from(total).ok())
        .ok_or_else(|| Error::Output {
            what: "glb",
            reason: format!(
                "{json} bytes of JSON and {bin} of binary data are more than the 4 GiB a glb \
                 can hold (its header counts the length in 32 bits)"
            ),
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn glb_has_its_header_and_padded_chunks() {
        let glb = to_glb(&json!({"asset": {"version": "2.0"}}), vec![1, 2, 3]).unwrap();
        let word = |at: usize| u32::from_le_bytes(glb[at..at + 4].try_into().unwrap());
        assert_eq!(&glb[0..4], b"glTF");
        assert_eq!(
            (word(0), word(4), word(8) as usize),
            (GLB_MAGIC, 2, glb.len())
        );
        let json_len = word(12) as usize;
        assert!(json_len.is_multiple_of(4));
        assert_eq!(word(16), CHUNK_JSON);
        let bin_at = 20 + json_len;
        assert_eq!((word(bin_at), word(bin_at + 4)), (4, CHUNK_BIN));
        assert_eq!(&glb[bin_at + 8..], &[1, 2, 3, 0]);
        // No BIN chunk without binary data.
        let glb = to_glb(&json!({}), Vec::new()).unwrap();
        assert_eq!((glb.len(), &glb[20..]), (24, &b"{}  "[..]));
    }

    #[test]
    fn glb_length_counts_the_headers_and_refuses_what_32_bits_cannot_say() {
        assert_eq!(glb_length(8, 0).unwrap(), 28);
        assert_eq!(glb_length(8, 4).unwrap(), 40);
        // The largest glb: 12 + 8 + json + 8 + bin = u32::MAX.
        let json = u32::MAX as usize - 12 - 8 - 8 - 4;
        assert_eq!(glb_length(json, 4).unwrap(), u32::MAX);
        assert_eq!(glb_length(u32::MAX as usize - 20, 0).unwrap(), u32::MAX);
        let over = [
            (json + 1, 4),
            (u32::MAX as usize - 19, 0),
            (4, u32::MAX as usize),
            (usize::MAX - 4, 4),
            (4, usize::MAX),
        ];
        for (json, bin) in over {
            let e = glb_length(json, bin).unwrap_err().to_string();
            assert!(e.contains("4 GiB"), "{json} + {bin}: {e}");
        }
    }
}
