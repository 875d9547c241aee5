//! Files as the glTF toolchain writes them (gltfpack, glTF-Transform): meshopt-compressed,
//! quantized, GPU-instanced, with WebP textures. Each is made here from a fixture and must bake
//! to the lightmap of the plain file; the client checks (`tests/clients`) run the real tools.

use crate::output::split_glb;
use crate::{bake, parse, quick};
use penumbra::fixtures;
use serde_json::{Value, json};

fn glb(json: &Value, bin: Vec<u8>) -> Vec<u8> {
    penumbra::write::to_glb(json, bin).unwrap()
}

/// The lightmapped glb of a bake of `input`.
fn written(input: &[u8], b: &mut penumbra::Bake) -> Vec<u8> {
    let gltf = parse(input, "input.glb");
    penumbra::bake::glb_bytes(&gltf, b, penumbra::lightmap::Encoding::Srgb).unwrap()
}

/// The covered texels of a bake's lightmap, in texel order.
fn texels(b: &penumbra::Bake) -> Vec<glam::DVec3> {
    b.lightmap.texels.clone()
}

/// The mean of the covered texels, weighted by their coverage.
fn covered_mean(b: &penumbra::Bake) -> f64 {
    let m = &b.lightmap;
    let (s, w) = m
        .texels
        .iter()
        .zip(&m.coverage)
        .fold((0.0, 0.0), |(s, w), (t, &c)| {
            (s + (t.x + t.y + t.z) * c as f64, w + c as f64)
        });
    s / w
}

/// Encodes `data` (elements of `stride` bytes) with meshopt's vertex codec.
fn encode_vertices(data: &[u8], stride: usize) -> Vec<u8> {
    fn typed<const N: usize>(data: &[u8]) -> Vec<u8> {
        let v: Vec<[u8; N]> = data
            .chunks_exact(N)
            .map(|c| c.try_into().unwrap())
            .collect();
        meshopt::encode_vertex_buffer(&v).unwrap()
    }
    match stride {
        8 => typed::<8>(data),
        12 => typed::<12>(data),
        16 => typed::<16>(data),
        s => panic!("no encoder for stride {s}"),
    }
}

/// `bytes` with every buffer view meshopt-encoded (index views with the INDICES codec, vertex
/// views with ATTRIBUTES) into buffer 0, and the plain bytes replaced by an empty fallback
/// buffer, as gltfpack -c writes them.
fn meshopt_compressed(bytes: &[u8]) -> Vec<u8> {
    let (mut json, bin) = split_glb(bytes);
    let accessors = json["accessors"].as_array().unwrap().clone();
    let mut encoded = Vec::new();
    for (i, view) in json["bufferViews"]
        .as_array_mut()
        .unwrap()
        .iter_mut()
        .enumerate()
    {
        let acc = accessors
            .iter()
            .find(|a| a["bufferView"] == i)
            .expect("every view holds an accessor");
        let (off, len) = (
            view["byteOffset"].as_u64().unwrap_or(0) as usize,
            view["byteLength"].as_u64().unwrap() as usize,
        );
        let data = &bin[off..off + len];
        let (stream, stride, count, mode) = if acc["type"] == "SCALAR" {
            let indices: Vec<u32> = data
                .chunks_exact(2)
                .map(|c| u16::from_le_bytes([c[0], c[1]]) as u32)
                .collect();
            let n = indices.iter().max().map_or(0, |&m| m as usize + 1);
            let s = meshopt::encode_index_sequence(&indices, n).unwrap();
            (s, 2, indices.len(), "INDICES")
        } else {
            let stride = if acc["type"] == "VEC2" { 8 } else { 12 };
            (
                encode_vertices(data, stride),
                stride,
                len / stride,
                "ATTRIBUTES",
            )
        };
        while !encoded.len().is_multiple_of(4) {
            encoded.push(0);
        }
        view["extensions"] = json!({"EXT_meshopt_compression": {"buffer": 0,
            "byteOffset": encoded.len(), "byteLength": stream.len(), "byteStride": stride,
            "count": count, "mode": mode}});
        view["buffer"] = json!(1);
        encoded.extend_from_slice(&stream);
    }
    json["buffers"] = json!([{"byteLength": encoded.len()},
        {"byteLength": bin.len(), "extensions": {"EXT_meshopt_compression": {"fallback": true}}}]);
    json["extensionsUsed"] = json!(["EXT_meshopt_compression"]);
    json["extensionsRequired"] = json!(["EXT_meshopt_compression"]);
    glb(&json, encoded)
}

