//! The direct light measured: [`LightError`] (the light tree's cut against every emitter
//! exact) and [`LightShown`] (the light the mesh shows against a finer integration).

use crate::BakeOptions;
use crate::solve::{Direct, SurfacePoint};
use crate::visibility::Visibility;
use glam::DVec2;
use std::path::PathBuf;

/// Bakes one glb's direct light with every emitter exact (`--light-error 0`) and with the light
/// tree's cut at each error given, and prints both direct-light times, the exact evaluations,
/// the bounded nodes and the lightmap's RMSE between the two, relative to its mean.
#[derive(Clone, Debug, clap::Args)]
pub struct LightError {
    /// Input glTF scene.
    input: PathBuf,
    /// The light tree's errors to measure (as the bake's --light-error), comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "0.01")]
    light_error: Vec<f64>,
}

impl LightError {
    /// Runs the bakes and prints one line per bake and one per error measured.
    pub(crate) fn run(&self) -> anyhow::Result<()> {
        let gltf = super::read(&self.input)?;
        let errors: Vec<f64> = std::iter::once(0.0)
            .chain(self.light_error.iter().copied())
            .collect();
        let mut bakes = Vec::new();
        for &e in &errors {
            let mut o = BakeOptions::default();
            o.solve.bounces = Some(0);
            o.solve.light_error = e;
            let b = crate::bake(&gltf, &o, &|_, _, _| {})?;
            let d = &b.stats.solve.direct;
            println!(
                "light error {e}: direct {:.2} s, evaluations {}, bounded {}, rays {}",
                d.seconds, d.evaluations, d.bounded, b.stats.solve.rays
            );
            bakes.push(b);
        }
        let a = &bakes[0].lightmap;
        for (e, b) in errors.iter().zip(&bakes).skip(1) {
            let b = &b.lightmap;
            let covered: Vec<usize> = (0..a.texels.len())
                .filter(|&i| a.coverage.get(i).is_some_and(|c| *c > 0.0))
                .collect();
            let mean = covered
                .iter()
                .map(|&i| a.texels[i].element_sum() / 3.0)
                .sum::<f64>()
                / covered.len().max(1) as f64;
            let sq = covered
                .iter()
                .map(|&i| (a.texels[i] - b.texels[i]).length_squared() / 3.0)
                .sum::<f64>()
                / covered.len().max(1) as f64;
            let max = covered
                .iter()
                .map(|&i| (a.texels[i] - b.texels[i]).abs().max_element())
                .fold(0.0, f64::max);
            println!(
                "light error {e}: lightmap RMSE {:.3e} of the mean {mean:.4e}, max {:.3e} of the mean ({} texels)",
                sq.sqrt() / mean,
                max / mean,
                covered.len()
            );
        }
        Ok(())
    }
}

/// How much direct light the mesh shows, against a finer estimate on the same mesh: bakes one
/// glb, then integrates the direct light over every element twice: by the vertex rule (the mean
/// of its three exact vertex values, what the lightmap's linear interpolation shows) and by the
/// edge-midpoint rule (exact for a quadratic light, the light evaluated at its three edge
/// midpoints). Prints both totals against the power the area emitters send out (W), then the
/// polygons that lose the most light.
///
/// A polygon whose vertex rule is far below its midpoint rule has a peak between its vertices
/// that the mesh cannot show (a wall lit between a dark ceiling edge and a dark floor edge);
/// see `mesh::refine_by_light`.
#[derive(Clone, Debug, clap::Args)]
pub struct LightShown {
    /// Input glTF scene.
    input: PathBuf,
    /// Element budget [default: the bake's].
    #[arg(long)]
    budget: Option<usize>,
    /// How many of the polygons that lose the most light to list.
    #[arg(long, default_value_t = 10)]
    rows: usize,
}

impl LightShown {
    /// Runs the bake and prints the totals and the polygons.
    pub(crate) fn run(&self) -> anyhow::Result<()> {
        let gltf = super::read(&self.input)?;
        let options = BakeOptions {
            budget: self.budget,
            ..BakeOptions::default()
        };
        let bake = crate::bake(&gltf, &options, &|_, _, _| {})?;
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
                .map(|q: DVec2| {
                    SurfacePoint::new(frame.world_from_plane(q), frame.n, m.polygon, &vis)
                })
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
                by_midpoints +=
                    a * (0..3).map(|j| mean(at_midpoints[3 * k + j])).sum::<f64>() / 3.0;
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
        let total =
            |f: fn(&(usize, f64, f64, f64, usize)) -> f64| polygons.iter().map(f).sum::<f64>();
        let (v, q) = (total(|p| p.1), total(|p| p.2));
        let emitted = bake.stats.solve.emitted_power;
        println!(
            "{}: {} elements; direct light shown {v:.2} W (vertex rule), {q:.2} W (midpoint \
             rule), ratio {:.4}; area emitters send {emitted:.2} W",
            self.input.display(),
            bake.stats.elements,
            v / q
        );
        polygons.sort_by(|a, b| (b.2 - b.1).total_cmp(&(a.2 - a.1)).then(a.0.cmp(&b.0)));
        for (polygon, v, q, area, n) in polygons.iter().take(self.rows) {
            println!(
                "  polygon {polygon}: {v:.3} W of {q:.3} W ({:.0}%), {area:.2} m², {n} elements, normal {:.2}",
                100.0 * v / q.max(1e-12),
                scene.polygons[*polygon].frame.n
            );
        }
        Ok(())
    }
}
