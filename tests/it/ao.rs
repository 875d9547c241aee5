//! Ambient occlusion (`--ao`): the written `occlusionTexture` against the closed form of a
//! floor in the corner of two walls, read back from the output file as a client reads it.

use crate::output::{bake_to_file_with, split_glb};
use crate::{parse, quick, scratch};
use glam::DVec3;
use penumbra::fixtures::{GlbBuilder, Light, Material, Node, Transform, horizontal_rect, quad};
use penumbra::lightmap::ao::AoOptions;
use penumbra::visibility::Visibility;
use penumbra::{BakeOptions, reference};
use std::f64::consts::PI;

/// Side of the floor and height of the walls, m.
const SIDE: f64 = 6.0;
/// The AO distance of the tests, m.
const DISTANCE: f64 = 1.0;

/// A floor `[0, SIDE]²` at y = 0 facing up, and two walls `SIDE` high along its edges x = 0
/// (facing +x) and z = 0 (facing +z), meeting in a corner at the origin; grey, under a sun.
fn corner() -> Vec<u8> {
    let mut b = GlbBuilder::new();
    let grey = b.add_material(Material::diffuse("grey", [0.5; 3]));
    b.add_mesh_node(
        "floor",
        &horizontal_rect([0.0, SIDE], [0.0, SIDE], 0.0, true),
        grey,
    );
    let s = SIDE;
    b.add_mesh_node(
        "wall x",
        &quad([[0.0, 0.0, s], [0.0, 0.0, 0.0], [0.0, s, 0.0], [0.0, s, s]]),
        grey,
    );
    b.add_mesh_node(
        "wall z",
        &quad([[0.0, 0.0, 0.0], [s, 0.0, 0.0], [s, s, 0.0], [0.0, s, 0.0]]),
        grey,
    );
    add_sun(&mut b);
    b.to_glb()
}

/// A sun of 3 lux from above, slanting.
fn add_sun(b: &mut GlbBuilder) {
    let sun = b.add_light(Light::directional("sun", 3.0));
    b.add_node(
        Node::new("sun")
            .with_transform(Transform::look_to(
                [5.0, 5.0, 5.0],
                [-0.3, -1.0, -0.4],
                [0.0, 1.0, 0.0],
            ))
            .with_light(sun),
    );
}

/// The blocked area of the unit disk beyond `x = h` (a segment; `h` in 0..1).
fn segment(h: f64) -> f64 {
    let h = h.clamp(0.0, 1.0);
    h.acos() - h * (1.0 - h * h).sqrt()
}

/// The closed form of a floor point at distances `a` and `b` from two infinite walls that meet
/// at a right angle: a cosine-distributed direction projects uniformly onto the unit disk, and
/// meets a wall within `DISTANCE` exactly when its component towards that wall exceeds the
/// point's distance over `DISTANCE`. Blocked: the union of the two segments, whose overlap (the
/// disk's part beyond both lines) is integrated numerically.
fn in_the_corner(a: f64, b: f64) -> f64 {
    let (ha, hb) = (a / DISTANCE, b / DISTANCE);
    let overlap = if ha * ha + hb * hb >= 1.0 {
        0.0
    } else {
        // ∫ from ha to sqrt(1 - hb²) of (sqrt(1 - x²) - hb) dx, by the midpoint rule.
        let top = (1.0 - hb * hb).sqrt();
        let n = 20_000;
        let dx = (top - ha) / n as f64;
        (0..n)
            .map(|k| {
                let x = ha + (k as f64 + 0.5) * dx;
                ((1.0 - x * x).sqrt() - hb).max(0.0) * dx
            })
            .sum()
    };
    1.0 - (segment(ha) + segment(hb) - overlap) / PI
}

fn with_ao() -> BakeOptions {
    BakeOptions {
        ao: Some(AoOptions {
            distance: DISTANCE,
            samples: 128,
        }),
        resolution: Some(256),
        ..quick()
    }
}

#[test]
fn the_corner_closed_form_has_its_known_limits() {
    // Far from both walls nothing is blocked; beside one wall, half; in the corner, three
    // quarters; along one wall far from the other, the one-wall segment alone.
    assert_eq!(in_the_corner(2.0, 2.0), 1.0);
    assert!((in_the_corner(0.0, 5.0) - 0.5).abs() < 1e-9);
    assert!((in_the_corner(0.0, 0.0) - 0.25).abs() < 1e-6);
    let one_wall = 1.0 - segment(0.3) / PI;
    assert!((in_the_corner(0.3, 1.5) - one_wall).abs() < 1e-9);
}