#[test]
fn a_meshopt_compressed_file_bakes_to_the_plain_files_lightmap_and_is_written_decoded() {
    let plain = fixtures::cornell_box();
    let packed = meshopt_compressed(&plain);
    let (a, mut b) = (bake(&plain, &quick()), bake(&packed, &quick()));
    assert_eq!(
        texels(&a),
        texels(&b),
        "lossless compression, the same bake"
    );

    // The output stands alone: the views decoded, the extension and its fallback gone.
    let out = written(&packed, &mut b);
    let (json, _) = split_glb(&out);
    assert!(
        !json.to_string().contains("meshopt"),
        "{}",
        json["extensionsUsed"]
    );
    assert_eq!(json["buffers"].as_array().unwrap().len(), 1);
    let again = bake(&out, &quick());
    assert_eq!(again.scene.triangles.len(), a.scene.triangles.len());
}

#[test]
fn a_corrupt_meshopt_stream_is_an_error_naming_the_view() {
    let (mut json, bin) = split_glb(&meshopt_compressed(&fixtures::cornell_box()));
    json["bufferViews"][3]["extensions"]["EXT_meshopt_compression"]["byteLength"] = json!(3);
    let e = penumbra::load::from_bytes(glb(&json, bin), std::path::Path::new("bad.glb"))
        .err()
        .expect("refused")
        .to_string();
    assert!(
        e.contains("bad.glb") && e.contains("bufferViews[3]") && e.contains("decode"),
        "{e}"
    );
}

/// `bytes` with every mesh's positions quantized to normalized 16-bit integers within its
/// bounds (KHR_mesh_quantization), the node placing it given a child with the scale and
/// offset that undo it, as gltfpack and `gltf-transform quantize` do.
fn quantized(bytes: &[u8]) -> Vec<u8> {
    let (mut json, mut bin) = split_glb(bytes);
    let meshes = json["meshes"].as_array().unwrap().len();
    let mut dequantize = Vec::new();
    for m in 0..meshes {
        let prims = json["meshes"][m]["primitives"].as_array().unwrap().clone();
        let mut extent: f64 = 0.0;
        let mut data = Vec::new();
        for p in &prims {
            let acc = &json["accessors"][p["attributes"]["POSITION"].as_u64().unwrap() as usize];
            let view = &json["bufferViews"][acc["bufferView"].as_u64().unwrap() as usize];
            let off = view["byteOffset"].as_u64().unwrap_or(0) as usize;
            let n = acc["count"].as_u64().unwrap() as usize;
            let pts: Vec<f64> = bin[off..off + 12 * n]
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes(c.try_into().unwrap()) as f64)
                .collect();
            extent = pts.iter().fold(extent, |e, x| e.max(x.abs()));
            data.push(pts);
        }
        for (p, pts) in prims.iter().zip(data) {
            let mut q = Vec::new();
            for c in pts.chunks_exact(3) {
                for x in c {
                    q.extend_from_slice(&((x / extent * 32767.0).round() as i16).to_le_bytes());
                }
                q.extend_from_slice(&[0, 0]);
            }
            while !bin.len().is_multiple_of(4) {
                bin.push(0);
            }
            let views = json["bufferViews"].as_array_mut().unwrap();
            views.push(json!({"buffer": 0, "byteOffset": bin.len(), "byteLength": q.len(), "byteStride": 8}));
            let view = views.len() - 1;
            bin.extend_from_slice(&q);
            let a = p["attributes"]["POSITION"].as_u64().unwrap() as usize;
            let acc = &mut json["accessors"][a];
            acc["bufferView"] = json!(view);
            acc["componentType"] = json!(5122);
            acc["normalized"] = json!(true);
            for k in ["min", "max"] {
                acc[k] = json!(
                    acc[k]
                        .as_array()
                        .unwrap()
                        .iter()
                        .map(|v| (v.as_f64().unwrap() / extent * 32767.0).round() / 32767.0)
                        .collect::<Vec<_>>()
                );
            }
        }
        dequantize.push(extent);
    }
    json["buffers"][0]["byteLength"] = json!(bin.len());
    let nodes = json["nodes"].as_array().unwrap().len();
    for n in 0..nodes {
        if let Some(m) = json["nodes"][n]["mesh"].as_u64() {
            let s = dequantize[m as usize];
            let nodes = json["nodes"].as_array_mut().unwrap();
            nodes.push(json!({"mesh": m, "scale": [s, s, s]}));
            let child = nodes.len() - 1;
            let node = nodes[n].as_object_mut().unwrap();
            node.remove("mesh");
            node.entry("children")
                .or_insert(json!([]))
                .as_array_mut()
                .unwrap()
                .push(json!(child));
        }
    }
    json["extensionsUsed"] = json!(["KHR_mesh_quantization"]);
    json["extensionsRequired"] = json!(["KHR_mesh_quantization"]);
    glb(&json, bin)
}

