//! What the loader accepts: external buffers, mirrored nodes, fans, skins, textures.

use crate::output::split_glb;
use crate::{no_progress, parse, quick, scratch};
use glam::DVec3;
use penumbra::fixtures;
use serde_json::{Value, json};

fn edit(bytes: &[u8], f: impl FnOnce(&mut Value, &mut Vec<u8>)) -> Vec<u8> {
    let (mut json, mut bin) = split_glb(bytes);
    f(&mut json, &mut bin);
    if let Some(b) = json["buffers"].get_mut(0) {
        b["byteLength"] = json!(bin.len());
    }
    penumbra::write::to_glb(&json, bin).unwrap()
}

/// Appends `data` to the binary chunk as a new buffer view; returns its index.
fn add_view(json: &mut Value, bin: &mut Vec<u8>, data: &[u8]) -> usize {
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let views = json["bufferViews"].as_array_mut().unwrap();
    views.push(json!({"buffer": 0, "byteOffset": bin.len(), "byteLength": data.len()}));
    bin.extend_from_slice(data);
    views.len() - 1
}

/// Irradiance of every vertex of a bake, with its world position.
pub(crate) fn vertex_values(b: &penumbra::Bake) -> Vec<(DVec3, DVec3)> {
    let mut out = Vec::new();
    for (m, values) in b.meshes.iter().zip(&b.solution.irradiance) {
        let frame = &b.scene.polygons[m.polygon].frame;
        for (v, h) in m.vertices.iter().zip(values) {
            out.push((frame.world_from_plane(*v), *h));
        }
    }
    out
}

