//! One mesh primitive placed by a node: its triangles in world space, its vertex colours and
//! texture coordinates, its emissive texture's split, added to the scene as an instance (and
//! its back side for a double-sided material).

use super::*;

/// What the node walk carries from one primitive to the next.
pub(super) struct Walk {
    /// The index of the glTF default material in [`Scene::materials`].
    pub(super) default_material: usize,
    /// Per (mesh, primitive) with a varying emissive texture: how its triangles split.
    pub(super) emission_plans: std::collections::BTreeMap<(usize, usize), Option<emission::Plan>>,
    /// Whether emitters with an emissive texture are split where it changes.
    pub(super) split_emission: bool,
}

pub(super) fn add_primitive(
    gltf: &Gltf,
    scene: &mut Scene,
    (node, gpu_instance): (usize, Option<u32>),
    mesh: &gltf::Mesh,
    prim: &gltf::Primitive,
    world: &DMat4,
    walk: &mut Walk,
) -> Result<()> {
    let default_material = walk.default_material;
    let item = format!(
        "mesh {}{} primitive {}",
        mesh.index(),
        name_suffix(mesh.name()),
        prim.index()
    );
    let mode = prim.mode();
    if !matches!(
        mode,
        Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
    ) {
        scene
            .warnings
            .push(format!("{item}: {mode:?} primitives are skipped"));
        return Ok(());
    }
    let pos_acc = prim
        .get(&gltf::Semantic::Positions)
        .ok_or_else(|| gltf.bad(&item, "has no POSITION attribute"))?;
    let flat = gltf
        .read_floats(&pos_acc, Dimensions::Vec3)
        .map_err(|e| e.within(&format!("{item}: POSITION")))?;
    let vertex_count = flat.len() / 3;
    for (semantic, acc) in prim.attributes() {
        if acc.count() != vertex_count {
            return Err(gltf.bad(
                &item,
                format!(
                    "attribute {} (accessor {}) has {} elements but POSITION has {vertex_count}",
                    semantic.to_string(),
                    acc.index(),
                    acc.count()
                ),
            ));
        }
    }
    let normal_from_local = DMat3::from_mat4(*world);
    let mirrored = normal_from_local.determinant() < 0.0;
    let mut positions_world = Vec::with_capacity(vertex_count);
    for (i, c) in flat.chunks_exact(3).enumerate() {
        let p = DVec3::new(c[0], c[1], c[2]);
        if !p.is_finite() {
            return Err(gltf.bad(
                &item,
                format!(
                    "POSITION (accessor {}) vertex {i} is not finite: {p}",
                    pos_acc.index()
                ),
            ));
        }
        let w = world.transform_point3(p);
        if !w.is_finite() {
            return Err(gltf.bad(&item, format!("vertex {i} overflows in world space")));
        }
        positions_world.push(w);
    }
    let raw: Vec<u32> = match prim.indices() {
        Some(acc) => gltf
            .read_indices(&acc)
            .map_err(|e| e.within(&format!("{item}: indices")))?,
        None => (0..vertex_count as u32).collect(),
    };
    if let Some(&bad) = raw.iter().find(|&&i| i as usize >= vertex_count) {
        return Err(gltf.bad(
            &item,
            format!("index {bad} is out of range ({vertex_count} vertices)"),
        ));
    }
    let mut indices = triangle_list(mode, &raw);
    if mirrored {
        for t in indices.chunks_exact_mut(3) {
            t.swap(1, 2);
        }
    }
    if indices.is_empty() {
        scene.warnings.push(format!("{item}: no triangles"));
        return Ok(());
    }
    let material = prim.material().index().unwrap_or(default_material);
    let colours = vertex_colours(gltf, prim, &item)?;
    let uvs = texture_coordinates(gltf, scene, prim, material, &item)?;
    let front = Instance {
        node,
        gpu_instance,
        mesh: mesh.index(),
        primitive: prim.index(),
        gltf_material: prim.material().index(),
        positions_world,
        indices,
        mirrored,
        side: Side::Front,
        first_triangle: 0,
        derived: Vec::new(),
        colours,
        material,
        uvs,
        emission: None,
    };
    // A double-sided material: the back is a second instance right after the front, its
    // winding reversed, so both sides receive, reflect (and emit) light. Not for a closed
    // surface: its back is inside the volume (and a box's bottom would lie face up on the
    // floor it stands on, a duplicate of the floor).
    let mut front = front;
    if let Some((radiance, texture)) = scene.materials[material]
        .base
        .as_ref()
        .and_then(|b| b.emission.clone())
        .filter(|_| walk.split_emission)
    {
        // One plan per primitive, whatever places it.
        let plan = walk
            .emission_plans
            .entry((mesh.index(), prim.index()))
            .or_insert_with(|| {
                emission::plan(&front, radiance, &texture, &scene.images[texture.image])
            });
        if let Some(plan) = plan {
            emission::apply(&mut front, plan);
        }
    }
    let back = (prim.material().double_sided() && !front.is_closed()).then(|| front.back_side());
    scene.add_instance(front, material);
    if let Some(back) = back {
        scene.add_instance(back, material);
    }
    Ok(())
}