#[test]
fn quantized_positions_bake_as_the_float_ones_within_the_quantization_step() {
    let plain = fixtures::cornell_box();
    let q = quantized(&plain);
    let (a, b) = (bake(&plain, &quick()), bake(&q, &quick()));
    // Each vertex is off by at most half a step of 1/32767 of its mesh's extent.
    let extent = a.scene.extent();
    for (x, y) in a.scene.instances.iter().zip(&b.scene.instances) {
        for (p, r) in x.positions_world.iter().zip(&y.positions_world) {
            assert!((*p - *r).length() < extent / 32767.0, "{p} vs {r}");
        }
    }
    // Another layout (the atlas packs the moved vertices anew): the covered texels' mean.
    let (ma, mb) = (covered_mean(&a), covered_mean(&b));
    assert!((mb / ma - 1.0).abs() < 0.005, "mean texel {mb} vs {ma}");

    // The same integers without the extension are refused, naming the accessor.
    let (mut json, bin) = split_glb(&q);
    json.as_object_mut().unwrap().remove("extensionsUsed");
    json.as_object_mut().unwrap().remove("extensionsRequired");
    json["accessors"][0]["normalized"] = json!(false);
    let e = penumbra::load::scene(&parse(&glb(&json, bin), "q.glb"))
        .err()
        .unwrap()
        .to_string();
    assert!(
        e.contains("KHR_mesh_quantization") && e.contains("accessor 0"),
        "{e}"
    );
}

/// The instanced fixture with its two panel nodes made one node with two GPU instances.
fn gpu_instanced(bytes: &[u8]) -> Vec<u8> {
    let (mut json, mut bin) = split_glb(bytes);
    assert_eq!(
        json["nodes"][3]["children"],
        json!([1, 2]),
        "panels, as the fixture has them"
    );
    let (s, c) = (15f32.to_radians().sin(), 15f32.to_radians().cos());
    let t: [f32; 6] = [-0.8, 0.25, 0.0, 0.8, 0.75, 0.0];
    let r: [f32; 8] = [0.0, 0.0, 0.0, 1.0, 0.0, s, 0.0, c];
    let mut add = |data: &[f32], ty: &str| {
        let at = bin.len();
        bin.extend(data.iter().flat_map(|x| x.to_le_bytes()));
        let views = json["bufferViews"].as_array_mut().unwrap();
        views.push(json!({"buffer": 0, "byteOffset": at, "byteLength": 4 * data.len()}));
        let view = views.len() - 1;
        let accessors = json["accessors"].as_array_mut().unwrap();
        accessors.push(json!({"bufferView": view, "componentType": 5126, "count": 2, "type": ty}));
        accessors.len() - 1
    };
    let (ta, ra) = (add(&t, "VEC3"), add(&r, "VEC4"));
    json["buffers"][0]["byteLength"] = json!(bin.len());
    let panels = &mut json["nodes"][3];
    panels.as_object_mut().unwrap().remove("children");
    panels["name"] = json!("panels");
    panels["mesh"] = json!(1);
    panels["extensions"] =
        json!({"EXT_mesh_gpu_instancing": {"attributes": {"TRANSLATION": ta, "ROTATION": ra}}});
    json["extensionsUsed"] = json!(["EXT_mesh_gpu_instancing"]);
    json["extensionsRequired"] = json!(["EXT_mesh_gpu_instancing"]);
    glb(&json, bin)
}

