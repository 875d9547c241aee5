//! Stability where discontinuity meshing is known to fail: each scene bakes (or fails with a
//! clear error), never panics, and agrees with a fine uniform mesh.

use crate::discontinuity::dm;
use crate::output::split_glb;
use glam::DVec3;
use penumbra::fixtures::{self, GlbBuilder, Material, TriangleMesh};
use penumbra::mesh::Mesher;
use penumbra::{Bake, BakeOptions};
use serde_json::{Value, json};

/// Area-weighted mean irradiance of every polygon (the integral of the mesh interpolant).
fn polygon_means(b: &Bake) -> Vec<DVec3> {
    let mut out = vec![DVec3::ZERO; b.scene.polygons.len()];
    for (m, values) in b.meshes.iter().zip(&b.solution.irradiance) {
        let mut sum = DVec3::ZERO;
        let mut area = 0.0;
        for t in &m.triangles {
            let [p, q, r] = t.map(|i| m.vertices[i as usize]);
            let a = 0.5 * (q - p).perp_dot(r - p);
            sum += t.iter().map(|&i| values[i as usize]).sum::<DVec3>() / 3.0 * a;
            area += a;
        }
        out[m.polygon] = if area > 0.0 { sum / area } else { DVec3::ZERO };
    }
    out
}

/// Bakes with discontinuity meshing and with a fine uniform mesh; every polygon's mean agrees
/// within `tol` of the scene's brightest polygon mean.
fn agrees_with_fine_uniform(name: &str, bytes: &[u8], tol: f64) -> Bake {
    if let Some(dir) = std::env::var_os("PENUMBRA_DUMP") {
        std::fs::write(
            std::path::Path::new(&dir).join(format!("{}.glb", name.replace(' ', "-"))),
            bytes,
        )
        .unwrap();
    }
    let mut o = dm();
    o.solve.bounces = Some(0);
    o.solve.shadow_samples = 256;
    let d = crate::bake(bytes, &o);
    let fine = BakeOptions {
        mesher: Mesher::Uniform,
        budget: 40_000,
        ..o.clone()
    };
    let u = crate::bake(bytes, &fine);
    let (md, mu) = (polygon_means(&d), polygon_means(&u));
    let peak = mu.iter().map(|m| m.x).fold(0.0, f64::max);
    assert!(peak > 0.0, "{name}: nothing is lit");
    for (i, (a, b)) in md.iter().zip(&mu).enumerate() {
        assert!(
            (a.x - b.x).abs() <= tol * peak,
            "{name}: polygon {i} mean {} (discontinuity) vs {} (fine uniform)",
            a.x,
            b.x
        );
    }
    d
}

fn edit(bytes: &[u8], f: impl FnOnce(&mut Value)) -> Vec<u8> {
    let (mut json, bin) = split_glb(bytes);
    f(&mut json);
    penumbra::write::to_glb(&json, bin)
}

/// Puts the whole scene under one root node with the given TRS.
fn transformed(bytes: &[u8], trs: Value) -> Vec<u8> {
    edit(bytes, |json| {
        let roots = json["scenes"][0]["nodes"].clone();
        let nodes = json["nodes"].as_array_mut().unwrap();
        let mut root = trs;
        root["children"] = roots;
        nodes.push(root);
        let id = nodes.len() - 1;
        json["scenes"][0]["nodes"] = json!([id]);
    })
}

fn floor_and_light(g: &mut GlbBuilder) -> usize {
    let grey = g.add_material(Material::diffuse("grey", [0.5; 3]));
    g.add_mesh_node(
        "floor",
        &fixtures::horizontal_rect([-2.0, 2.0], [-2.0, 2.0], 0.0, true),
        grey,
    );
    let light = g.add_material(Material::diffuse("light", [0.0; 3]).emitting([1.0; 3]));
    g.add_mesh_node(
        "light",
        &fixtures::horizontal_rect([-0.5, 0.5], [-0.5, 0.5], 2.0, false),
        light,
    );
    grey
}

