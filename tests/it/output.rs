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
    bake_to_file_with(input, dir, threads, &quick())
}

/// Bakes `input` through `bake_file` on `threads` threads with `options`; the output's bytes.
pub fn bake_to_file_with(
    input: &[u8],
    dir: &Path,
    threads: usize,
    options: &penumbra::BakeOptions,
) -> Vec<u8> {
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
            options,
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

/// The PNG of texture `tex` in a baked glb, decoded to 8-bit RGB.
pub fn texture_rgb(json: &Value, bin: &[u8], tex: usize) -> image::RgbImage {
    let img = &json["images"][json["textures"][tex]["source"].as_u64().unwrap() as usize];
    let view = &json["bufferViews"][img["bufferView"].as_u64().unwrap() as usize];
    let off = view["byteOffset"].as_u64().unwrap_or(0) as usize;
    let len = view["byteLength"].as_u64().unwrap() as usize;
    image::load_from_memory(&bin[off..off + len])
        .unwrap()
        .to_rgb8()
}

/// Bakes `input` to a file with `options`; returns the bake and the glb bytes.
fn bake_with(
    input: &[u8],
    dir: &Path,
    name: &str,
    options: &penumbra::BakeOptions,
) -> (penumbra::Bake, Vec<u8>) {
    let inp = dir.join("in.glb");
    let out = dir.join(format!("{name}.glb"));
    std::fs::write(&inp, input).unwrap();
    let b = penumbra::bake_file(
        &inp,
        &penumbra::OutputFiles::glb(&out),
        options,
        no_progress(),
    )
    .expect("bake succeeds");
    (b, std::fs::read(&out).unwrap())
}

/// The 95th percentile, over covered texels at 1% of the maximum or more, of the relative
/// difference between the file's 8-bit lightmap (decoded as its extras say, times
/// `MOZ_lightmap.intensity`) and the float lightmap.
fn decoded_error_p95(b: &penumbra::Bake, glb: &[u8]) -> f64 {
    let (json, bin) = split_glb(glb);
    let moz = &json["materials"][0]["extensions"]["MOZ_lightmap"];
    let tex = moz["index"].as_u64().unwrap() as usize;
    let intensity = moz["intensity"].as_f64().unwrap();
    let extras = &json["textures"][tex]["extras"]["penumbra"];
    assert_eq!(extras["quantity"], "irradiance");
    assert_eq!(extras["units"], "W/m^2");
    assert_eq!(extras["scale"].as_f64().unwrap(), intensity);
    let encoding =
        penumbra::lightmap::Encoding::from_name(extras["encoding"].as_str().unwrap()).unwrap();
    let rgb = texture_rgb(&json, &bin, tex);
    let map = &b.lightmap;
    assert_eq!((rgb.width(), rgb.height()), (map.width, map.height));
    let max = map.max_value();
    let mut errors: Vec<f64> = Vec::new();
    for (k, (h, c)) in map.texels.iter().zip(&map.coverage).enumerate() {
        if *c <= 0.0 || h.max_element() < 0.01 * max {
            continue;
        }
        let p = rgb.get_pixel(k as u32 % map.width, k as u32 / map.width);
        for ch in 0..3 {
            let decoded = encoding.decode(p.0[ch] as f64 / 255.0) * intensity;
            errors.push((decoded - h[ch]).abs() / h[ch].max(1e-300));
        }
    }
    assert!(errors.len() > 1000, "{} samples", errors.len());
    errors.sort_by(f64::total_cmp);
    errors[errors.len() * 95 / 100]
}

/// The bound on the 95th-percentile decoded error of the default (sRGB, rounded) lightmap on
/// box-on-floor, for texels at 1% of the maximum or more.
const SRGB_P95_BOUND: f64 = 0.015;

#[test]
fn srgb_lightmap_decodes_within_1_5_percent_and_linear_does_not() {
    use penumbra::lightmap::Encoding;
    let dir = scratch("encoding");
    let input = fixtures::box_on_floor();
    let mut options = quick();
    let (b, srgb) = bake_with(&input, &dir, "srgb", &options);
    options.encoding = Encoding::Linear;
    let (b_linear, linear) = bake_with(&input, &dir, "linear", &options);
    assert_eq!(b.lightmap, b_linear.lightmap);
    let (json, _) = split_glb(&srgb);
    assert_eq!(json["textures"].as_array().unwrap().len(), 1);
    let e_srgb = decoded_error_p95(&b, &srgb);
    let e_linear = decoded_error_p95(&b, &linear);
    // For the record: the same without the dither (rounded to the nearest code).
    let undithered = |encoding: Encoding| {
        let max = b.lightmap.max_value();
        let mut e: Vec<f64> = b
            .lightmap
            .texels
            .iter()
            .zip(&b.lightmap.coverage)
            .filter(|(h, c)| **c > 0.0 && h.max_element() >= 0.01 * max)
            .flat_map(|(h, _)| h.to_array())
            .map(|h| {
                let code = (encoding.encode(h / max) * 255.0).round() / 255.0;
                (encoding.decode(code) * max - h).abs() / h
            })
            .collect();
        e.sort_by(f64::total_cmp);
        e[e.len() * 95 / 100]
    };
    println!(
        "95th percentile decoded error: srgb {e_srgb:.4}, linear {e_linear:.4}; without the \
         dither: srgb {:.4}, linear {:.4}",
        undithered(Encoding::Srgb),
        undithered(Encoding::Linear)
    );
    // The dither adds up to one code: at 10% of the maximum one sRGB code is 2.3%, so the
    // 95th percentile on this scene (floor, box sides, shadows: much of it below 20% of the
    // maximum) is about 1.9%; linear is about 3x worse.
    assert!(e_srgb <= SRGB_P95_BOUND, "srgb: {e_srgb}");
    assert!(e_linear > SRGB_P95_BOUND, "linear: {e_linear}");
    assert!(e_linear > 2.0 * e_srgb, "srgb {e_srgb}, linear {e_linear}");
    let _ = std::fs::remove_dir_all(dir);
}

/// The mean red radiance of a baked glb as `penumbra render` shows it (64 x 64, the automatic
/// camera, lightmap shading): what a client sees, whatever the page layout.
fn rendered_mean(glb: &[u8]) -> f64 {
    let g = penumbra::load::from_bytes(glb.to_vec(), Path::new("baked.glb")).unwrap();
    let camera = penumbra::render::Camera::auto(&penumbra::load::scene(&g).unwrap());
    let r = penumbra::render::render_radiance(
        &g,
        Some(camera),
        64,
        64,
        penumbra::render::Shading::Lightmap,
    )
    .unwrap();
    r.iter().map(|c| c.x).sum::<f64>() / r.len() as f64
}

/// Options that put box-on-floor's charts onto pages of `page_size` texels at 24 texels per
/// metre (the 4 m floor is 96 texels wide).
fn paged(page_size: u32) -> penumbra::BakeOptions {
    penumbra::BakeOptions {
        texels_per_unit: Some(24.0),
        resolution: None,
        page_size,
        ..quick()
    }
}

#[test]
fn charts_that_do_not_fit_one_page_go_onto_more_pages() {
    let dir = scratch("pages");
    let input = fixtures::box_on_floor();
    let (one, one_glb) = bake_with(&input, &dir, "one", &paged(2048));
    assert_eq!(one.atlas.pages, 1);
    let (b, out) = bake_with(&input, &dir, "many", &paged(128));
    let pages = b.atlas.pages as usize;
    // Deterministic bytes, also with one thread.
    let one_thread = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| bake_with(&input, &dir, "many-1", &paged(128)).1);
    assert!(one_thread == out, "1 thread and the default pool differ");
    assert!(pages > 1, "{pages} pages");
    assert_eq!(b.atlas.texels_per_unit, 24.0, "the density is kept");
    assert_eq!(b.lightmap.pages(), pages);
    let doc = gltf::Gltf::from_slice(&out).expect("output parses and validates");
    let (json, bin) = split_glb(&out);
    // One texture (and image) per page, each with its page number.
    let lightmaps: Vec<usize> = (0..json["textures"].as_array().unwrap().len())
        .filter(|&t| json["textures"][t]["extras"]["penumbra"].is_object())
        .collect();
    assert_eq!(lightmaps.len(), pages);
    for (p, &t) in lightmaps.iter().enumerate() {
        assert_eq!(json["textures"][t]["extras"]["penumbra"]["page"], p);
        let rgb = texture_rgb(&json, &bin, t);
        assert_eq!((rgb.width(), rgb.height()), (b.atlas.width, b.atlas.height));
        assert!(rgb.width() <= 128 && rgb.height() <= 128);
    }
    // Every primitive: UVs in [0,1], its material's MOZ_lightmap on one of the pages.
    let mut used = std::collections::BTreeSet::new();
    let mut material_of_page = std::collections::BTreeMap::new();
    for mesh in doc.meshes() {
        for prim in mesh.primitives() {
            let uv = prim.get(&gltf::Semantic::TexCoords(1)).unwrap();
            let (lo, hi) = (uv.min().unwrap(), uv.max().unwrap());
            for c in 0..2 {
                assert!(lo[c].as_f64().unwrap() >= 0.0 && hi[c].as_f64().unwrap() <= 1.0);
            }
            let m = prim.material().index().unwrap();
            let tex = json["materials"][m]["extensions"]["MOZ_lightmap"]["index"]
                .as_u64()
                .unwrap() as usize;
            assert!(lightmaps.contains(&tex));
            used.insert(tex);
            // One material per page: a material is never on two pages.
            assert_eq!(*material_of_page.entry(m).or_insert(tex), tex);
        }
    }
    assert_eq!(used.len(), pages, "every page is used");
    // The floor and the box share one material: it is cloned for the pages beyond the first.
    let (json_in, _) = split_glb(&input);
    assert!(
        json["materials"].as_array().unwrap().len()
            > json_in["materials"].as_array().unwrap().len()
    );
    // A client sees the same picture from the paged file as from the one-page file.
    let (m_one, m_many) = (rendered_mean(&one_glb), rendered_mean(&out));
    assert!((m_one / m_many - 1.0).abs() < 0.02, "{m_one} vs {m_many}");
    let _ = std::fs::remove_dir_all(dir);
}