#[test]
fn gpu_instances_bake_as_separate_nodes_and_each_keeps_its_own_lightmap() {
    let plain = fixtures::instanced();
    let inst = gpu_instanced(&plain);
    let (a, mut b) = (bake(&plain, &quick()), bake(&inst, &quick()));
    assert_eq!(a.scene.instances.len(), b.scene.instances.len());
    let gpu: Vec<_> = b.scene.instances.iter().map(|i| i.gpu_instance).collect();
    assert!(gpu.contains(&Some(0)) && gpu.contains(&Some(1)), "{gpu:?}");
    for (x, y) in a.scene.instances.iter().zip(&b.scene.instances) {
        for (p, r) in x.positions_world.iter().zip(&y.positions_world) {
            assert!((*p - *r).length() < 1e-6, "{p} vs {r}");
        }
    }
    // The same layout; the transforms are composed in another order, so the positions differ
    // in the last bits, and the refinement may split a few elements differently.
    let (ta, tb) = (texels(&a), texels(&b));
    let sq = ta
        .iter()
        .zip(&tb)
        .map(|(x, y)| (*x - *y).length_squared())
        .sum::<f64>();
    let rms = (sq / ta.len() as f64).sqrt();
    let mean = ta.iter().map(|v| v.length()).sum::<f64>() / ta.len() as f64;
    assert!(rms < 1e-2 * mean, "texel RMS difference {rms}, mean {mean}");

    // Written out, each instance is a node of its own with its own lightmapped mesh.
    let out = written(&inst, &mut b);
    let (json, _) = split_glb(&out);
    assert!(!json.to_string().contains("EXT_mesh_gpu_instancing"));
    let panels = &json["nodes"][3];
    assert!(panels.get("mesh").is_none());
    let kids: Vec<usize> = panels["children"]
        .as_array()
        .unwrap()
        .iter()
        .map(|k| k.as_u64().unwrap() as usize)
        .collect();
    assert_eq!(kids.len(), 2);
    let meshes: Vec<&Value> = kids.iter().map(|&k| &json["nodes"][k]["mesh"]).collect();
    assert_ne!(
        meshes[0], meshes[1],
        "each instance its own mesh, so its own lightmap UVs"
    );
    let again = bake(&out, &quick());
    assert_eq!(again.scene.instances.len(), b.scene.instances.len());
}

#[test]
fn a_webp_texture_colours_the_bake_as_the_same_png_does() {
    use image::ImageEncoder;
    let px: Vec<u8> = (0..64)
        .flat_map(|i| [i as u8 * 4, 128, 255 - i as u8 * 4])
        .collect();
    let (mut png, mut webp) = (Vec::new(), Vec::new());
    image::codecs::png::PngEncoder::new(&mut png)
        .write_image(&px, 8, 8, image::ExtendedColorType::Rgb8)
        .unwrap();
    image::codecs::webp::WebPEncoder::new_lossless(&mut webp)
        .write_image(&px, 8, 8, image::ExtendedColorType::Rgb8)
        .unwrap();
    let textured = |bytes: &[u8], mime: &str, webp: bool| {
        let (mut json, mut bin) = split_glb(&fixtures::plane_uniform());
        let at = bin.len();
        bin.extend_from_slice(bytes);
        json["bufferViews"]
            .as_array_mut()
            .unwrap()
            .push(json!({"buffer": 0, "byteOffset": at, "byteLength": bytes.len()}));
        json["buffers"][0]["byteLength"] = json!(bin.len());
        let view = json["bufferViews"].as_array().unwrap().len() - 1;
        json["images"] = json!([{"bufferView": view, "mimeType": mime}]);
        json["textures"] = if webp {
            json["extensionsUsed"] = json!(["EXT_texture_webp"]);
            json["extensionsRequired"] = json!(["EXT_texture_webp"]);
            json!([{"extensions": {"EXT_texture_webp": {"source": 0}}}])
        } else {
            json!([{"source": 0}])
        };
        json["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = json!({"index": 0});
        glb(&json, bin)
    };
    let a = penumbra::load::scene(&parse(&textured(&png, "image/png", false), "a.glb")).unwrap();
    let b = penumbra::load::scene(&parse(&textured(&webp, "image/webp", true), "b.glb")).unwrap();
    assert_eq!(a.materials[0].rho, b.materials[0].rho);
    assert!(a.materials[0].rho.x < 0.3 && b.warnings.iter().all(|w| !w.contains("decode")));
}

#[test]
fn gpu_instances_count_against_the_instance_limit_before_they_are_read() {
    let dir = crate::scratch("gpu-instance-limit");
    let path = dir.join("inst.glb");
    std::fs::write(&path, gpu_instanced(&fixtures::instanced())).unwrap();
    let mut options = penumbra::load::LoadOptions::default();
    options.limits.instances = 1;
    let gltf = penumbra::load::read_with(&path, &options).unwrap();
    let e = penumbra::load::scene(&gltf)
        .expect_err("refused")
        .to_string();
    assert!(
        e.contains("inst.glb")
            && e.contains("node 3 EXT_mesh_gpu_instancing")
            && e.contains("--max-instances"),
        "{e}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
