//! Reading glTF: the file, its buffers, and the static scene the baker works on.
//!
//! Every accessor is bounds-checked here before it is read, so a truncated or inconsistent file
//! gives an [`Error`] that names the file and the item, never a panic.
//!
//! Which extensions a file may require is decided in [`extensions`], not by the `gltf` crate:
//! quantized attributes, meshopt-compressed views ([`meshopt`]), GPU instances ([`instancing`],
//! each instance a placement of its own) and WebP images are read.
//!
//! A primitive whose material is `doubleSided` becomes two instances: its front, and right
//! after it its back ([`crate::scene::Side::Back`]: the same world positions, every triangle's winding
//! reversed). Both sides then receive, reflect and (if the material emits) emit light as two
//! ordinary one-sided surfaces back to back; the writer gives the back its own primitive. A
//! closed primitive ([`crate::scene::Instance::is_closed`]: a box with all its faces) gets no back: its back
//! is inside the volume, which many exporters mark double-sided by default.

use crate::error::{Error, Result};
use crate::scene::{
    Instance, LightKind, MAX_ALBEDO, Material, PunctualLight, Scene, Side, emission,
};
use base64::Engine;
use glam::{DMat3, DMat4, DVec2, DVec3};
use gltf::accessor::{DataType, Dimensions};
use gltf::mesh::Mode;
use std::path::{Path, PathBuf};

pub(crate) mod extensions;
pub(crate) mod instancing;
mod limits;
mod materials;
pub(crate) mod meshopt;
mod primitive;
pub(crate) mod uri;
mod validate;

pub use limits::{
    DEFAULT_IMAGE_MIB, DEFAULT_IMAGE_SIDE, DEFAULT_INPUT_MIB, DEFAULT_INSTANCES, DEFAULT_NODES,
    DEFAULT_POLYGONS, DEFAULT_PRIMITIVES, DEFAULT_TRIANGLES, Limits, MIB,
};
use materials::{Textures, material};
use primitive::{Walk, add_primitive, triangles_at_most};

/// What the loader is told: the resource limits, and the folders besides the input's own that
/// its URIs may name files in.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct LoadOptions {
    pub limits: Limits,
    /// Folders whose files a URI may name besides the input's own folder (`--allow-outside
    /// DIR`); see [`uri`].
    pub allow_outside: Vec<PathBuf>,
}

/// A parsed glTF file with its buffer data, kept whole so the writer can preserve everything.
pub struct Gltf {
    /// The file it came from (for messages and relative URIs).
    pub(crate) path: PathBuf,
    /// The parsed document.
    pub document: gltf::Document,
    /// The data of every buffer, in buffer order (the GLB binary chunk, a data URI, or a file;
    /// empty for a meshopt fallback buffer).
    pub buffers: Vec<Vec<u8>>,
    /// Per buffer view, its decoded bytes when it is meshopt-compressed ([`meshopt`]).
    pub(crate) decoded_views: Vec<Option<Vec<u8>>>,
    /// The JSON as written in the file, key order kept: the writer edits this, so everything it
    /// does not touch (extensions, extras, unknown properties) survives as it was.
    pub json: serde_json::Value,
    /// The limits and folders it was read with; its images are read and decoded with them too.
    pub(crate) options: LoadOptions,
}

/// Reads and parses a `.glb` or `.gltf` file and all of its buffers, with the default
/// [`LoadOptions`].
pub fn read(path: &Path) -> Result<Gltf> {
    read_with(path, &LoadOptions::default())
}

/// Reads and parses a `.glb` or `.gltf` file and all of its buffers, at most
/// [`Limits::input_bytes`] from each file.
pub fn read_with(path: &Path, options: &LoadOptions) -> Result<Gltf> {
    let file = std::fs::File::open(path).map_err(|source| Error::Read {
        path: path.to_path_buf(),
        source,
    })?;
    let bytes = uri::read_limited(file, options.limits.input_bytes, "--max-input-mib", path)
        .map_err(|reason| Error::Read {
            path: path.to_path_buf(),
            source: std::io::Error::other(reason),
        })?;
    from_bytes_with(bytes, path, options)
}

/// Parses glTF bytes with the default [`LoadOptions`]; `path` names the file in messages and
/// anchors relative URIs.
pub fn from_bytes(bytes: Vec<u8>, path: &Path) -> Result<Gltf> {
    from_bytes_with(bytes, path, &LoadOptions::default())
}

