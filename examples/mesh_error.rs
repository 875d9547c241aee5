//! How well each mesher's mesh shows the direct light, at one budget, with no Monte Carlo
//! reference: bakes the direct light only (`bounces 0`) with the uniform, discontinuity and
//! adaptive meshers, then compares what the lightmap shows inside every element (the linear
//! interpolation of its exact vertex values) with the exact direct light there, at seven points
//! per element (the centroid, the three points at barycentric (2/3, 1/6, 1/6) and the three edge
//! midpoints), leaving out the points buried under other geometry (never seen, as the
//! reference leaves out buried texels). Prints per mesher the elements, the mesh stage's seconds, the RMSE (area-weighted
//! over the points) as a fraction of the mean exact light over the lit points (those with any
//! direct light), the same over the lit points alone, and the light shown over the exact light
//! (the same points); then the same split between up-facing surfaces (ground, floors, roofs)
//! and the others, and the largest polygon's element sizes (how many slivers it holds):
//! `cargo run --release --example mesh_error -- scene.glb [BUDGET]` (`ONLY=discontinuity`: that
//! mesher alone).
//!
//! It isolates the mesh: the vertices' values are exact, so every error it measures is what
//! linear interpolation between them cannot show (a shadow edge across an element, a pool of
//! light between vertices). Fast enough for the scale ladder's scenes, where a Monte Carlo
//! reference takes minutes.

use glam::DVec2;
use penumbra::mesh::Mesher;
use penumbra::solve::{Direct, SurfacePoint};
use penumbra::visibility::Visibility;
use penumbra::{BakeOptions, load};
use std::path::Path;

/// Barycentric weights of the seven points per element.
const POINTS: [[f64; 3]; 7] = [
    [1.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0],
    [2.0 / 3.0, 1.0 / 6.0, 1.0 / 6.0],
    [1.0 / 6.0, 2.0 / 3.0, 1.0 / 6.0],
    [1.0 / 6.0, 1.0 / 6.0, 2.0 / 3.0],
    [0.5, 0.5, 0.0],
    [0.0, 0.5, 0.5],
    [0.5, 0.0, 0.5],
];

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
        let scene = &bake.scene;
        let vis = Visibility::new(scene);
        let direct = Direct::with_options(scene, &vis, &options.solve);
        let mean = |c: glam::DVec3| c.element_sum() / 3.0;
        // (weight m², shown, exact) per point, W/m².
        let mut samples: Vec<(f64, f64, f64)> = Vec::new();
        let mut by_class = [(0usize, 0.0f64, 0.0f64); 2];
        for (m, at_vertices) in bake.meshes.iter().zip(&bake.solution.direct) {
            let frame = &scene.polygons[m.polygon].frame;
            let class = usize::from(frame.n.y > 0.9);
            let first = samples.len();
            let mut points = Vec::new();
            let mut shown = Vec::new();
            for t in &m.triangles {
                let p = t.map(|i| m.vertices[i as usize]);
                let v = t.map(|i| mean(at_vertices[i as usize]));
                let a = 0.5 * (p[1] - p[0]).perp_dot(p[2] - p[0]).abs();
                for w in POINTS {
                    let q: DVec2 = p[0] * w[0] + p[1] * w[1] + p[2] * w[2];
                    let at = frame.world_from_plane(q);
                    // Ground under a box is never seen (the lightmap's buried texels).
                    if vis.buried(at, frame.n) {
                        continue;
                    }
                    points.push(SurfacePoint::new(at, frame.n, m.polygon, &vis));
                    shown.push((
                        a / POINTS.len() as f64,
                        v[0] * w[0] + v[1] * w[1] + v[2] * w[2],
                    ));
                }
            }
            let exact = direct.irradiance_points(&points);
            samples.extend(
                shown
                    .iter()
                    .zip(&exact)
                    .map(|(&(w, s), &e)| (w, s, mean(e))),
            );
            by_class[class].0 += m.triangles.len();
            for s in &samples[first..] {
                by_class[class].1 += s.0 * (s.1 - s.2).powi(2);
                by_class[class].2 += s.0;
            }
        }
        // The largest polygon's element areas (usually the ground): how many are slivers, far
        // below the typical element, and how much of its area they cover.
        if let Some(m) = bake
            .meshes
            .iter()
            .max_by(|a, b| a.area().total_cmp(&b.area()))
        {
            let mut areas: Vec<f64> = m
                .triangles
                .iter()
                .map(|t| {
                    let p = t.map(|i| m.vertices[i as usize]);
                    0.5 * (p[1] - p[0]).perp_dot(p[2] - p[0]).abs()
                })
                .collect();
            areas.sort_by(f64::total_cmp);
            let q = |f: f64| areas[((areas.len() - 1) as f64 * f) as usize];
            let total: f64 = areas.iter().sum();
            // Its elements buried under other geometry (the ground under a building): never
            // seen, so any there are spent for nothing.
            let frame = &scene.polygons[m.polygon].frame;
            let buried = m
                .triangles
                .iter()
                .filter(|t| {
                    let p = t.map(|i| m.vertices[i as usize]);
                    vis.buried(frame.world_from_plane((p[0] + p[1] + p[2]) / 3.0), frame.n)
                })
                .count();
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
                100.0 * tiny.iter().sum::<f64>() / total
            );
        }
        let lit: Vec<&(f64, f64, f64)> = samples.iter().filter(|s| s.2 > 0.0).collect();
        let sum =
            |it: &mut dyn Iterator<Item = &(f64, f64, f64)>,
             f: &dyn Fn(&(f64, f64, f64)) -> f64| { it.map(f).sum::<f64>() };
        let lit_area = sum(&mut lit.iter().copied(), &|s| s.0);
        let lit_mean = sum(&mut lit.iter().copied(), &|s| s.0 * s.2) / lit_area;
        let area = sum(&mut samples.iter(), &|s| s.0);
        let rmse = (sum(&mut samples.iter(), &|s| s.0 * (s.1 - s.2).powi(2)) / area).sqrt();
        let rmse_lit =
            (sum(&mut lit.iter().copied(), &|s| s.0 * (s.1 - s.2).powi(2)) / lit_area).sqrt();
        let shown = sum(&mut samples.iter(), &|s| s.0 * s.1);
        let exact = sum(&mut samples.iter(), &|s| s.0 * s.2);
        println!(
            "  {mesher:?}: {} elements, mesh {:.2} s; RMSE {:.2}% of the lit mean (lit points {:.2}%), shown/exact {:.4}",
            bake.stats.elements,
            bake.stats.timings_s.mesh,
            100.0 * rmse / lit_mean,
            100.0 * rmse_lit / lit_mean,
            shown / exact
        );
        for (name, (n, e2, a)) in ["other surfaces", "up-facing surfaces"]
            .iter()
            .zip(by_class)
        {
            println!(
                "    {name}: {n} elements, {a:.3} units², {:.1}% of the squared error, RMSE there {:.2}%",
                100.0 * e2 / (rmse * rmse * area),
                100.0 * (e2 / a).sqrt() / lit_mean
            );
        }
    }
    Ok(())
}
