//! The written glb: structure, preservation, determinism.

use crate::{no_progress, quick, scratch};
use penumbra::fixtures;
use serde_json::Value;
use std::path::Path;

/// Splits a glb into its JSON and binary chunk.
pub fn split_glb(bytes: &[u8]) -> (Value, Vec<u8>) {
    let glb = gltf::binary::Glb::from_slice(bytes).expect("valid glb container");
    let json = serde_json::from_slice(&glb.json).expect("valid JSON chunk");
    (json, glb.bin.map(|b| b.into_owned()).unwrap_or_default())
}

fn bake_to_file(input: &[u8], dir: &Path, threads: usize) -> Vec<u8> {
    let inp = dir.join("in.glb");
    let out = dir.join(format!("out-{threads}.glb"));
    std::fs::write(&inp, input).unwrap();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| {
        penumbra::bake_file(
            &inp,
            &penumbra::OutputFiles::glb(&out),
            &quick(),
            no_progress(),
        )
    })
    .expect("bake succeeds");
    std::fs::read(&out).unwrap()
}

#[test]
fn cornell_output_has_lightmap_uvs_and_moz_lightmap_on_every_primitive() {
    let dir = scratch("cornell-output");
    let input = fixtures::cornell_box();
    let out = bake_to_file(&input, &dir, 2);
    // The gltf crate accepts it (it validates indices and references).
    let doc = gltf::Gltf::from_slice(&out).expect("output parses and validates");
    let (json, bin) = split_glb(&out);
    let (json_in, _) = split_glb(&input);
    assert_eq!(
        json["extensionsUsed"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|e| *e == "MOZ_lightmap")
            .count(),
        1
    );
    assert!(
        json.get("extensionsRequired")
            .is_none_or(|r| !r.to_string().contains("MOZ_lightmap"))
    );
    let mut primitives = 0;
    for mesh in doc.meshes() {
        for prim in mesh.primitives() {
            primitives += 1;
            assert!(
                prim.get(&gltf::Semantic::TexCoords(1)).is_some(),
                "mesh {} lacks TEXCOORD_1",
                mesh.index()
            );
            assert!(
                prim.get(&gltf::Semantic::TexCoords(0)).is_some(),
                "mesh {} lacks TEXCOORD_0",
                mesh.index()
            );
            let m = prim
                .material()
                .index()
                .expect("lightmapped primitives have a material");
            let moz = &json["materials"][m]["extensions"]["MOZ_lightmap"];
            assert_eq!(moz["texCoord"], 1);
            let tex = moz["index"].as_u64().unwrap() as usize;
            let img = json["textures"][tex]["source"].as_u64().unwrap() as usize;
            assert_eq!(json["images"][img]["mimeType"], "image/png");
            assert!(moz["intensity"].as_f64().unwrap() > 0.0);
            // UVs lie in [0,1].
            let uv = prim.get(&gltf::Semantic::TexCoords(1)).unwrap();
            let lo = uv.min().unwrap();
            let hi = uv.max().unwrap();
            for c in 0..2 {
                assert!(lo[c].as_f64().unwrap() >= 0.0 && hi[c].as_f64().unwrap() <= 1.0);
            }
        }
    }
    assert_eq!(primitives, 8);
    // Everything else is preserved: names, materials' factors, the camera.
    assert_eq!(json["cameras"], json_in["cameras"]);
    assert_eq!(json["scenes"], json_in["scenes"]);
    for (a, b) in json["materials"]
        .as_array()
        .unwrap()
        .iter()
        .zip(json_in["materials"].as_array().unwrap())
    {
        assert_eq!(a["pbrMetallicRoughness"], b["pbrMetallicRoughness"]);
        assert_eq!(a["name"], b["name"]);
    }
    // The PNG decodes and has the atlas size; texel x intensity is the baked irradiance.
    let tex = json["materials"][0]["extensions"]["MOZ_lightmap"]["index"]
        .as_u64()
        .unwrap() as usize;
    let img = &json["images"][json["textures"][tex]["source"].as_u64().unwrap() as usize];
    let view = &json["bufferViews"][img["bufferView"].as_u64().unwrap() as usize];
    let off = view["byteOffset"].as_u64().unwrap_or(0) as usize;
    let len = view["byteLength"].as_u64().unwrap() as usize;
    let png = image::load_from_memory(&bin[off..off + len])
        .unwrap()
        .to_rgb8();
    assert_eq!(png.width(), 128);
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn instances_get_their_own_lightmap_space() {
    let dir = scratch("instanced");
    let input = fixtures::instanced();
    let out = bake_to_file(&input, &dir, 2);
    let (json, _) = split_glb(&out);
    let (json_in, _) = split_glb(&input);
    // Nodes that shared one mesh now point to different meshes with different lightmap UVs.
    let shared: Vec<usize> = {
        let mut by_mesh = std::collections::BTreeMap::<u64, Vec<usize>>::new();
        for (i, n) in json_in["nodes"].as_array().unwrap().iter().enumerate() {
            if let Some(m) = n["mesh"].as_u64() {
                by_mesh.entry(m).or_default().push(i);
            }
        }
        by_mesh
            .into_values()
            .find(|v| v.len() > 1)
            .expect("fixture has a shared mesh")
    };
    let meshes: Vec<u64> = shared
        .iter()
        .map(|&n| json["nodes"][n]["mesh"].as_u64().unwrap())
        .collect();
    assert_ne!(meshes[0], meshes[1]);
    let uv =
        |m: u64| json["meshes"][m as usize]["primitives"][0]["attributes"]["TEXCOORD_1"].clone();
    assert_ne!(uv(meshes[0]), uv(meshes[1]));
    gltf::Gltf::from_slice(&out).expect("output parses");
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn output_is_byte_identical_across_runs_and_thread_counts() {
    let dir = scratch("determinism");
    let input = fixtures::cornell_box();
    let a = bake_to_file(&input, &dir, 1);
    let b = bake_to_file(&input, &dir, 2);
    let c = bake_to_file(&input, &dir, 2);
    assert!(a == b, "--threads 1 and --threads 2 differ");
    assert!(b == c, "two runs differ");
    let _ = std::fs::remove_dir_all(dir);
}
