//! How much direct light the mesh shows, against a finer estimate on the same mesh: bakes one
//! glb (default options, or `BUDGET` elements; `-` for the default), then integrates the direct light over every
//! element twice: by the vertex rule (the mean of its three exact vertex values, what the
//! lightmap's linear interpolation shows) and by the edge-midpoint rule (exact for a quadratic
//! light, the light evaluated at its three edge midpoints). Prints both totals against the
//! power the area emitters send out (W), then the polygons that lose the most light:
//! `cargo run --release --example light_shown -- scene.glb [BUDGET] [ROWS]`.
//!
//! A polygon whose vertex rule is far below its midpoint rule has a peak between its
//! vertices that the mesh cannot show (a wall lit between a dark ceiling edge and a dark floor
//! edge); see `mesh::refine_by_light`.

use glam::DVec2;
use penumbra::solve::{Direct, SurfacePoint};
use penumbra::visibility::Visibility;
use penumbra::{BakeOptions, load};
use std::path::Path;

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let path = args
        .next()
        .ok_or_else(|| anyhow::anyhow!("usage: light_shown SCENE.glb [BUDGET] [ROWS]"))?;
    let options = BakeOptions {
        budget: args
            .next()
            .filter(|s| s != "-")
            .map(|s| s.parse())
            .transpose()?,
        ..BakeOptions::default()
    };
    let rows: usize = args.next().map(|s| s.parse()).transpose()?.unwrap_or(10);
    let gltf = load::read(Path::new(&path))?;
    let bake = penumbra::bake(&gltf, &options, &|_, _, _| {})?;
    let scene = &bake.scene;
    let vis = Visibility::new(scene);
    let direct = Direct::with_options(scene, &vis, &options.solve);
    let mean = |c: glam::DVec3| c.element_sum() / 3.0;
    // Per polygon: (vertex rule, midpoint rule, area, elements), W and m².
    let mut polygons = Vec::new();
    for (m, at_vertices) in bake.meshes.iter().zip(&bake.solution.direct) {
        let frame = &scene.polygons[m.polygon].frame;
        let corners = |t: &[u32; 3]| t.map(|i| m.vertices[i as usize]);
        let midpoints: Vec<SurfacePoint> = m
            .triangles
            .iter()
            .flat_map(|t| {
                let p = corners(t);
                [
                    (p[0] + p[1]) * 0.5,
                    (p[1] + p[2]) * 0.5,
                    (p[2] + p[0]) * 0.5,
                ]
            })
            .map(|q: DVec2| SurfacePoint::new(frame.world_from_plane(q), frame.n, m.polygon, &vis))
            .collect();
        let at_midpoints = direct.irradiance_points(&midpoints);
        let (mut by_vertices, mut by_midpoints, mut area) = (0.0, 0.0, 0.0);
        for (k, t) in m.triangles.iter().enumerate() {
            let a = m.triangle_area(t);
            by_vertices += a * t
                .iter()
                .map(|&i| mean(at_vertices[i as usize]))
                .sum::<f64>()
                / 3.0;
            by_midpoints += a * (0..3).map(|j| mean(at_midpoints[3 * k + j])).sum::<f64>() / 3.0;
            area += a;
        }
        polygons.push((
            m.polygon,
            by_vertices,
            by_midpoints,
            area,
            m.triangles.len(),
        ));
    }
    let total = |f: fn(&(usize, f64, f64, f64, usize)) -> f64| polygons.iter().map(f).sum::<f64>();
    let (v, q) = (total(|p| p.1), total(|p| p.2));
    let emitted = bake.stats.solve.emitted_power;
    println!(
        "{path}: {} elements; direct light shown {v:.2} W (vertex rule), {q:.2} W (midpoint \
         rule), ratio {:.4}; area emitters send {emitted:.2} W",
        bake.stats.elements,
        v / q
    );
    polygons.sort_by(|a, b| (b.2 - b.1).total_cmp(&(a.2 - a.1)).then(a.0.cmp(&b.0)));
    for (polygon, v, q, area, n) in polygons.iter().take(rows) {
        println!(
            "  polygon {polygon}: {v:.3} W of {q:.3} W ({:.0}%), {area:.2} m², {n} elements, normal {:.2}",
            100.0 * v / q.max(1e-12),
            scene.polygons[*polygon].frame.n
        );
    }
    Ok(())
}
