//! Mixed lighting: lights baked for their bounces only (`bake: indirect`), not at all
//! (`none`), and light groups written as layers. Radiosity is linear in the lights' power, so
//! the known answers are sums: the layers add up to the bake of all lights, and a light's
//! bounces plus its direct light give its full light.

use crate::output::split_glb;
use crate::{bake, parse, quick};
use glam::DVec3;
use penumbra::fixtures::{
    GlbBuilder, Light, Material, Node, Transform, add_unit_box, horizontal_rect, quad,
};
use penumbra::scene::mixed::CliRule;
use penumbra::{Bake, BakeOptions};
use serde_json::json;

/// A box on a floor beside a wall, lit by an emissive panel (`panel`, material "panel") above
/// and a point light (`lamp`) to the side; grey surfaces, so the bounces matter.
fn room() -> Vec<u8> {
    let mut b = GlbBuilder::new();
    let grey = b.add_material(Material::diffuse("grey", [0.6; 3]));
    b.add_mesh_node(
        "floor",
        &horizontal_rect([-2.0, 2.0], [-2.0, 2.0], 0.0, true),
        grey,
    );
    b.add_mesh_node(
        "wall",
        &quad([
            [-2.0, 0.0, 2.0],
            [-2.0, 0.0, -2.0],
            [-2.0, 2.5, -2.0],
            [-2.0, 2.5, 2.0],
        ]),
        grey,
    );
    add_unit_box(&mut b, grey, false);
    let panel = b.add_material(Material::diffuse("panel", [0.0; 3]).emitting([4.0; 3]));
    b.add_mesh_node(
        "panel",
        &horizontal_rect([-1.2, -0.4], [-0.4, 0.4], 2.4, false),
        panel,
    );
    let lamp = b.add_light(Light::point("lamp", 6.0));
    b.add_node(
        Node::new("lamp")
            .with_transform(Transform::translation([1.4, 1.3, 1.1]))
            .with_light(lamp),
    );
    b.to_glb()
}

fn with(rules: &[CliRule]) -> BakeOptions {
    BakeOptions {
        lights: rules.to_vec(),
        resolution: Some(128),
        ..quick()
    }
}

fn group(text: &str) -> CliRule {
    CliRule::group(text).unwrap()
}

fn mode(text: &str) -> CliRule {
    CliRule::bake(text).unwrap()
}

/// The largest difference between two maps' texels (any channel), over `a`'s peak.
fn worst(a: &[DVec3], b: &[DVec3], peak: f64) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (*x - *y).abs().max_element())
        .fold(0.0, f64::max)
        / peak
}

fn sum(maps: &[&[DVec3]]) -> Vec<DVec3> {
    (0..maps[0].len())
        .map(|i| maps.iter().map(|m| m[i]).sum())
        .collect()
}

fn layer<'a>(b: &'a Bake, name: &str) -> &'a [DVec3] {
    &b.layers
        .iter()
        .find(|(n, _)| n == name)
        .unwrap_or_else(|| panic!("no layer {name}"))
        .1
        .texels
}

#[test]
fn the_groups_add_up_to_the_bake_of_all_lights() {
    let all = bake(&room(), &with(&[]));
    assert!(all.layers.is_empty());
    let grouped = bake(
        &room(),
        &with(&[group("lamp=lamp"), group("panel=ceiling")]),
    );
    let peak = all.lightmap.max_value();
    let (lamp, ceiling) = (layer(&grouped, "lamp"), layer(&grouped, "ceiling"));
    // Each layer holds a real part of the light: neither is nearly all of it.
    let mean = |m: &[DVec3]| m.iter().map(|t| t.x).sum::<f64>() / m.len() as f64;
    let whole = mean(&all.lightmap.texels);
    for (name, part) in [("lamp", lamp), ("ceiling", ceiling)] {
        let share = mean(part) / whole;
        assert!((0.1..0.9).contains(&share), "{name}: {share}");
    }
    // Measured: the same texels.
    let main = worst(&grouped.lightmap.texels, &all.lightmap.texels, peak);
    assert!(
        main < 1e-4,
        "the main lightmap moved by {main:e} of the peak"
    );
    // Measured: 4e-16. Solving each group's bounces to the tolerance instead of for the
    // whole's iterations was 5.6e-4 off, and without the whole's clamp of the gradients 2.5e-4.
    let layers = worst(&sum(&[lamp, ceiling]), &all.lightmap.texels, peak);
    assert!(
        layers < 1e-4,
        "the layers add up to within {layers:e} of the peak"
    );
}