/// The `TEXCOORD_n` sets that `material`'s textures read (base colour, emission), per vertex.
/// A set the primitive lacks is left out, with a warning: the texture's mean colour stands
/// for it.
fn texture_coordinates(
    gltf: &Gltf,
    scene: &mut Scene,
    prim: &gltf::Primitive,
    material: usize,
    item: &str,
) -> Result<std::collections::BTreeMap<u32, Vec<DVec2>>> {
    let mut sets = std::collections::BTreeMap::new();
    let Some(base) = scene.materials[material].base.as_ref() else {
        return Ok(sets);
    };
    let wanted: Vec<u32> = [
        base.texture.as_ref(),
        base.emission.as_ref().map(|e| &e.1),
        base.transmission_texture.as_ref(),
    ]
    .into_iter()
    .flatten()
    .map(|t| t.tex_coord)
    .collect();
    for n in wanted {
        if sets.contains_key(&n) {
            continue;
        }
        let Some(acc) = prim.get(&gltf::Semantic::TexCoords(n)) else {
            scene.warnings.push(format!(
                "{item}: its material's texture reads TEXCOORD_{n}, which it does not have; \
                 the texture's mean colour stands for it"
            ));
            continue;
        };
        let values = gltf
            .read_floats(&acc, Dimensions::Vec2)
            .map_err(|e| e.within(&format!("{item}: TEXCOORD_{n}")))?;
        let uvs: Vec<DVec2> = values
            .chunks_exact(2)
            .map(|c| DVec2::new(c[0], c[1]))
            .collect();
        if let Some(bad) = uvs.iter().find(|c| !c.is_finite()) {
            return Err(gltf.bad(item, format!("TEXCOORD_{n} holds {bad}, not a coordinate")));
        }
        sets.insert(n, uvs);
    }
    Ok(sets)
}

/// A primitive's `COLOR_0` as linear RGB per vertex (glTF stores vertex colours linear; alpha
/// is left out), or `None` without one.
fn vertex_colours(gltf: &Gltf, prim: &gltf::Primitive, item: &str) -> Result<Option<Vec<DVec3>>> {
    let Some(acc) = prim.get(&gltf::Semantic::Colors(0)) else {
        return Ok(None);
    };
    let dims = acc.dimensions();
    let n = match dims {
        Dimensions::Vec3 => 3,
        Dimensions::Vec4 => 4,
        _ => return Err(gltf.bad(item, format!("COLOR_0 is {dims:?}, not VEC3 or VEC4"))),
    };
    let values = gltf
        .read_floats(&acc, dims)
        .map_err(|e| e.within(&format!("{item}: COLOR_0")))?;
    let colours: Vec<DVec3> = values
        .chunks_exact(n)
        .map(|c| DVec3::new(c[0], c[1], c[2]))
        .collect();
    if let Some(bad) = colours
        .iter()
        .find(|c| !c.is_finite() || c.min_element() < 0.0)
    {
        return Err(gltf.bad(item, format!("COLOR_0 holds {bad}, not a colour")));
    }
    Ok(Some(colours))
}

/// The most triangles a primitive can hold, from its accessors' counts (before reading them).
pub(super) fn triangles_at_most(prim: &gltf::Primitive) -> usize {
    let count = match prim.indices() {
        Some(acc) => acc.count(),
        None => prim
            .get(&gltf::Semantic::Positions)
            .map_or(0, |acc| acc.count()),
    };
    match prim.mode() {
        Mode::Triangles => count / 3,
        Mode::TriangleStrip | Mode::TriangleFan => count.saturating_sub(2),
        _ => 0,
    }
}

/// Expands strips and fans into a triangle list (glTF winding rules).
fn triangle_list(mode: Mode, raw: &[u32]) -> Vec<u32> {
    let mut out = Vec::new();
    match mode {
        Mode::Triangles => {
            for t in raw.chunks_exact(3) {
                out.extend_from_slice(t);
            }
        }
        Mode::TriangleStrip => {
            for i in 0..raw.len().saturating_sub(2) {
                if i % 2 == 0 {
                    out.extend_from_slice(&[raw[i], raw[i + 1], raw[i + 2]]);
                } else {
                    out.extend_from_slice(&[raw[i + 1], raw[i], raw[i + 2]]);
                }
            }
        }
        Mode::TriangleFan => {
            for i in 1..raw.len().saturating_sub(1) {
                out.extend_from_slice(&[raw[0], raw[i], raw[i + 1]]);
            }
        }
        _ => {}
    }
    out
}