fn plate(y: f64, corners: [[f64; 2]; 4]) -> TriangleMesh {
    fixtures::quad(corners.map(|[x, z]| [x, y, z]))
}

#[test]
fn light_coplanar_with_the_ceiling() {
    // The published Cornell light height, 548.8 mm: coplanar with and overlapping the ceiling.
    let bytes = edit(&fixtures::cornell_box(), |json| {
        for n in json["nodes"].as_array_mut().unwrap() {
            if n["name"]
                .as_str()
                .is_some_and(|s| s.to_lowercase().contains("light"))
            {
                n["translation"] = json!([0.0, 0.0001, 0.0]);
            }
        }
    });
    agrees_with_fine_uniform("coplanar light", &bytes, 0.03);
}

#[test]
fn rotated_occluder_d2() {
    let mut g = GlbBuilder::new();
    floor_and_light(&mut g);
    let m = g.add_material(Material::diffuse("plate", [0.5; 3]).double_sided());
    let r = std::f64::consts::FRAC_1_SQRT_2;
    g.add_mesh_node(
        "diamond",
        &plate(1.0, [[0.0, -r], [-r, 0.0], [0.0, r], [r, 0.0]]),
        m,
    );
    agrees_with_fine_uniform("rotated occluder", &g.to_glb(), 0.02);
}

#[test]
fn occluder_touching_the_emitter() {
    let mut g = GlbBuilder::new();
    floor_and_light(&mut g);
    let m = g.add_material(Material::diffuse("plate", [0.5; 3]).double_sided());
    // A vertical plate hanging from the light's edge down to y = 1.
    g.add_mesh_node(
        "hanging",
        &fixtures::quad([
            [0.5, 2.0, -0.5],
            [0.5, 2.0, 0.5],
            [0.5, 1.0, 0.5],
            [0.5, 1.0, -0.5],
        ]),
        m,
    );
    agrees_with_fine_uniform("occluder touching emitter", &g.to_glb(), 0.02);
}

#[test]
fn occluder_crossing_the_receiver() {
    let mut g = GlbBuilder::new();
    let grey = floor_and_light(&mut g);
    g.add_mesh_node(
        "sunk box",
        &fixtures::cuboid([-0.3, -0.5, -0.3], [0.3, 0.5, 0.3]),
        grey,
    );
    let b = agrees_with_fine_uniform("crossing box", &g.to_glb(), 0.03);
    let floor = b.scene.polygons.iter().position(|p| p.area > 15.0).unwrap();
    assert!(
        b.segments[floor]
            .iter()
            .filter(|s| s.kind == penumbra::discontinuity::Kind::D0)
            .count()
            >= 4,
        "the crossing must give D0 lines"
    );
}

#[test]
fn nearly_coincident_occluders() {
    let mut g = GlbBuilder::new();
    floor_and_light(&mut g);
    let m = g.add_material(Material::diffuse("plate", [0.5; 3]).double_sided());
    let sq = [[-0.5, -0.5], [-0.5, 0.5], [0.5, 0.5], [0.5, -0.5]];
    g.add_mesh_node("plate a", &plate(1.0, sq), m);
    g.add_mesh_node(
        "plate b",
        &plate(1.0 + 1e-7, sq.map(|[x, z]| [x + 1e-7, z])),
        m,
    );
    agrees_with_fine_uniform("coincident occluders", &g.to_glb(), 0.02);
}

/// The generator lives in the library (benchmarks use it too); `crate::stability::box_grid`
/// stays for the other test modules.
pub use penumbra::fixtures::box_grid;

#[test]
fn box_grid_with_coplanar_tops_and_aligned_edges() {
    // 2400 charts need a larger lightmap than the quick default.
    let o = BakeOptions {
        resolution: Some(512),
        budget: 20_000,
        ..dm()
    };
    let b = crate::bake(&box_grid(20), &o);
    let d = b.stats.discontinuity.as_ref().unwrap();
    assert_eq!(d.refused, 0, "{d:?}");
    assert!(d.kept > 0 && d.d0 >= 1600, "{d:?}");
    // Budget held (the D0 footprints alone need about 1600 x 8 elements here).
    assert!(
        b.stats.elements * 4 <= 20_000 * 5,
        "budget not held: {} elements",
        b.stats.elements
    );
    assert_eq!(b.scene.triangles.len(), 20 * 20 * 12 + 4);
}

