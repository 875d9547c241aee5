//! The meshes measured: [`MeshError`] (each mesher's mesh against the exact direct light) and
//! [`DmCoverage`] (how much of the discontinuity lines the mesh follows).

use crate::BakeOptions;
use crate::bake::meshes;
use crate::compare::{MeshSample, mesh_error, mesh_samples};
use crate::mesh::{Mesher, ReceiverMesh};
use crate::scene::Scene;
use crate::solve::Direct;
use crate::visibility::Visibility;
use std::path::PathBuf;

/// How well each mesher's mesh shows the direct light, at one budget, with no Monte Carlo
/// reference ([`crate::compare::mesh_samples`]): bakes the direct light only (`bounces 0`) with
/// each mesher and prints per mesher the elements, the mesh stage's seconds, the RMSE over all
/// points and over the lit ones (fractions of the mean lit light) and the light shown over the
/// exact light; then the same split between up-facing surfaces (ground, floors, roofs) and the
/// others, and the largest polygon's element sizes (how many slivers it holds, how many lie
/// buried). Fast enough for the scale ladder's scenes, where a Monte Carlo reference takes
/// minutes.
#[derive(Clone, Debug, clap::Args)]
pub struct MeshError {
    /// Input glTF scene.
    input: PathBuf,
    /// Element budget [default: the bake's].
    #[arg(long)]
    budget: Option<usize>,
    /// The meshers, comma-separated: uniform, discontinuity, adaptive.
    #[arg(
        long,
        value_enum,
        value_delimiter = ',',
        default_value = "uniform,discontinuity,adaptive"
    )]
    #[arg(hide_possible_values = true)]
    meshers: Vec<Mesher>,
}

impl MeshError {
    /// Runs one direct-light bake per mesher and prints its errors.
    pub(crate) fn run(&self) -> anyhow::Result<()> {
        let gltf = super::read(&self.input)?;
        println!("{}", self.input.display());
        for &mesher in &self.meshers {
            let mut options = BakeOptions {
                budget: self.budget,
                mesher,
                ..BakeOptions::default()
            };
            options.solve.bounces = Some(0);
            let bake = crate::bake(&gltf, &options, &|_, _, _| {})?;
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

/// How much of the discontinuity lines the mesh follows, at the default options: for every
/// wedge segment (all kinds but D0) of every receiver, 8 points along it count as followed when
/// they lie within 5 cm of a mesh edge on a discontinuity or of the polygon's outline; prints
/// the followed fraction of the segments' total length. Pieces dropped for the budget, left out
/// as crowded or shortened near the outline are what it misses.
#[derive(Clone, Debug, clap::Args)]
pub struct DmCoverage {
    /// Input glTF scene.
    input: PathBuf,
}

impl DmCoverage {
    /// Meshes the scene and prints the followed length.
    pub(crate) fn run(&self) -> anyhow::Result<()> {
        let gltf = super::read(&self.input)?;
        let (scene, segments, meshes, _) = meshes(&gltf, &BakeOptions::default())?;
        let (mut total, mut covered) = (0.0, 0.0);
        for m in &meshes {
            let segs = &segments[m.polygon];
            let mut edges: Vec<_> = m
                .constraints
                .iter()
                .map(|c| (m.vertices[c.a as usize], m.vertices[c.b as usize]))
                .collect();
            edges.extend(
                scene.polygons[m.polygon]
                    .boundary
                    .iter()
                    .map(|[a, b]| (*a, *b)),
            );
            for s in segs.iter().filter(|s| s.kind.is_wedge()) {
                let len = s.a.distance(s.b);
                total += len;
                // 8 points along it, each followed when within 5 cm of an edge.
                let mut c = 0;
                let poly = &scene.polygons[m.polygon];
                let inside = (0..8)
                    .filter(|k| poly.contains(s.a.lerp(s.b, (*k as f64 + 0.5) / 8.0)))
                    .count();
                total -= len * (8 - inside) as f64 / 8.0;
                for k in 0..8 {
                    let p = s.a.lerp(s.b, (k as f64 + 0.5) / 8.0);
                    if !poly.contains(p) {
                        continue;
                    }
                    if edges.iter().any(|(a, b)| {
                        let d = *b - *a;
                        let t = ((p - *a).dot(d) / d.length_squared()).clamp(0.0, 1.0);
                        (*a + d * t).distance(p) < 0.05
                    }) {
                        c += 1;
                    }
                }
                covered += len * c as f64 / 8.0;
            }
        }
        println!(
            "wedge length {total:.1}, in the mesh {covered:.1} ({:.1}%)",
            100.0 * covered / total
        );
        Ok(())
    }
}