/// Parses glTF bytes; `path` names the file in messages and anchors relative URIs, which may
/// name files only in its folder and `options.allow_outside` ([`uri`]).
pub(crate) fn from_bytes_with(bytes: Vec<u8>, path: &Path, options: &LoadOptions) -> Result<Gltf> {
    let not_gltf = |reason: String| Error::NotGltf {
        path: path.to_path_buf(),
        reason,
    };
    if bytes.is_empty() {
        return Err(not_gltf("the file is empty".into()));
    }
    // The JSON first, checked where the gltf crate would panic (see `validate`).
    let (json_bytes, mut blob) = if bytes.starts_with(b"glTF") {
        let glb = gltf::binary::Glb::from_slice(&bytes).map_err(|e| not_gltf(e.to_string()))?;
        (glb.json.into_owned(), glb.bin.map(|b| b.into_owned()))
    } else {
        (bytes.clone(), None)
    };
    let json: serde_json::Value =
        serde_json::from_slice(&json_bytes).map_err(|e| not_gltf(e.to_string()))?;
    if !json.is_object() {
        // The writer edits this object in place.
        return Err(not_gltf("the JSON root is not an object".into()));
    }
    let invalid = |e: validate::Invalid| Error::BadItem {
        path: path.to_path_buf(),
        item: e.item,
        reason: e.reason,
    };
    validate::check(&json).map_err(invalid)?;
    limits::check_counts(&json, &options.limits).map_err(invalid)?;
    extensions::check_required(&json).map_err(invalid)?;
    let root: gltf::json::Root = serde_json::from_value(extensions::for_parsing(&json))
        .map_err(|e| not_gltf(e.to_string()))?;
    let document = gltf::Document::from_json(root).map_err(|e| not_gltf(e.to_string()))?;
    let mut buffers = Vec::new();
    // What the input and its buffer files hold together: each file is read within the limit
    // that is left.
    let mut total = bytes.len() as u64;
    for buffer in document.buffers() {
        let item = format!("buffer {}", buffer.index());
        if meshopt::is_fallback(&json["buffers"][buffer.index()]) {
            // Its bytes are only in the compressed views that name it.
            buffers.push(Vec::new());
            continue;
        }
        let data = match buffer.source() {
            gltf::buffer::Source::Bin => blob.take().ok_or_else(|| Error::BadItem {
                path: path.to_path_buf(),
                item: item.clone(),
                reason: "refers to the GLB binary chunk, which is missing".into(),
            })?,
            gltf::buffer::Source::Uri(uri) => {
                let left = LoadOptions {
                    limits: Limits {
                        input_bytes: options.limits.input_bytes.saturating_sub(total),
                        ..options.limits.clone()
                    },
                    allow_outside: options.allow_outside.clone(),
                };
                let data = read_uri(path, uri, &item, &left)?;
                total += data.len() as u64;
                data
            }
        };
        if data.len() < buffer.length() {
            return Err(Error::BadItem {
                path: path.to_path_buf(),
                item,
                reason: format!(
                    "is truncated: byteLength is {} but only {} bytes are present",
                    buffer.length(),
                    data.len()
                ),
            });
        }
        buffers.push(data);
    }
    let decoded_views =
        meshopt::decode_views(&json, &buffers, options.limits.input_bytes).map_err(invalid)?;
    Ok(Gltf {
        path: path.to_path_buf(),
        document,
        buffers,
        decoded_views,
        json,
        options: options.clone(),
    })
}

/// Reads the bytes behind a URI: a base64 data URI, or a regular file relative to the glTF
/// file, inside its folder or `options.allow_outside` ([`uri`]), of at most
/// [`Limits::input_bytes`].
pub(crate) fn read_uri(
    gltf_path: &Path,
    uri: &str,
    item: &str,
    options: &LoadOptions,
) -> Result<Vec<u8>> {
    if let Some(rest) = uri.strip_prefix("data:") {
        let (_, payload) = rest.split_once(";base64,").ok_or_else(|| Error::BadItem {
            path: gltf_path.to_path_buf(),
            item: item.to_string(),
            reason: "data URI is not base64".into(),
        })?;
        return base64::engine::general_purpose::STANDARD
            .decode(payload)
            .map_err(|e| Error::BadItem {
                path: gltf_path.to_path_buf(),
                item: item.to_string(),
                reason: format!("bad base64 in data URI: {e}"),
            });
    }
    let decoded = percent_decode(uri);
    let refuse = |reason: String| Error::BadItem {
        path: gltf_path.to_path_buf(),
        item: item.to_string(),
        reason: format!("URI {uri:?} {reason}"),
    };
    let confinement = uri::Confinement {
        allow: &options.allow_outside,
    };
    let file = confinement.resolve(gltf_path, &decoded).map_err(refuse)?;
    let handle = uri::open_regular(&file).map_err(refuse)?;
    uri::read_limited(handle, options.limits.input_bytes, "--max-input-mib", &file).map_err(refuse)
}