#[test]
fn ambient_occlusion_in_a_corner_matches_the_closed_form() {
    let dir = scratch("ao-corner");
    let out = bake_to_file_with(&corner(), &dir, 2, &with_ao());
    // The same bytes with one thread.
    assert!(out == bake_to_file_with(&corner(), &dir, 1, &with_ao()));
    let gltf = parse(&out, "out.glb");
    let json = &gltf.json;
    // Every lightmapped material binds the AO on the lightmap's UV set, linear, with its
    // distance in the texture's extras.
    let materials = json["materials"].as_array().unwrap();
    let ao_texture = materials[0]["occlusionTexture"]["index"].as_u64().unwrap() as usize;
    for m in materials {
        assert_eq!(m["occlusionTexture"]["index"], ao_texture, "{m}");
        assert_eq!(m["occlusionTexture"]["texCoord"], 1, "{m}");
    }
    let extras = &json["textures"][ao_texture]["extras"]["penumbra"];
    assert_eq!(extras["quantity"], "ambient occlusion");
    assert_eq!(extras["distance"], DISTANCE);
    // The AO image as a client decodes it: red channel, linear.
    let source = json["textures"][ao_texture]["source"].as_u64().unwrap() as usize;
    let view =
        &json["bufferViews"][json["images"][source]["bufferView"].as_u64().unwrap() as usize];
    let at = view["byteOffset"].as_u64().unwrap_or(0) as usize;
    let bin = split_glb(&out).1;
    let bytes = &bin[at..at + view["byteLength"].as_u64().unwrap() as usize];
    let img = image::load_from_memory(bytes).unwrap().to_luma8();

    let scene = penumbra::load::scene(&gltf).unwrap();
    let vis = Visibility::new(&scene);
    let layout = reference::texel_layout(&gltf, &scene, &vis, 4).unwrap();
    assert_eq!((layout.width, layout.height), img.dimensions());
    // Per band of distance from the corner's nearer wall, the mean of the texels against the
    // mean of the closed form at their sub-samples: floor texels wholly covered, away from
    // the far ends of the walls.
    let bands = [0.0, 0.1, 0.25, 0.5, 0.75, 1.0, 1.5];
    let mut sums = vec![(0.0, 0.0, 0usize); bands.len() - 1];
    let mut along_one_wall = (0.0, 0.0, 0usize);
    for (i, samples) in layout.samples.iter().enumerate() {
        if layout.coverage(i) < 1.0 || samples[0].n.y < 0.99 {
            continue;
        }
        let want = samples
            .iter()
            .map(|s| in_the_corner(s.p.x, s.p.z))
            .sum::<f64>()
            / samples.len() as f64;
        let got = img.as_raw()[i] as f64 / 255.0;
        let p = samples.iter().map(|s| s.p).sum::<DVec3>() / samples.len() as f64;
        if p.x.max(p.z) > SIDE - 1.5 {
            continue;
        }
        if p.x.min(p.z) > 1.5 && p.x.max(p.z) > 1.5 {
            // Beyond the distance of both walls: open.
            assert!(got > 0.99, "texel at {p}: AO {got}");
            continue;
        }
        if let Some(k) = bands
            .windows(2)
            .position(|w| (w[0]..w[1]).contains(&p.x.min(p.z)))
        {
            let s = &mut sums[k];
            *s = (s.0 + got, s.1 + want, s.2 + 1);
        }
        if p.x < 0.5 && p.z > 2.5 {
            along_one_wall = (
                along_one_wall.0 + got,
                along_one_wall.1 + want,
                along_one_wall.2 + 1,
            );
        }
    }
    for (k, (got, want, n)) in sums.iter().enumerate() {
        assert!(*n > 40, "band {k}: {n} texels");
        let (got, want) = (got / *n as f64, want / *n as f64);
        // 128 rays a texel, over at least 40 texels: a standard error under 0.007, plus 8-bit
        // rounding. Measured: within 0.0021 in every band; AO rays 20% too long are 0.014 to
        // 0.027 off.
        assert!(
            (got - want).abs() < 0.01,
            "band {:?} m from the nearer wall: AO {got:.4}, closed form {want:.4} ({n} texels)",
            &bands[k..k + 2]
        );
    }
    let (got, want, n) = along_one_wall;
    assert!(
        n > 40 && (got - want).abs() / (n as f64) < 0.01,
        "{got} {want} {n}"
    );
    // What the AO is not: the same bake without --ao writes no occlusion texture.
    let plain = bake_to_file_with(&corner(), &dir, 2, &quick());
    let plain = parse(&plain, "plain.glb");
    assert!(
        plain.json["materials"]
            .as_array()
            .unwrap()
            .iter()
            .all(|m| m.get("occlusionTexture").is_none())
    );
}

#[test]
fn a_materials_own_occlusion_texture_is_kept() {
    // The demo's materials given an occlusion texture of their own (TEXCOORD_0): the bake keeps
    // it, and binds its AO to the others.
    let mut b = GlbBuilder::new();
    let grey = b.add_material(Material::diffuse("grey", [0.5; 3]));
    let own = b.add_material(Material::diffuse("own ao", [0.5; 3]));
    b.add_mesh_node(
        "floor",
        &horizontal_rect([0.0, SIDE], [0.0, SIDE], 0.0, true),
        grey,
    );
    b.add_mesh_node(
        "wall",
        &quad([
            [0.0, 0.0, SIDE],
            [0.0, 0.0, 0.0],
            [0.0, SIDE, 0.0],
            [0.0, SIDE, SIDE],
        ]),
        own,
    );
    let texture = b.add_texture(2, 2, &[128; 16], 10497);
    add_sun(&mut b);
    let (mut json, bin) = split_glb(&b.to_glb());
    json["materials"][own]["occlusionTexture"] = serde_json::json!({"index": texture});
    let input = penumbra::write::to_glb(&json, bin).unwrap();
    let out = bake_to_file_with(&input, &scratch("ao-own"), 2, &with_ao());
    let json = parse(&out, "out.glb").json;
    let mats = json["materials"].as_array().unwrap();
    let by_name = |n: &str| mats.iter().find(|m| m["name"] == n).unwrap();
    assert_eq!(
        by_name("own ao")["occlusionTexture"],
        serde_json::json!({"index": texture})
    );
    let baked = by_name("grey")["occlusionTexture"]["index"]
        .as_u64()
        .unwrap();
    assert_ne!(baked, texture as u64);
}