#[test]
fn a_lights_bounces_plus_its_direct_light_are_its_whole_light() {
    let all = bake(&room(), &with(&[]));
    let peak = all.lightmap.max_value();
    let bounces = bake(&room(), &with(&[mode("lamp=indirect")]));
    // The lamp's direct light alone: its layer in a bake without bounces.
    let mut direct_only = with(&[group("lamp=lamp")]);
    direct_only.solve.bounces = Some(0);
    let direct = bake(&room(), &direct_only);
    let err = worst(
        &sum(&[&bounces.lightmap.texels, layer(&direct, "lamp")]),
        &all.lightmap.texels,
        peak,
    );
    // Measured: 4e-16.
    assert!(
        err < 1e-4,
        "indirect + direct is {err:e} of the peak off all"
    );
    // And the bounces are there: the bake without the lamp at all is darker still.
    let none = bake(&room(), &with(&[mode("lamp=none")]));
    let total = |m: &[DVec3]| m.iter().map(|t| t.element_sum()).sum::<f64>();
    let (a, i, n) = (
        total(&all.lightmap.texels),
        total(&bounces.lightmap.texels),
        total(&none.lightmap.texels),
    );
    assert!(
        a > i && i > n,
        "all {a}, bounces only {i}, without the lamp {n}"
    );
    // The lamp's bounce is a modest part of its light in this open room: 5% to 60%.
    let bounce_share = (i - n) / (a - n);
    assert!((0.05..0.6).contains(&bounce_share), "{bounce_share}");
}