fn percent_decode(uri: &str) -> String {
    let bytes = uri.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%'
            && i + 2 < bytes.len()
            && let Ok(v) = u8::from_str_radix(&uri[i + 1..i + 3], 16)
        {
            out.push(v);
            i += 3;
            continue;
        }
        out.push(bytes[i]);
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

impl Gltf {
    /// The bytes behind one of this file's URIs ([`read_uri`] with the options it was read
    /// with).
    pub(crate) fn uri_bytes(&self, uri: &str, item: &str) -> Result<Vec<u8>> {
        read_uri(&self.path, uri, item, &self.options)
    }

    /// Decodes an image within [`Limits::image_side`] and [`Limits::image_bytes`]: `Ok(Err)`
    /// says why it cannot be decoded (not an image, a format not built in), an error naming
    /// `item` that it is past a limit.
    pub(crate) fn decode_image(
        &self,
        bytes: &[u8],
        item: &str,
    ) -> Result<std::result::Result<image::DynamicImage, String>> {
        limits::decode_image(bytes, &self.options.limits).map_err(|reason| self.bad(item, reason))
    }

    /// Every file a bake of this glTF reads: the file itself, and the external buffers and
    /// images its URIs name (an output must be none of them).
    pub fn files_read(&self) -> Vec<PathBuf> {
        let dir = self.path.parent().unwrap_or_else(|| Path::new("."));
        let buffers = self.document.buffers().filter_map(|b| match b.source() {
            gltf::buffer::Source::Uri(uri) => Some(uri.to_string()),
            gltf::buffer::Source::Bin => None,
        });
        let images = self.document.images().filter_map(|i| match i.source() {
            gltf::image::Source::Uri { uri, .. } => Some(uri.to_string()),
            gltf::image::Source::View { .. } => None,
        });
        let mut files = vec![self.path.clone()];
        for uri in buffers.chain(images) {
            if !uri.starts_with("data:") {
                files.push(dir.join(percent_decode(&uri)));
            }
        }
        files
    }

    internal! {
        /// Names an instance's glTF item: `mesh 2 "chair" primitive 0 (node 7)`, or
        /// `mesh 2 "chair" primitive 0 (back side) (node 7)` for the back of a double-sided one.
        pub fn instance_item(&self, instance: &Instance) -> String {
            let name = self
                .document
                .meshes()
                .nth(instance.mesh)
                .and_then(|m| m.name().map(|n| format!(" \"{n}\"")))
                .unwrap_or_default();
            let side = match instance.side {
                Side::Front => "",
                Side::Back => " (back side)",
            };
            format!(
                "mesh {}{name} primitive {}{side} (node {})",
                instance.mesh, instance.primitive, instance.node
            )
        }
    }

    fn bad(&self, item: impl Into<String>, reason: impl Into<String>) -> Error {
        Error::BadItem {
            path: self.path.clone(),
            item: item.into(),
            reason: reason.into(),
        }
    }

    /// The bytes of a buffer view, checked against its buffer.
    pub(crate) fn view_bytes(&self, view: &gltf::buffer::View, item: &str) -> Result<&[u8]> {
        if let Some(Some(decoded)) = self.decoded_views.get(view.index()) {
            return Ok(decoded);
        }
        let data = &self.buffers[view.buffer().index()];
        let end = view.offset().checked_add(view.length());
        match end {
            Some(end) if end <= data.len() => Ok(&data[view.offset()..end]),
            _ => Err(self.bad(
                format!("{item}, bufferView {}", view.index()),
                format!(
                    "range {}..{} is outside buffer {} ({} bytes)",
                    view.offset(),
                    view.offset().saturating_add(view.length()),
                    view.buffer().index(),
                    data.len()
                ),
            )),
        }
    }

    /// An accessor's elements, tightly packed (sparse substitution applied), and the size of one
    /// element in bytes.
    pub(crate) fn accessor_bytes(&self, accessor: &gltf::Accessor) -> Result<(Vec<u8>, usize)> {
        let item = format!("accessor {}", accessor.index());
        let elem = accessor.size();
        let count = accessor.count();
        let mut out = match accessor.view() {
            Some(view) => {
                let bytes = self.view_bytes(&view, &item)?;
                let stride = view.stride().unwrap_or(elem);
                // glTF: at most 252 bytes, whole components, and elements that do not overlap.
                let component = accessor.data_type().size();
                if view.stride().is_some()
                    && (stride < elem || stride > 252 || !stride.is_multiple_of(component))
                {
                    return Err(self.bad(
                        format!("{item}, bufferView {}", view.index()),
                        format!(
                            "byteStride {stride} is invalid for {elem}-byte elements (it must be \
                             at least the element size, at most 252, and a multiple of the \
                             {component}-byte component size)"
                        ),
                    ));
                }
                read_strided(bytes, accessor.offset(), stride, elem, count)
                    .ok_or_else(|| self.bad(&item, "elements run past the end of its bufferView"))?
            }
            None => {
                // All zeros (then sparse values): the size is not bounded by any buffer.
                let total = count
                    .checked_mul(elem)
                    .filter(|&t| t <= 1 << 30)
                    .ok_or_else(|| {
                        self.bad(&item, format!("count {count} is implausibly large"))
                    })?;
                vec![0u8; total]
            }
        };
        if let Some(sparse) = accessor.sparse() {
            let n = sparse.count();
            let iv = sparse.indices();
            let isz = iv.index_type().size();
            let ibytes = self.view_bytes(&iv.view(), &format!("{item} sparse indices"))?;
            let idx = read_strided(ibytes, iv.offset(), isz, isz, n)
                .ok_or_else(|| self.bad(&item, "sparse indices run past their bufferView"))?;
            let vv = sparse.values();
            let vbytes = self.view_bytes(&vv.view(), &format!("{item} sparse values"))?;
            let vals = read_strided(vbytes, vv.offset(), elem, elem, n)
                .ok_or_else(|| self.bad(&item, "sparse values run past their bufferView"))?;
            for k in 0..n {
                let i = read_uint(&idx[k * isz..(k + 1) * isz]) as usize;
                if i >= count {
                    return Err(self.bad(&item, format!("sparse index {i} >= count {count}")));
                }
                out[i * elem..(i + 1) * elem].copy_from_slice(&vals[k * elem..(k + 1) * elem]);
            }
        }
        Ok((out, elem))
    }

    /// An accessor of `dims` components as f64, with normalized integers mapped to 0..1 / -1..1.
    pub fn read_floats(&self, accessor: &gltf::Accessor, dims: Dimensions) -> Result<Vec<f64>> {
        let item = format!("accessor {}", accessor.index());
        if accessor.dimensions() != dims {
            return Err(self.bad(
                item,
                format!(
                    "expected {dims:?} elements, found {:?}",
                    accessor.dimensions()
                ),
            ));
        }
        let dt = accessor.data_type();
        // KHR_mesh_quantization: positions, texture coordinates and instance transforms may be
        // integers, normalized or not; the node's transform scales them back.
        let integers = extensions::declares(&self.json, "KHR_mesh_quantization")
            && matches!(
                dt,
                DataType::I8 | DataType::U8 | DataType::I16 | DataType::U16
            );
        if dt != DataType::F32 && !accessor.normalized() && !integers {
            return Err(self.bad(
                item,
                format!(
                    "expected float or normalized components, found {dt:?} (integer attributes \
                     need KHR_mesh_quantization)"
                ),
            ));
        }
        let (bytes, elem) = self.accessor_bytes(accessor)?;
        let size = dt.size();
        let n = dims.multiplicity();
        let scale = |max: f64| if accessor.normalized() { max } else { 1.0 };
        // `accessor_bytes` packs the elements tightly (a view's stride pads an 8- or 16-bit
        // VEC3 to 4 bytes; the element itself is not padded).
        Ok(bytes
            .chunks_exact(elem)
            .flat_map(|e| e[..n * size].chunks_exact(size))
            .map(|c| match dt {
                DataType::F32 => f32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f64,
                DataType::U8 => c[0] as f64 / scale(255.0),
                DataType::I8 => (c[0] as i8 as f64 / scale(127.0)).max(-scale(1.0)),
                DataType::U16 => u16::from_le_bytes([c[0], c[1]]) as f64 / scale(65535.0),
                DataType::I16 => {
                    (i16::from_le_bytes([c[0], c[1]]) as f64 / scale(32767.0)).max(-scale(1.0))
                }
                DataType::U32 => u32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f64,
            })
            .collect())
    }

    /// An index accessor as u32 values.
    pub fn read_indices(&self, accessor: &gltf::Accessor) -> Result<Vec<u32>> {
        let item = format!("accessor {}", accessor.index());
        if accessor.dimensions() != Dimensions::Scalar
            || !matches!(
                accessor.data_type(),
                DataType::U8 | DataType::U16 | DataType::U32
            )
        {
            return Err(self.bad(item, "indices must be unsigned byte, short or int scalars"));
        }
        let (bytes, elem) = self.accessor_bytes(accessor)?;
        Ok(bytes.chunks_exact(elem).map(read_uint).collect())
    }
}

fn read_uint(c: &[u8]) -> u32 {
    match c.len() {
        1 => c[0] as u32,
        2 => u16::from_le_bytes([c[0], c[1]]) as u32,
        _ => u32::from_le_bytes([c[0], c[1], c[2], c[3]]),
    }
}

/// The `count` elements of `elem` bytes at `offset + k * stride`, tightly packed; `None` when
/// the source is too short (checked before anything is allocated).
fn read_strided(
    src: &[u8],
    offset: usize,
    stride: usize,
    elem: usize,
    count: usize,
) -> Option<Vec<u8>> {
    if count == 0 {
        return Some(Vec::new());
    }
    let last = offset.checked_add(stride.checked_mul(count - 1)?)?;
    if last.checked_add(elem)? > src.len() {
        return None;
    }
    let mut out = Vec::with_capacity(count * elem);
    for k in 0..count {
        let s = offset + k * stride;
        out.extend_from_slice(&src[s..s + elem]);
    }
    Some(out)
}

/// Loads the static scene: every node of the default scene (or the first scene), with world
/// transforms, materials, area emitters and punctual lights, within the limits `gltf` was read
/// with.
pub fn scene(gltf: &Gltf) -> Result<Scene> {
    scene_limited(gltf, &gltf.options.limits)
}

/// [`scene`] within `limits`: the instances and the triangles are counted as the node graph is
/// walked, before each primitive's geometry is read.
pub(crate) fn scene_limited(gltf: &Gltf, limits: &Limits) -> Result<Scene> {
    scene_walked(gltf, limits, true)
}

/// [`scene`] with every emissive texture left unsplit: each emitter emits its material's mean
/// radiance, and [`Scene::emission_at`] gives the texture's value at a point. For
/// `penumbra reference`, which reads the emissive texture at its own sample points, apart from
/// the baker's split.
pub(crate) fn scene_unsplit(gltf: &Gltf) -> Result<Scene> {
    scene_walked(gltf, &gltf.options.limits, false)
}

/// [`scene_limited`], splitting the emitters of emissive textures when `split_emission`.
fn scene_walked(gltf: &Gltf, limits: &Limits, split_emission: bool) -> Result<Scene> {
    let doc = &gltf.document;
    let mut scene = Scene::default();
    let mut textures = Textures::default();
    // One baker material per glTF material, plus the glTF default material at the end.
    for m in doc.materials() {
        scene.materials.push(material(gltf, &m, &mut textures)?);
    }
    let default_material = scene.materials.len();
    // glTF's default material is white (base colour 1): as any albedo, clamped.
    scene.materials.push(Material {
        name: "default material".into(),
        rho: DVec3::splat(MAX_ALBEDO),
        radiance: DVec3::ZERO,
        base: None,
    });
    scene.warnings.append(&mut textures.warnings);
    scene.images = std::sync::Arc::new(textures.kept);
    let mut walk = Walk {
        default_material,
        emission_plans: Default::default(),
        split_emission,
    };
    scene.warnings.extend(extensions::warnings(&gltf.json));

    let gscene = match doc.default_scene().or_else(|| doc.scenes().next()) {
        Some(s) => s,
        None => {
            return Err(Error::EmptyScene {
                path: gltf.path.clone(),
            });
        }
    };
    let mut stack: Vec<(gltf::Node, DMat4, usize)> =
        gscene.nodes().map(|n| (n, DMat4::IDENTITY, 0)).collect();
    stack.reverse();
    let mut lights_seen = 0;
    let (mut instances, mut triangles) = (0usize, 0usize);
    // Placements so far, by vertex data, material and world matrix; and the repeats skipped.
    let mut placed = std::collections::HashSet::new();
    let mut duplicates = 0usize;
    let mut visited = vec![false; doc.nodes().len()];
    while let Some((node, parent, depth)) = stack.pop() {
        // glTF node graphs are strict trees: a node reached twice is a cycle or a shared child,
        // which would otherwise multiply the work exponentially.
        if std::mem::replace(&mut visited[node.index()], true) {
            return Err(gltf.bad(
                format!("node {}", node.index()),
                "is reached twice: the node hierarchy is not a tree",
            ));
        }
        if depth > MAX_DEPTH {
            return Err(gltf.bad(
                format!("node {}", node.index()),
                format!("lies deeper than {MAX_DEPTH} levels in the node hierarchy"),
            ));
        }
        let local =
            DMat4::from_cols_array_2d(&node.transform().matrix().map(|c| c.map(|x| x as f64)));
        let world = parent * local;
        if !world.is_finite() {
            return Err(gltf.bad(format!("node {}", node.index()), "transform is not finite"));
        }
        if let Some(light) = node.light() {
            scene
                .lights
                .push(punctual(gltf, &light, &world, lights_seen, node.index())?);
            lights_seen += 1;
        }
        if let Some(mesh) = node.mesh() {
            let morph = mesh.primitives().any(|p| p.morph_targets().len() > 0);
            if node.skin().is_some() || morph {
                scene.warnings.push(format!(
                    "node {} (mesh {}{}) is skinned or morphing: not static, it neither occludes nor receives a lightmap",
                    node.index(),
                    mesh.index(),
                    name_suffix(mesh.name())
                ));
            } else {
                // One placement, or one per GPU instance (`instancing`).
                let placements: Vec<(Option<u32>, DMat4)> =
                    match instancing::instances(gltf, node.index(), limits.instances)? {
                        Some(locals) => (0u32..)
                            .zip(locals)
                            .map(|(k, local)| (Some(k), world * local))
                            .collect(),
                        None => vec![(None, world)],
                    };
                for (gpu_instance, world) in &placements {
                    for prim in mesh.primitives() {
                        instances += 1;
                        triangles = triangles.saturating_add(triangles_at_most(&prim));
                        let item = || {
                            format!(
                                "node {} (mesh {}{} primitive {})",
                                node.index(),
                                mesh.index(),
                                name_suffix(mesh.name()),
                                prim.index()
                            )
                        };
                        if instances > limits.instances {
                            return Err(gltf.bad(
                                item(),
                                format!(
                                    "the scene places more than {} mesh instances (primitives \
                                     placed by nodes; --max-instances raises the limit)",
                                    limits.instances
                                ),
                            ));
                        }
                        if triangles > limits.triangles {
                            return Err(gltf.bad(
                                item(),
                                format!(
                                    "the scene's instances hold more than {} triangles \
                                     (--max-triangles raises the limit)",
                                    limits.triangles
                                ),
                            ));
                        }
                        // The same vertex data and material placed again at the same place
                        // (a copied node or primitive): it would only z-fight with the first,
                        // and each copy would cost a chart and an occluder.
                        let key = (
                            prim.get(&gltf::Semantic::Positions).map(|a| a.index()),
                            prim.indices().map(|a| a.index()),
                            prim.mode() as u32,
                            prim.material().index(),
                            world.to_cols_array().map(f64::to_bits),
                        );
                        if !placed.insert(key) {
                            duplicates += 1;
                            continue;
                        }
                        add_primitive(
                            gltf,
                            &mut scene,
                            (node.index(), *gpu_instance),
                            &mesh,
                            &prim,
                            world,
                            &mut walk,
                        )?;
                    }
                }
            }
        }
        let mut children: Vec<_> = node.children().map(|c| (c, world, depth + 1)).collect();
        children.reverse();
        stack.extend(children);
    }
    if duplicates > 0 {
        scene.warnings.push(format!(
            "{duplicates} primitive placement(s) repeat an earlier one (the same vertex data and \
             material at the same place) and are skipped: they get no lightmap"
        ));
    }
    if scene.triangles.is_empty() {
        return Err(Error::EmptyScene {
            path: gltf.path.clone(),
        });
    }
    if scene.instances.iter().any(|i| i.gltf_material.is_none()) {
        scene.warnings.push(format!(
            "primitives without a material use glTF's default white material, baked with albedo {MAX_ALBEDO}"
        ));
    }
    if scene.polygons.len() > limits.polygons {
        return Err(gltf.bad(
            "scene",
            format!(
                "{} receiver polygons, more than {} (--max-polygons raises the limit)",
                scene.polygons.len(),
                limits.polygons
            ),
        ));
    }
    check_extent(gltf, &scene)?;
    let degenerate = scene
        .triangles
        .iter()
        .filter(|t| t.polygon.is_none() && scene.instances[t.instance].side == Side::Front)
        .count();
    if degenerate > 0 {
        scene.warnings.push(format!(
            "{degenerate} zero-area triangle(s) skipped as receivers and occluders"
        ));
    }
    Ok(scene)
}

/// The deepest a node may lie in the node hierarchy (its root at depth 0).
pub(crate) const MAX_DEPTH: usize = 1024;

/// The largest scene a bake takes, in scene units across (the bounding box diagonal): every
/// tolerance is relative to it, and the lightmap atlas and the BVH work in f32.
pub(crate) const MAX_EXTENT: f64 = 1e9;

/// The smallest scene a bake takes, in scene units across (the bounding box diagonal): the
/// irradiance of a punctual light grows as the inverse square of the scale, past what the f32
/// lightmap holds, and spade's refinement loses precision near f64's smallest numbers. A
/// micrometre-sized scene (1e-6) bakes.
pub(crate) const MIN_EXTENT: f64 = 1e-9;

/// The largest ratio of the scene's extent to its typical (median) triangle. The geometric
/// tolerances of input geometry are 1e-6 of the extent ([`crate::scene::tolerance::INPUT`]); past this ratio most triangles would fall below
/// them and vanish from the bake. A stray vertex far from everything else is the usual cause.
pub(crate) const MAX_EXTENT_RATIO: f64 = 1e6;

/// Refuses scenes whose extent no bake can resolve ([`MIN_EXTENT`], [`MAX_EXTENT`],
/// [`MAX_EXTENT_RATIO`]),
/// naming the vertex farthest from the middle of the scene.
fn check_extent(gltf: &Gltf, scene: &Scene) -> Result<()> {
    let extent = (scene.bounds_max - scene.bounds_min).length();
    let mut sizes: Vec<f64> = scene
        .triangles
        .iter()
        .filter(|t| t.polygon.is_some())
        .map(|t| {
            (0..3)
                .map(|k| (t.p[k] - t.p[(k + 1) % 3]).length())
                .fold(0.0, f64::max)
        })
        .collect();
    if sizes.is_empty() {
        return Ok(()); // nothing to bake: reported as such later
    }
    if extent < MIN_EXTENT {
        let index = gltf
            .document
            .default_scene()
            .or_else(|| gltf.document.scenes().next())
            .map_or(0, |s| s.index());
        return Err(gltf.bad(
            format!("scenes[{index}]"),
            format!(
                "the scene spans {extent:.3e} units, less than a bake resolves (at least \
                 {MIN_EXTENT:e} units across): scale it into practical units, e.g. with a \
                 root node's scale"
            ),
        ));
    }
    let mid = sizes.len() / 2;
    let typical = *sizes.select_nth_unstable_by(mid, f64::total_cmp).1;
    if extent.is_finite() && extent <= MAX_EXTENT && extent <= MAX_EXTENT_RATIO * typical {
        return Ok(());
    }
    // The middle of the scene: the per-axis median of the triangle centroids.
    let mut axes = [Vec::new(), Vec::new(), Vec::new()];
    for t in &scene.triangles {
        let c = (t.p[0] + t.p[1] + t.p[2]) / 3.0;
        for (a, v) in axes.iter_mut().zip(c.to_array()) {
            a.push(v);
        }
    }
    let middle = DVec3::from_array(axes.map(|mut a| {
        let mid = a.len() / 2;
        *a.select_nth_unstable_by(mid, f64::total_cmp).1
    }));
    let mut far = (0, 0, middle, 0.0);
    for (i, inst) in scene.instances.iter().enumerate() {
        for (v, p) in inst.positions_world.iter().enumerate() {
            let d = (*p - middle).length();
            if d > far.3 {
                far = (i, v, *p, d);
            }
        }
    }
    let (i, v, p, d) = far;
    Err(gltf.bad(
        gltf.instance_item(&scene.instances[i]),
        format!(
            "vertex {v} at {} lies {d:.3e} units from the middle of the scene, whose triangles \
             are typically {typical:.3e} units long: the scene would span {extent:.3e} units, \
             beyond what a bake resolves (at most {MAX_EXTENT:e} units, and {MAX_EXTENT_RATIO:e} \
             times its typical triangle)",
            short(p)
        ),
    ))
}

/// A vector for messages: `(1.5, -3.4e38, 0)`, in 4 significant digits.
fn short(v: DVec3) -> String {
    let f = |x: f64| {
        if x != 0.0 && !(1e-3..1e6).contains(&x.abs()) {
            format!("{x:.3e}")
        } else {
            format!("{}", (x * 1e4).round() / 1e4)
        }
    };
    format!("({}, {}, {})", f(v.x), f(v.y), f(v.z))
}

fn name_suffix(name: Option<&str>) -> String {
    name.map(|n| format!(" \"{n}\"")).unwrap_or_default()
}

/// A punctual light placed by a node. Values outside the ranges of `KHR_lights_punctual` are
/// refused, naming the light: an intensity or colour that is negative or not finite, a range
/// that is not positive, spot cone angles outside `0 <= inner < outer <= pi/2`. A colour above
/// 1 is out of the specification's range too, but a well-defined brighter light: it is baked as
/// given.
fn punctual(
    gltf: &Gltf,
    light: &gltf::khr_lights_punctual::Light,
    world: &DMat4,
    n: usize,
    node: usize,
) -> Result<PunctualLight> {
    use gltf::khr_lights_punctual::Kind;
    let item = format!(
        "KHR_lights_punctual.lights[{}]{}",
        light.index(),
        name_suffix(light.name())
    );
    let refuse = |reason: String| Err(gltf.bad(&item, reason));
    let [r, g, b] = light.color();
    if ![r, g, b].iter().all(|c| c.is_finite() && *c >= 0.0) {
        return refuse(format!(
            "color ({r}, {g}, {b}) must be three finite numbers of at least 0"
        ));
    }
    let watts = light.intensity();
    if !(watts.is_finite() && watts >= 0.0) {
        return refuse(format!(
            "intensity {watts} must be a finite number of at least 0"
        ));
    }
    if let Some(range) = light.range()
        && !(range.is_finite() && range > 0.0)
    {
        return refuse(format!(
            "range {range} must be a finite number greater than 0"
        ));
    }
    let color = DVec3::from_array(light.color().map(|c| c as f64));
    let intensity = color * watts as f64;
    let kind = match light.kind() {
        Kind::Point => LightKind::Point,
        Kind::Directional => LightKind::Directional,
        Kind::Spot {
            inner_cone_angle,
            outer_cone_angle,
        } => {
            let (inner, outer) = (inner_cone_angle, outer_cone_angle);
            if !(inner >= 0.0 && inner < outer && outer <= std::f32::consts::FRAC_PI_2) {
                return refuse(format!(
                    "spot innerConeAngle {inner} and outerConeAngle {outer} must satisfy \
                     0 <= innerConeAngle < outerConeAngle <= pi/2 (radians)"
                ));
            }
            LightKind::Spot {
                inner_cone: inner as f64,
                outer_cone: outer as f64,
            }
        }
    };
    Ok(PunctualLight {
        kind,
        name: light
            .name()
            .map(str::to_string)
            .unwrap_or_else(|| format!("light {n}")),
        position: world.transform_point3(DVec3::ZERO),
        direction: world
            .transform_vector3(DVec3::NEG_Z)
            .try_normalize()
            .unwrap_or(DVec3::NEG_Y),
        intensity,
        range: light.range().map(|r| r as f64),
        node,
        index: light.index(),
    })
}