#[test]
fn gltf_with_an_external_buffer_bakes_into_a_standalone_glb() {
    let dir = scratch("external-buffer");
    let (mut json, bin) = split_glb(&fixtures::cornell_box());
    json["buffers"][0]["uri"] = json!("cornell%20data.bin");
    std::fs::write(dir.join("cornell data.bin"), &bin).unwrap();
    std::fs::write(dir.join("cornell.gltf"), serde_json::to_vec(&json).unwrap()).unwrap();
    let out = dir.join("out.glb");
    let b = penumbra::bake_file(
        &dir.join("cornell.gltf"),
        &penumbra::OutputFiles::glb(&out),
        &quick(),
        no_progress(),
    )
    .unwrap();
    assert_eq!(b.scene.triangles.len(), fixtures::CORNELL_TRIANGLES);
    let bytes = std::fs::read(&out).unwrap();
    let (oj, _) = split_glb(&bytes);
    assert_eq!(oj["buffers"].as_array().unwrap().len(), 1);
    assert!(
        oj["buffers"][0].get("uri").is_none(),
        "the output must stand alone"
    );
    gltf::Gltf::from_slice(&bytes).expect("valid output");
    // Same light as the glb version of the scene.
    let from_glb = crate::bake(&fixtures::cornell_box(), &quick());
    assert_eq!(from_glb.lightmap.texels, b.lightmap.texels);
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn mirrored_node_keeps_its_front_face_and_winding() {
    let input = edit(&fixtures::point_light(), |json, _| {
        json["nodes"][0]["scale"] = json!([-1.0, 1.0, 1.0]);
    });
    let b = crate::bake(&input, &quick());
    assert!(b.scene.instances[0].mirrored);
    let light = &b.scene.lights[0];
    for (p, h) in vertex_values(&b) {
        let r = (light.position - p).length();
        let expected = light.intensity.x * light.position.y / (r * r * r);
        assert!(
            (h.x / expected - 1.0).abs() < 1e-4,
            "at {p}: {} vs {expected}",
            h.x
        );
    }
    // The written triangles keep the input's winding in the mesh's own frame.
    let dir = scratch("mirrored");
    std::fs::write(dir.join("in.glb"), &input).unwrap();
    penumbra::bake_file(
        &dir.join("in.glb"),
        &penumbra::OutputFiles::glb(dir.join("out.glb")),
        &quick(),
        no_progress(),
    )
    .unwrap();
    let out = parse(&std::fs::read(dir.join("out.glb")).unwrap(), "out.glb");
    let prim = out
        .document
        .meshes()
        .next()
        .unwrap()
        .primitives()
        .next()
        .unwrap();
    let pos = out
        .read_floats(
            &prim.get(&gltf::Semantic::Positions).unwrap(),
            gltf::accessor::Dimensions::Vec3,
        )
        .unwrap();
    let idx = out.read_indices(&prim.indices().unwrap()).unwrap();
    let p = |i: u32| {
        DVec3::new(
            pos[3 * i as usize],
            pos[3 * i as usize + 1],
            pos[3 * i as usize + 2],
        )
    };
    for t in idx.chunks_exact(3) {
        let n = (p(t[1]) - p(t[0])).cross(p(t[2]) - p(t[0]));
        assert!(n.y > 0.0, "local winding flipped: {n}");
    }
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn triangle_fans_are_expanded() {
    let input = edit(&fixtures::plane_uniform(), |json, bin| {
        let data: Vec<u8> = [0u16, 1, 2, 3]
            .iter()
            .flat_map(|i| i.to_le_bytes())
            .collect();
        let view = add_view(json, bin, &data);
        let accessors = json["accessors"].as_array_mut().unwrap();
        accessors
            .push(json!({"bufferView": view, "componentType": 5123, "count": 4, "type": "SCALAR"}));
        let acc = accessors.len() - 1;
        json["meshes"][0]["primitives"][0]["indices"] = json!(acc);
        json["meshes"][0]["primitives"][0]["mode"] = json!(6);
    });
    let b = crate::bake(&input, &quick());
    assert_eq!(b.scene.triangles.len(), 2);
    assert!((b.scene.polygons[0].area - 4.0).abs() < 1e-9);
    assert!(
        vertex_values(&b)
            .iter()
            .all(|(_, h)| (h.x - 1.0).abs() < 1e-9)
    );
}

#[test]
fn skinned_meshes_are_skipped_with_a_warning() {
    let input = edit(&fixtures::box_on_floor(), |json, _| {
        // Turn the first mesh node into a skinned one (joint: the node itself).
        let node = json["nodes"]
            .as_array()
            .unwrap()
            .iter()
            .position(|n| n.get("mesh").is_some())
            .unwrap();
        json["skins"] = json!([{"joints": [node]}]);
        json["nodes"][node]["skin"] = json!(0);
    });
    let all = crate::bake(&fixtures::box_on_floor(), &quick());
    let b = crate::bake(&input, &quick());
    assert!(
        b.stats.warnings.iter().any(|w| w.contains("skinned")),
        "{:?}",
        b.stats.warnings
    );
    assert!(b.scene.instances.len() < all.scene.instances.len());
}

#[test]
fn base_color_texture_mean_scales_the_reflectance() {
    // A 2x2 texture with sRGB values 255 and 128: linear mean (1 + 0.2158605) / 2.
    let mut png = Vec::new();
    {
        use image::ImageEncoder;
        let px: Vec<u8> = [255u8, 128, 255, 128]
            .iter()
            .flat_map(|&v| [v, v, v])
            .collect();
        image::codecs::png::PngEncoder::new(&mut png)
            .write_image(&px, 2, 2, image::ExtendedColorType::Rgb8)
            .unwrap();
    }
    let input = edit(&fixtures::plane_uniform(), |json, bin| {
        let view = add_view(json, bin, &png);
        json["images"] = json!([{"bufferView": view, "mimeType": "image/png"}]);
        json["textures"] = json!([{"source": 0}]);
        json["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = json!({"index": 0});
    });
    let scene = penumbra::load::scene(&parse(&input, "textured.glb")).unwrap();
    let expected = 0.5 * (1.0 + penumbra::color::srgb_to_linear(128.0 / 255.0)) / 2.0;
    assert!(
        (scene.materials[0].rho.x - expected).abs() < 1e-6,
        "{} vs {expected}",
        scene.materials[0].rho.x
    );
}

fn tiny_png() -> Vec<u8> {
    use image::ImageEncoder;
    let mut png = Vec::new();
    image::codecs::png::PngEncoder::new(&mut png)
        .write_image(&[200u8; 12], 2, 2, image::ExtendedColorType::Rgb8)
        .unwrap();
    png
}

#[test]
fn an_existing_texcoord_1_used_by_a_texture_moves_to_a_free_set() {
    let input = edit(&fixtures::plane_uniform(), |json, bin| {
        let uv: Vec<u8> = [0.0f32, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0, 0.0]
            .iter()
            .flat_map(|f| f.to_le_bytes())
            .collect();
        let view = add_view(json, bin, &uv);
        let accessors = json["accessors"].as_array_mut().unwrap();
        accessors
            .push(json!({"bufferView": view, "componentType": 5126, "count": 4, "type": "VEC2"}));
        let acc = accessors.len() - 1;
        json["meshes"][0]["primitives"][0]["attributes"]["TEXCOORD_0"] = json!(acc);
        json["meshes"][0]["primitives"][0]["attributes"]["TEXCOORD_1"] = json!(acc);
        let png = tiny_png();
        let view = add_view(json, bin, &png);
        json["images"] = json!([{"bufferView": view, "mimeType": "image/png"}]);
        json["textures"] = json!([{"source": 0}]);
        json["materials"][0]["occlusionTexture"] = json!({"index": 0, "texCoord": 1});
    });
    let dir = scratch("texcoord1");
    std::fs::write(dir.join("in.glb"), &input).unwrap();
    penumbra::bake_file(
        &dir.join("in.glb"),
        &penumbra::OutputFiles::glb(dir.join("out.glb")),
        &quick(),
        no_progress(),
    )
    .unwrap();
    let out = std::fs::read(dir.join("out.glb")).unwrap();
    gltf::Gltf::from_slice(&out).expect("valid output");
    let (json, _) = split_glb(&out);
    let prim = &json["meshes"][0]["primitives"][0];
    let mat = prim["material"].as_u64().unwrap() as usize;
    assert_eq!(json["materials"][mat]["occlusionTexture"]["texCoord"], 2);
    assert!(prim["attributes"]["TEXCOORD_2"].is_u64(), "{prim}");
    assert_ne!(
        prim["attributes"]["TEXCOORD_1"],
        prim["attributes"]["TEXCOORD_2"]
    );
    assert_eq!(
        json["materials"][mat]["extensions"]["MOZ_lightmap"]["texCoord"],
        1
    );
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn triangle_strips_are_expanded_with_alternating_winding() {
    let input = edit(&fixtures::plane_uniform(), |json, bin| {
        // The quad's corners (CCW from above) as the strip 0,1,3,2: triangles (0,1,3) and, odd,
        // (3,1,2) by glTF's strip rule; both face up.
        let data: Vec<u8> = [0u16, 1, 3, 2]
            .iter()
            .flat_map(|i| i.to_le_bytes())
            .collect();
        let view = add_view(json, bin, &data);
        let accessors = json["accessors"].as_array_mut().unwrap();
        accessors
            .push(json!({"bufferView": view, "componentType": 5123, "count": 4, "type": "SCALAR"}));
        let acc = accessors.len() - 1;
        json["meshes"][0]["primitives"][0]["indices"] = json!(acc);
        json["meshes"][0]["primitives"][0]["mode"] = json!(5);
    });
    let b = crate::bake(&input, &quick());
    assert_eq!(b.scene.triangles.len(), 2);
    assert!(
        b.scene.triangles.iter().all(|t| t.normal.y > 0.99),
        "a strip triangle faces down"
    );
    assert!((b.scene.polygons[0].area - 4.0).abs() < 1e-9);
}

#[test]
fn vertex_colours_tint_each_polygon_by_their_mean_over_it() {
    // The floor (two triangles) with a colour per vertex, as floats.
    let colours: [[f32; 3]; 4] = [
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 1.0],
        [0.5, 0.5, 0.5],
        [0.0, 0.0, 1.0],
    ];
    let input = edit(&fixtures::plane_uniform(), |json, bin| {
        let bytes: Vec<u8> = colours
            .iter()
            .flatten()
            .flat_map(|c| c.to_le_bytes())
            .collect();
        let view = add_view(json, bin, &bytes);
        let accessors = json["accessors"].as_array_mut().unwrap();
        accessors
            .push(json!({"bufferView": view, "componentType": 5126, "count": 4, "type": "VEC3"}));
        let acc = accessors.len() - 1;
        json["meshes"][0]["primitives"][0]["attributes"]["COLOR_0"] = json!(acc);
    });
    let scene = penumbra::load::scene(&parse(&input, "coloured.glb")).unwrap();
    let inst = &scene.instances[0];
    assert_eq!(inst.positions_world.len(), 4, "the floor has four vertices");
    let c = |v: u32| DVec3::from(colours[v as usize].map(|x| x as f64));
    let (mut sum, mut area) = (DVec3::ZERO, 0.0);
    for t in inst.indices.chunks_exact(3) {
        let p: Vec<DVec3> = t
            .iter()
            .map(|&v| inst.positions_world[v as usize])
            .collect();
        let a = 0.5 * (p[1] - p[0]).cross(p[2] - p[0]).length();
        sum += (c(t[0]) + c(t[1]) + c(t[2])) / 3.0 * a;
        area += a;
    }
    let expected = 0.5 * sum / area;
    let rho = scene.materials[scene.polygons[0].material].rho;
    assert!(
        (rho - expected).abs().max_element() < 1e-12,
        "{rho} vs {expected}"
    );
    // A colour that is not one is refused, naming the primitive.
    let bad = edit(&input, |json, bin| {
        let bytes: Vec<u8> = [f32::NAN; 12]
            .iter()
            .flat_map(|c| c.to_le_bytes())
            .collect();
        let view = add_view(json, bin, &bytes);
        let acc = json["meshes"][0]["primitives"][0]["attributes"]["COLOR_0"]
            .as_u64()
            .unwrap() as usize;
        json["accessors"][acc]["bufferView"] = json!(view);
    });
    let e = penumbra::load::scene(&parse(&bad, "bad.glb"))
        .err()
        .unwrap()
        .to_string();
    assert!(
        e.contains("bad.glb") && e.contains("COLOR_0") && e.contains("mesh 0"),
        "{e}"
    );
}
