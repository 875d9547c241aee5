//! How well each mesher's mesh shows the direct light, at one budget, with no Monte Carlo
//! reference ([`penumbra::compare::mesh_samples`]): bakes the direct light only (`bounces 0`)
//! with the uniform, discontinuity and adaptive meshers and prints per mesher the elements, the
//! mesh stage's seconds, the RMSE over all points and over the lit ones (fractions of the mean
//! lit light) and the light shown over the exact light; then the same split between up-facing
//! surfaces (ground, floors, roofs) and the others, and the largest polygon's element sizes
//! (how many slivers it holds, how many lie buried):
//! `cargo run --release --example mesh_error -- scene.glb [BUDGET]` (`ONLY=discontinuity`: that
//! mesher alone). Fast enough for the scale ladder's scenes, where a Monte Carlo reference takes
//! minutes.

use penumbra::compare::{MeshSample, mesh_error, mesh_samples};
use penumbra::mesh::{Mesher, ReceiverMesh};
use penumbra::scene::Scene;
use penumbra::solve::Direct;
use penumbra::visibility::Visibility;
use penumbra::{BakeOptions, load};
use std::path::Path;

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let path = args
        .next()
        .ok_or_else(|| anyhow::anyhow!("usage: mesh_error SCENE.glb [BUDGET]"))?;
    let budget: Option<usize> = args.next().map(|s| s.parse()).transpose()?;
    let gltf = load::read(Path::new(&path))?;
    println!("{path}");
    let meshers: Vec<Mesher> = match std::env::var("ONLY").as_deref() {
        Ok("discontinuity") => vec![Mesher::Discontinuity],
        _ => vec![Mesher::Uniform, Mesher::Discontinuity, Mesher::Adaptive],
    };
    for mesher in meshers {
        let mut options = BakeOptions {
            budget,
            mesher,
            ..BakeOptions::default()
        };
        options.solve.bounces = Some(0);
        let bake = penumbra::bake(&gltf, &options, &|_, _, _| {})?;
        let vis = Visibility::new(&bake.scene);
        let direct = Direct::with_options(&bake.scene, &vis, &options.solve);
        let samples = mesh_samples(&bake, &vis, &direct);
        let Some(e) = mesh_error(&samples) else {
            println!("  {mesher:?}: no direct light");
            continue;
        };
        if let Some(m) = bake
            .meshes
            .iter()
            .max_by(|a, b| a.area().total_cmp(&b.area()))
        {
            largest_polygon(&bake.scene, &vis, m);
        }
        println!(
            "  {mesher:?}: {} elements, mesh {:.2} s; RMSE {:.2}% of the lit mean (lit points \
             {:.2}%), shown/exact {:.4}",
            bake.stats.elements,
            bake.stats.timings_s.mesh,
            100.0 * e.rmse,
            100.0 * e.rmse_lit,
            e.shown_over_exact
        );
        // Split by orientation: up-facing (normal within 26° of +y) and the others.
        let up = |s: &MeshSample| bake.scene.polygons[s.polygon].frame.n.y > 0.9;
        let squared = |s: &MeshSample| s.weight * (s.shown - s.exact).powi(2);
        let total: f64 = samples.iter().map(squared).sum();
        for (name, is_up) in [("other surfaces", false), ("up-facing surfaces", true)] {
            let part: Vec<&MeshSample> = samples.iter().filter(|s| up(s) == is_up).collect();
            let elements: usize = bake
                .meshes
                .iter()
                .filter(|m| (bake.scene.polygons[m.polygon].frame.n.y > 0.9) == is_up)
                .map(|m| m.triangles.len())
                .sum();
            let area: f64 = part.iter().map(|s| s.weight).sum();
            let e2: f64 = part.iter().map(|s| squared(s)).sum();
            println!(
                "    {name}: {elements} elements, {area:.3} units² seen, {:.1}% of the squared \
                 error, RMSE there {:.2}%",
                100.0 * e2 / total.max(1e-300),
                100.0 * (e2 / area.max(1e-300)).sqrt() / e.lit_mean
            );
        }
    }
    Ok(())
}

/// Prints the element sizes of `m` (usually the ground): how many are slivers, far below the
/// typical element, the share of its area they cover, and how many lie buried under other
/// geometry (the ground under a building: never seen, so spent for nothing).
fn largest_polygon(scene: &Scene, vis: &Visibility, m: &ReceiverMesh) {
    let frame = &scene.polygons[m.polygon].frame;
    let corners = |t: &[u32; 3]| t.map(|i| m.vertices[i as usize]);
    let mut areas: Vec<f64> = m.triangles.iter().map(|t| m.triangle_area(t)).collect();
    if areas.is_empty() {
        return;
    }
    let buried = m
        .triangles
        .iter()
        .filter(|t| {
            let p = corners(t);
            vis.buried(frame.world_from_plane((p[0] + p[1] + p[2]) / 3.0), frame.n)
        })
        .count();
    areas.sort_by(f64::total_cmp);
    let q = |f: f64| areas[((areas.len() - 1) as f64 * f) as usize];
    let total: f64 = areas.iter().sum();
    let tiny: Vec<f64> = areas
        .iter()
        .copied()
        .filter(|&a| a < 0.1 * q(0.9))
        .collect();
    println!(
        "    largest polygon {}: {total:.3} units², {} elements, areas at the 10th/50th/90th \
         percentile {:.3}/{:.3}/{:.3}; {} under a tenth of the 90th, on {:.1}% of its area; \
         {buried} buried",
        m.polygon,
        areas.len(),
        q(0.1),
        q(0.5),
        q(0.9),
        tiny.len(),
        100.0 * tiny.iter().sum::<f64>() / total + 0.0
    );
}