/// A UV sphere of `rings` x `2 rings` quads.
fn sphere(center: [f64; 3], radius: f64, rings: usize) -> TriangleMesh {
    let mut m = TriangleMesh {
        positions: vec![],
        normals: None,
        texcoords: None,
        indices: vec![],
    };
    let seg = 2 * rings;
    for i in 0..=rings {
        let th = std::f64::consts::PI * i as f64 / rings as f64;
        for j in 0..seg {
            let ph = 2.0 * std::f64::consts::PI * j as f64 / seg as f64;
            m.positions.push([
                center[0] + radius * th.sin() * ph.cos(),
                center[1] + radius * th.cos(),
                center[2] + radius * th.sin() * ph.sin(),
            ]);
        }
    }
    for i in 0..rings {
        for j in 0..seg {
            let a = (i * seg + j) as u32;
            let b = (i * seg + (j + 1) % seg) as u32;
            let c = a + seg as u32;
            let d = b + seg as u32;
            if i > 0 {
                m.indices.extend([a, b, c]);
            }
            if i + 1 < rings {
                m.indices.extend([b, d, c]);
            }
        }
    }
    m
}

#[test]
fn finely_tessellated_sphere_stays_within_budget() {
    let mut g = GlbBuilder::new();
    let grey = floor_and_light(&mut g);
    g.add_mesh_node("sphere", &sphere([0.0, 1.0, 0.0], 0.4, 40), grey);
    let bytes = g.to_glb();
    agrees_with_fine_uniform("tessellated sphere", &bytes, 0.03);
    // The sphere alone has 3120 triangles, each its own polygon, and refinement splits its
    // slivers at the poles: compare with the uniform mesher at the same budget.
    let o = BakeOptions {
        budget: 8000,
        ..dm()
    };
    let b = crate::bake(&bytes, &o);
    let u = crate::bake(
        &bytes,
        &BakeOptions {
            mesher: Mesher::Uniform,
            ..o.clone()
        },
    );
    let d = b.stats.discontinuity.as_ref().unwrap();
    assert!(d.dropped_budget > 0, "{d:?}");
    assert!(
        b.stats.elements * 4 <= u.stats.elements * 5,
        "mesh explosion: {} elements, uniform {}",
        b.stats.elements,
        u.stats.elements
    );
}

#[test]
fn same_result_at_tiny_and_huge_scales() {
    let base = fixtures::box_on_floor();
    let mut o = dm();
    o.solve.bounces = Some(0);
    let reference = polygon_means(&crate::bake(&base, &o));
    let peak = reference.iter().map(|m| m.x).fold(0.0, f64::max);
    for s in [1e-3, 1e4] {
        let b = crate::bake(&transformed(&base, json!({"scale": [s, s, s]})), &o);
        for (a, r) in polygon_means(&b).iter().zip(&reference) {
            assert!(
                (a.x - r.x).abs() < 0.01 * peak,
                "scale {s}: {} vs {}",
                a.x,
                r.x
            );
        }
    }
}

#[test]
fn rotating_and_translating_the_scene_keeps_the_light() {
    let base = fixtures::box_on_floor();
    let mut o = dm();
    o.solve.bounces = Some(0);
    let reference = polygon_means(&crate::bake(&base, &o));
    let peak = reference.iter().map(|m| m.x).fold(0.0, f64::max);
    let moved = transformed(
        &base,
        json!({"translation": [12.5, -3.0, 40.0], "rotation": [0.2126311, 0.3189466, 0.1063155, 0.9177546]}),
    );
    let b = crate::bake(&moved, &o);
    for (a, r) in polygon_means(&b).iter().zip(&reference) {
        assert!((a.x - r.x).abs() < 0.01 * peak, "{} vs {}", a.x, r.x);
    }
}