/// `penumbra render --irradiance`: the float lightmap of a paged bake, read back from its EXR
/// pages, draws the picture the file's 8-bit pages draw (within their quantisation); a map of
/// zeros draws the surfaces black.
#[test]
fn render_draws_a_float_lightmap_in_the_files_layout() {
    let dir = scratch("irradiance");
    let input = fixtures::box_on_floor();
    let inp = dir.join("in.glb");
    std::fs::write(&inp, &input).unwrap();
    let files = penumbra::OutputFiles {
        glb: dir.join("out.glb"),
        exr: Some(dir.join("out.exr")),
        stats: None,
    };
    let b = penumbra::bake_file(&inp, &files, &paged(128), no_progress()).expect("bake");
    assert!(b.atlas.pages > 1);
    let map = penumbra::render::read_irradiance(&dir.join("out.exr")).unwrap();
    assert_eq!(map.pages(), b.atlas.pages as usize, "every page read");
    let glb = std::fs::read(&files.glb).unwrap();
    let g = penumbra::load::from_bytes(glb.clone(), Path::new("out.glb")).unwrap();
    let camera = penumbra::render::Camera::auto(&penumbra::load::scene(&g).unwrap());
    let mean = |map: &penumbra::lightmap::Lightmap| {
        let r = penumbra::render::render_radiance(
            &g,
            Some(camera),
            64,
            64,
            penumbra::render::Shading::Irradiance(map),
        )
        .unwrap();
        r.iter().map(|c| c.x).sum::<f64>() / r.len() as f64
    };
    let (float, eight_bit) = (mean(&map), rendered_mean(&glb));
    assert!(
        (float / eight_bit - 1.0).abs() < 0.02,
        "{float} vs {eight_bit}"
    );
    let dark = penumbra::lightmap::Lightmap {
        texels: vec![glam::DVec3::ZERO; map.texels.len()],
        ..map.clone()
    };
    assert_eq!(mean(&dark), 0.0);
    let _ = std::fs::remove_dir_all(dir);
}