#[test]
fn rules_in_the_extras_work_as_the_command_line_does() {
    let (mut json, bin) = split_glb(&room());
    let lamp_light = json["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|n| n["name"] == "lamp")
        .unwrap()["extensions"]["KHR_lights_punctual"]["light"]
        .as_u64()
        .unwrap() as usize;
    json["extensions"]["KHR_lights_punctual"]["lights"][lamp_light]["extras"] =
        json!({"penumbra_bake": "indirect"});
    let panel = json["materials"]
        .as_array()
        .unwrap()
        .iter()
        .position(|m| m["name"] == "panel")
        .unwrap();
    json["materials"][panel]["extras"] = json!({"penumbra_group": "ceiling"});
    let input = penumbra::write::to_glb(&json, bin.clone()).unwrap();
    let from_extras = bake(&input, &with(&[]));
    let from_cli = bake(
        &room(),
        &with(&[mode("lamp=indirect"), group("panel=ceiling")]),
    );
    assert_eq!(from_extras.lightmap, from_cli.lightmap);
    assert_eq!(from_extras.layers, from_cli.layers);
    // The command line wins over the extras.
    let overridden = bake(&input, &with(&[mode("lamp=all")]));
    let all = bake(&room(), &with(&[group("panel=ceiling")]));
    assert_eq!(overridden.lightmap, all.lightmap);

    // The written file: one layer texture per group and page, listed in MOZ_lightmap's extras.
    let gltf = parse(&input, "in.glb");
    let mut b = from_extras;
    let out = penumbra::bake::glb_bytes(&gltf, &mut b, penumbra::lightmap::Encoding::Srgb).unwrap();
    let (out, _) = split_glb(&out);
    let moz = &out["materials"][0]["extensions"]["MOZ_lightmap"];
    let layers = moz["extras"]["penumbra"]["layers"].as_array().unwrap();
    assert_eq!(layers.len(), 1);
    assert_eq!(layers[0]["group"], "ceiling");
    let tex = layers[0]["index"].as_u64().unwrap() as usize;
    assert_eq!(
        out["textures"][tex]["extras"]["penumbra"]["layer"],
        "ceiling"
    );
    assert!(layers[0]["intensity"].as_f64().unwrap() > 0.0);

    // A rule that is not one is refused, naming the item.
    json["extensions"]["KHR_lights_punctual"]["lights"][lamp_light]["extras"] =
        json!({"penumbra_bake": "direct"});
    let bad = penumbra::write::to_glb(&json, bin).unwrap();
    let e = penumbra::bake(&parse(&bad, "bad.glb"), &with(&[]), crate::no_progress())
        .err()
        .expect("refused")
        .to_string();
    assert!(
        e.contains("bad.glb")
            && e.contains(&format!("lights[{lamp_light}]"))
            && e.contains("indirect"),
        "{e}"
    );
}

#[test]
fn light_groups_need_the_hierarchical_solver() {
    let mut options = with(&[group("lamp=lamp")]);
    options.solve.solver = penumbra::solve::Solver::Progressive;
    let e = penumbra::bake(&parse(&room(), "room.glb"), &options, crate::no_progress())
        .err()
        .expect("refused")
        .to_string();
    assert!(
        e.contains("--solver hierarchical") && e.contains("lamp"),
        "{e}"
    );
    // `indirect` works with the patch solvers too.
    let mut options = with(&[mode("lamp=indirect")]);
    options.solve.solver = penumbra::solve::Solver::Progressive;
    bake(&room(), &options);
}

/// Two lamp panels in two groups before a black wall: one 0.3 m from it, whose elements take
/// its light per texel, and a large one 30 m away, whose light they interpolate. Each group
/// measures the unoccluded light only of its own lamps; the main lightmap, which takes both,
/// must divide by both: the same texels as the bake without groups.
#[test]
fn groups_near_and_far_from_a_receiver_bake_as_one() {
    let scene = || {
        let mut b = crate::direct::lamp_and_wall([
            [-0.25, 1.25, 0.3],
            [-0.25, 1.75, 0.3],
            [0.25, 1.75, 0.3],
            [0.25, 1.25, 0.3],
        ]);
        let far = b.add_material(Material::diffuse("far", [0.0; 3]).emitting([400.0; 3]));
        b.add_mesh_node(
            "far",
            &quad([
                [-2.0, 0.0, 30.0],
                [-2.0, 3.0, 30.0],
                [2.0, 3.0, 30.0],
                [2.0, 0.0, 30.0],
            ]),
            far,
        );
        b.to_glb()
    };
    let options = |rules: &[CliRule]| BakeOptions {
        mesher: penumbra::mesh::Mesher::Uniform,
        budget: Some(40),
        ..with(rules)
    };
    let all = bake(&scene(), &options(&[]));
    let grouped = bake(&scene(), &options(&[group("lamp=near"), group("far=far")]));
    let peak = all.lightmap.max_value();
    let (near, far) = (layer(&grouped, "near"), layer(&grouped, "far"));
    let main = worst(&grouped.lightmap.texels, &all.lightmap.texels, peak);
    let layers = worst(&sum(&[near, far]), &all.lightmap.texels, peak);
    // Measured: 0 and 6.7e-4 (3e3 and 1.6e-3 when each group measured the unoccluded light
    // only where its own lamps are near). The layers differ from the whole where the near
    // panel shadows the far one: the whole takes one visible fraction for both lamps.
    assert!(
        main < 1e-9 && layers < 1e-3,
        "the main lightmap is {main:e}, the layers' sum {layers:e} of the peak off"
    );
}