/// A floor 4 m wide (one quad, with normals and `TEXCOORD_0` = its position) under an area
/// light.
fn textured_floor() -> Vec<u8> {
    use penumbra::fixtures::{GlbBuilder, Material, horizontal_rect};
    let mut b = GlbBuilder::new();
    let grey = b.add_material(Material::diffuse("grey", [0.5; 3]));
    let floor = horizontal_rect([-2.0, 2.0], [-2.0, 2.0], 0.0, true);
    let uv = floor
        .positions
        .iter()
        .map(|p| [(p[0] + 2.0) / 4.0, (p[2] + 2.0) / 4.0])
        .collect();
    b.add_mesh_node("floor", &floor.with_texcoords(uv), grey);
    let light = Material::diffuse("light", [0.0; 3]).emitting([10.0; 3]);
    let light = b.add_material(light);
    let panel = horizontal_rect([-0.5, 0.5], [-0.5, 0.5], 3.0, false);
    b.add_mesh_node("light", &panel, light);
    b.to_glb()
}

#[test]
fn a_triangle_longer_than_the_page_is_cut_and_its_attributes_interpolated() {
    let dir = scratch("long-triangle");
    let input = textured_floor();
    // The 4 m floor at 100 texels per metre is 400 texels wide; the page is 128.
    let options = penumbra::BakeOptions {
        texels_per_unit: Some(100.0),
        resolution: None,
        page_size: 128,
        ..quick()
    };
    let (b, out) = bake_with(&input, &dir, "cut", &options);
    // The floor's and the 1 m light's two triangles each (edges longer than 0.625 m).
    assert!(b.stats.cut.triangles_cut == 4, "{:?}", b.stats.cut);
    assert!(b.atlas.pages > 4, "{} pages", b.atlas.pages);
    assert_eq!(b.atlas.texels_per_unit, 100.0, "the density is kept");
    assert_eq!(b.stats.triangles, 4, "stats count the input's triangles");
    let doc = gltf::Gltf::from_slice(&out).expect("output parses and validates");
    let (_, bin) = split_glb(&out);
    let mut floor_vertices = 0;
    let mut floor_area = 0.0f64;
    let floor = doc.meshes().find(|m| m.name() == Some("floor")).unwrap();
    for prim in floor.primitives() {
        let reader = prim.reader(|_| Some(&bin[..]));
        let p: Vec<f32> = reader.read_positions().unwrap().flatten().collect();
        let n: Vec<f32> = reader.read_normals().unwrap().flatten().collect();
        let uv: Vec<f32> = reader
            .read_tex_coords(0)
            .unwrap()
            .into_f32()
            .flatten()
            .collect();
        floor_vertices += p.len() / 3;
        // Every vertex, old or new, has the floor's normal and TEXCOORD_0 = its position.
        for k in 0..p.len() / 3 {
            let (x, z) = (p[3 * k], p[3 * k + 2]);
            assert!((n[3 * k + 1] - 1.0).abs() < 1e-6 && n[3 * k].abs() < 1e-6);
            assert!((uv[2 * k] - (x + 2.0) / 4.0).abs() < 1e-6, "u at {x},{z}");
            assert!(
                (uv[2 * k + 1] - (z + 2.0) / 4.0).abs() < 1e-6,
                "v at {x},{z}"
            );
        }
        // The winding still faces up, and the pieces tile the floor.
        let idx: Vec<u32> = reader.read_indices().unwrap().into_u32().collect();
        for t in idx.chunks_exact(3) {
            let q = [t[0], t[1], t[2]].map(|i| {
                glam::DVec3::new(
                    p[3 * i as usize] as f64,
                    p[3 * i as usize + 1] as f64,
                    p[3 * i as usize + 2] as f64,
                )
            });
            let cross = (q[1] - q[0]).cross(q[2] - q[0]);
            assert!(cross.y > 0.0, "a piece faces down");
            floor_area += 0.5 * cross.length();
            for c in 0..3 {
                assert!(
                    q[c].distance(q[(c + 1) % 3]) <= 0.625 + 1e-6,
                    "a long edge is left"
                );
            }
        }
    }
    assert!(floor_vertices > 4);
    assert!((floor_area - 16.0).abs() < 1e-4, "floor area {floor_area}");
    // The light is the same as on one large page, where nothing is cut.
    let one_page = penumbra::BakeOptions {
        page_size: 2048,
        ..options.clone()
    };
    let (one, one_glb) = bake_with(&input, &dir, "one", &one_page);
    assert_eq!((one.atlas.pages, one.stats.cut.triangles_cut), (1, 0));
    let (m_one, m_cut) = (rendered_mean(&one_glb), rendered_mean(&out));
    assert!((m_one / m_cut - 1.0).abs() < 0.02, "{m_one} vs {m_cut}");
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn an_atlas_too_large_fails_before_the_solve_naming_file_and_density() {
    let dir = scratch("atlas-too-large");
    let inp = dir.join("in.glb");
    std::fs::write(&inp, fixtures::box_on_floor()).unwrap();
    let stages = std::sync::Mutex::new(Vec::<String>::new());
    let progress = |stage: &str, _: u64, _: u64| {
        let mut s = stages.lock().unwrap();
        if s.last().is_none_or(|l| l != stage) {
            s.push(stage.to_string());
        }
    };
    // About 22 m² of surface at 5000 texels per metre is more than 16384² texels.
    let options = penumbra::BakeOptions {
        texels_per_unit: Some(5000.0),
        resolution: None,
        page_size: 128,
        ..quick()
    };
    let err = penumbra::bake_file(
        &inp,
        &penumbra::OutputFiles::glb(dir.join("out.glb")),
        &options,
        &progress,
    )
    .err()
    .expect("the bake fails");
    let message = err.to_string();
    println!("{message}");
    assert!(message.contains("in.glb"), "{message}");
    assert!(message.contains(" 5000 texels per unit"), "{message}");
    let stages = stages.into_inner().unwrap();
    for later in ["discontinuity", "mesh", "solve", "lightmap"] {
        assert!(
            !stages.iter().any(|s| s == later),
            "{later} ran: {stages:?}"
        );
    }
    let _ = std::fs::remove_dir_all(dir);
}

/// `glb` with every lightmapped primitive's lightmap UVs moved from `TEXCOORD_1` to
/// `TEXCOORD_<set>` and `MOZ_lightmap.texCoord` saying so; `TEXCOORD_1` then holds a decoy, all
/// UVs zero. With `point_at_decoy`, `texCoord` stays 1 (so readers get the decoy).
fn lightmap_uvs_moved_to(glb: &[u8], set: u32, point_at_decoy: bool) -> Vec<u8> {
    let (mut json, mut bin) = split_glb(glb);
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let lightmapped = |json: &Value, m: &Value| {
        m.as_u64().is_some_and(|m| {
            json["materials"][m as usize]["extensions"]["MOZ_lightmap"].is_object()
        })
    };
    let meshes = json["meshes"].as_array().unwrap().len();
    let mut moved = 0;
    for mesh in 0..meshes {
        let prims = json["meshes"][mesh]["primitives"].as_array().unwrap().len();
        for p in 0..prims {
            let prim = json["meshes"][mesh]["primitives"][p].clone();
            if !lightmapped(&json, &prim["material"]) {
                continue;
            }
            let uv = prim["attributes"]["TEXCOORD_1"].clone();
            let count = json["accessors"][uv.as_u64().unwrap() as usize]["count"]
                .as_u64()
                .unwrap();
            let offset = bin.len();
            bin.extend(std::iter::repeat_n(0u8, count as usize * 8));
            let views = json["bufferViews"].as_array_mut().unwrap();
            views.push(
                serde_json::json!({"buffer": 0, "byteOffset": offset, "byteLength": count * 8}),
            );
            let view = views.len() - 1;
            let accessors = json["accessors"].as_array_mut().unwrap();
            accessors.push(serde_json::json!({
                "bufferView": view, "componentType": 5126, "count": count, "type": "VEC2"
            }));
            let decoy = accessors.len() - 1;
            let attributes = &mut json["meshes"][mesh]["primitives"][p]["attributes"];
            attributes[format!("TEXCOORD_{set}")] = uv;
            attributes["TEXCOORD_1"] = decoy.into();
            moved += 1;
        }
    }
    assert!(moved > 0);
    for m in json["materials"].as_array_mut().unwrap() {
        if let Some(moz) = m["extensions"].get_mut("MOZ_lightmap") {
            moz["texCoord"] = if point_at_decoy { 1 } else { set }.into();
        }
    }
    json["buffers"][0]["byteLength"] = bin.len().into();
    penumbra::write::to_glb(&json, bin).unwrap()
}

/// `penumbra render` and the reference's texel layout read the lightmap UVs from the set that
/// `MOZ_lightmap.texCoord` names, whichever it is.
#[test]
fn render_and_reference_read_the_uv_set_moz_lightmap_names() {
    let dir = scratch("moz-texcoord");
    let baked = bake_to_file(&fixtures::box_on_floor(), &dir, 2);
    let read = |glb: &[u8]| {
        let g = penumbra::load::from_bytes(glb.to_vec(), Path::new("baked.glb")).unwrap();
        let scene = penumbra::load::scene(&g).unwrap();
        let vis = penumbra::visibility::Visibility::new(&scene);
        let camera = penumbra::render::Camera::auto(&scene);
        let shading = penumbra::render::Shading::Lightmap;
        let picture = penumbra::render::render_radiance(&g, Some(camera), 32, 32, shading).unwrap();
        let layout = penumbra::reference::texel_layout(&g, &scene, &vis, 2).unwrap();
        (picture, layout.samples)
    };
    let expected = read(&baked);
    for set in [0, 2] {
        let moved = read(&lightmap_uvs_moved_to(&baked, set, false));
        assert!(
            moved == expected,
            "texCoord {set}: not the same picture and texel layout"
        );
    }
    // The decoy set differs: a reader of TEXCOORD_1 would not pass the check above.
    let decoy = read(&lightmap_uvs_moved_to(&baked, 2, true));
    assert!(decoy.0 != expected.0 && decoy.1 != expected.1);
    let _ = std::fs::remove_dir_all(dir);
}
