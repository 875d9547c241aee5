//! The indirect solvers measured: [`SolverError`] against a Monte Carlo reference of the
//! lightmap, [`SolverDiff`] against each other at the mesh vertices.

use crate::compare::{classify, lightmap_error, mean_lit_irradiance};
use crate::discontinuity::Kind;
use crate::light::{SurfacePoint, luminance};
use crate::load;
use crate::reference::{ReferenceOptions, TexelLayout, reference_with, texel_layout};
use crate::solve::Solver;
use crate::visibility::Visibility;
use crate::{Bake, BakeOptions};
use std::path::PathBuf;

/// Bakes one glb with each solver and measures every lightmap against one Monte Carlo
/// reference, by region (`penumbra compare`'s measure), with the signed mean error per region
/// (a bias, which the reference's noise averages out of).
#[derive(Clone, Debug, clap::Args)]
pub struct SolverError {
    /// Input glTF scene.
    input: PathBuf,
    /// Reference paths per texel.
    #[arg(long, default_value_t = 256)]
    spp: u32,
    /// Element budget [default: the bake's].
    #[arg(long)]
    budget: Option<usize>,
    /// The hierarchical solver's tolerance [default: the bake's].
    #[arg(long)]
    hr_tolerance: Option<f64>,
    /// Lightmap width and height.
    #[arg(long, default_value_t = 256)]
    resolution: u32,
    /// Sub-samples per texel side, for the bakes and the reference.
    #[arg(long, default_value_t = 4)]
    supersample: u32,
    /// The solvers, comma-separated: progressive, hierarchical, matrix.
    #[arg(
        long,
        value_enum,
        value_delimiter = ',',
        default_value = "progressive,hierarchical"
    )]
    #[arg(hide_possible_values = true)]
    solvers: Vec<Solver>,
    /// Patch counts of the patch solvers, comma-separated: one bake each.
    #[arg(long, value_delimiter = ',')]
    patches: Vec<usize>,
    /// Tolerances of the hierarchical solver, comma-separated: one bake each.
    #[arg(long, value_delimiter = ',')]
    tolerances: Vec<f64>,
    /// Also print the bias per region and polygon (polygons of 20 texels or more).
    #[arg(long)]
    by_polygon: bool,
}

impl SolverError {
    /// Runs the bakes and the reference; prints one line of errors and one of biases per bake.
    pub(crate) fn run(&self) -> anyhow::Result<()> {
        let gltf = super::read(&self.input)?;
        let mut options = BakeOptions {
            resolution: Some(self.resolution),
            supersample: self.supersample,
            budget: self.budget,
            ..BakeOptions::default()
        };
        if let Some(t) = self.hr_tolerance {
            options.solve.hr_tolerance = t;
        }
        let mut bakes = Vec::new();
        // One bake per patch count of a patch solver and per tolerance of the hierarchical one
        // (a speed/accuracy sweep against the one reference); one at the options when none is
        // given.
        let settings = |given: Vec<Option<f64>>| {
            if given.is_empty() { vec![None] } else { given }
        };
        for &solver in &self.solvers {
            let settings = match solver {
                Solver::Hierarchical => {
                    settings(self.tolerances.iter().map(|&t| Some(t)).collect())
                }
                _ => settings(self.patches.iter().map(|&p| Some(p as f64)).collect()),
            };
            for setting in settings {
                let mut o = options.clone();
                o.solve.solver = solver;
                let label = match (solver, setting) {
                    (Solver::Hierarchical, Some(t)) => {
                        o.solve.hr_tolerance = t;
                        format!("{solver:?} (tolerance {t:e})")
                    }
                    (_, Some(p)) => {
                        o.solve.patches = p as usize;
                        format!("{solver:?} ({p} patches)")
                    }
                    (_, None) => format!("{solver:?}"),
                };
                let b = crate::bake(&gltf, &o, &|_, _, _| {})?;
                bakes.push((label, b));
            }
        }
        anyhow::ensure!(!bakes.is_empty(), "--solvers names no solver");
        let tmp = std::env::temp_dir().join("penumbra-solver-error.glb");
        let bytes = crate::bake::glb_bytes(&gltf, &mut bakes[0].1, options.encoding)?;
        std::fs::write(&tmp, bytes)?;
        let baked = load::read(&tmp)?;
        let scene = load::scene(&baked)?;
        let vis = Visibility::new(&scene);
        let layout = texel_layout(&baked, &scene, &vis, options.supersample)?;
        let refmap = reference_with(
            &scene,
            &vis,
            &layout,
            &ReferenceOptions {
                spp: self.spp,
                seed: 0,
                bounces_max: None,
                supersample: options.supersample,
                sky: options.solve.sky,
            },
        );
        let texels_per_unit = bakes[0].1.atlas.texels_per_unit as f64;
        let regions = classify(&refmap, 3.0 / texels_per_unit);
        let scale = mean_lit_irradiance(&refmap, &regions);
        for (label, b) in &bakes {
            let (all, by) = lightmap_error(&b.lightmap, &refmap, &regions, scale);
            print!(
                "{label}: solve {:.2} s, elements {}: all rmse {:.4} max {:.3}",
                b.stats.timings_s.solve, b.stats.elements, all.rmse, all.max
            );
            for (r, e) in by {
                print!(" | {} rmse {:.4} max {:.3}", r.name(), e.rmse, e.max);
            }
            println!();
            // The signed mean error per region (bake minus reference, channel mean, as a fraction
            // of the lit mean): a bias shows here, while the reference's noise averages out.
            let mut bias: std::collections::BTreeMap<&str, (f64, usize)> = Default::default();
            for (i, r) in regions.iter().enumerate() {
                if let Some(r) = r {
                    let d = (b.lightmap.texels[i] - refmap.mean[i]).element_sum() / 3.0;
                    let e = bias.entry(r.name()).or_default();
                    e.0 += d / scale;
                    e.1 += 1;
                }
            }
            // The bias per region and polygon (polygons of 20 texels or more), to find where a
            // region's bias comes from.
            if self.by_polygon {
                let mut per: std::collections::BTreeMap<(&str, usize), (f64, f64, usize)> =
                    Default::default();
                for (i, r) in regions.iter().enumerate() {
                    let (Some(r), Some(at)) = (r, layout.samples[i].first()) else {
                        continue;
                    };
                    let e = per.entry((r.name(), at.polygon)).or_default();
                    e.0 += (b.lightmap.texels[i] - refmap.mean[i]).element_sum() / 3.0 / scale;
                    e.1 += refmap.mean[i].element_sum() / 3.0 / scale;
                    e.2 += 1;
                }
                for ((region, polygon), (bias, mean, n)) in per {
                    if n >= 20 {
                        println!(
                            "    {region} polygon {polygon}: {n} texels, reference mean {:.4}, bias {:+.4}",
                            mean / n as f64,
                            bias / n as f64,
                        );
                    }
                }
            }
            print!("  bias");
            for (name, (sum, n)) in bias {
                print!(" | {name} {:+.4}", sum / n as f64);
            }
            println!();
        }
        Ok(())
    }
}

/// Bakes one glb with `--solver progressive` and `--solver hierarchical` in the same run and
/// prints the solve and bake seconds, the hierarchical counters and the difference of the
/// vertex irradiance (luminance) between the two, relative to the progressive mean.
///
/// With `--reference SPP` it measures both solvers at the vertices against a Monte Carlo
/// reference (`penumbra reference`'s path tracer at the bake's own evaluation points): every
/// k-th vertex (about `--points`) and the 20 where the solvers differ most, the RMSE and bias as
/// fractions of the reference's mean, noise removed. A vertex is a point, not a texel: this is
/// free of the lightmap's resolution, which on small polygons (a window sill under one texel)
/// decides the texel errors. The share of the hierarchical squared error at vertices on contact
/// lines and on small polygons (at most 8 elements) is printed too.
#[derive(Clone, Debug, clap::Args)]
pub struct SolverDiff {
    /// Input glTF scene.
    input: PathBuf,
    /// The hierarchical solver's tolerance [default: the bake's].
    #[arg(long)]
    hr_tolerance: Option<f64>,
    /// Element budget [default: the bake's].
    #[arg(long)]
    budget: Option<usize>,
    /// The progressive solver's patch count [default: the bake's] (a reference run with finer
    /// patches).
    #[arg(long)]
    patches: Option<usize>,
    /// Print the mean indirect light of each polygon.
    #[arg(long)]
    per_polygon: bool,
    /// Measure both solvers at the vertices against a Monte Carlo reference of SPP paths each.
    #[arg(long, value_name = "SPP")]
    reference: Option<u32>,
    /// With --reference: about how many vertices to sample.
    #[arg(long, default_value_t = 2000, requires = "reference")]
    points: usize,
    /// With --reference: also list the sampled vertices farthest from the reference (10 for
    /// the direct light, 25 for the hierarchical solver).
    #[arg(long, requires = "reference")]
    worst: bool,
}

impl SolverDiff {
    /// Runs both bakes and prints their difference.
    pub(crate) fn run(&self) -> anyhow::Result<()> {
        let gltf = super::read(&self.input)?;
        let mut options = BakeOptions {
            budget: self.budget,
            ..BakeOptions::default()
        };
        if let Some(p) = self.patches {
            options.solve.patches = p;
        }
        let mut runs = Vec::new();
        for solver in [Solver::Progressive, Solver::Hierarchical] {
            let mut o = options.clone();
            o.solve.solver = solver;
            if let Some(t) = self.hr_tolerance {
                o.solve.hr_tolerance = t;
            }
            let t = std::time::Instant::now();
            let mut b = crate::bake(&gltf, &o, &|_, _, _| {})?;
            b.stats.timings_s.total = t.elapsed().as_secs_f64();
            // A directional light's emitted power is not defined (it lights an unbounded plane),
            // and `emitted_power` leaves it out: no ratio then.
            let emitted = b.stats.solve.emitted_power;
            let balance = if emitted > 0.0 {
                format!("{:.4}", b.stats.solve.absorbed_power / emitted)
            } else {
                "n/a".to_string()
            };
            println!(
                "{solver:?}: solve {:.2} s, bake {:.2} s, rays {}, vertices {}, absorbed/emitted {balance}, unshot {:.2e}",
                b.stats.timings_s.solve,
                b.stats.timings_s.total,
                b.stats.solve.rays,
                b.stats.vertices,
                b.stats.solve.unshot_fraction,
            );
            if let Some(h) = &b.stats.solve.hierarchical {
                println!("  {}", serde_json::to_string(h)?);
            }
            for w in &b.stats.warnings {
                println!("  warning: {w}");
            }
            runs.push(b);
        }
        let (p, h) = (&runs[0], &runs[1]);
        let (mut sum_p, mut sum_h, mut n) = (0.0, 0.0, 0usize);
        let (mut ind_p, mut ind_h) = (0.0, 0.0);
        let mut diffs = Vec::new();
        for m in 0..p.solution.irradiance.len() {
            for v in 0..p.solution.irradiance[m].len() {
                let a = luminance(p.solution.irradiance[m][v]);
                let b = luminance(h.solution.irradiance[m][v]);
                let d = luminance(p.solution.direct[m][v]);
                sum_p += a;
                sum_h += b;
                ind_p += a - d;
                ind_h += b - d;
                n += 1;
                diffs.push(((b - a).abs(), m, v, a, b, d));
            }
        }
        // Per polygon: mean indirect (luminance) of both solvers over its vertices.
        let mut per: std::collections::BTreeMap<usize, (f64, f64, usize)> = Default::default();
        for &(_, m, _, a, b, d) in &diffs {
            let e = per.entry(p.meshes[m].polygon).or_default();
            e.0 += a - d;
            e.1 += b - d;
            e.2 += 1;
        }
        if self.per_polygon {
            for (poly, (a, b, k)) in &per {
                println!(
                    "  polygon {poly}: mean indirect progressive {:.4}, hierarchical {:.4} ({k} vertices)",
                    a / *k as f64,
                    b / *k as f64
                );
            }
        }
        let mean = sum_p / n as f64;
        let mean_diff = diffs.iter().map(|d| d.0).sum::<f64>() / n as f64;
        let max_diff = diffs.iter().map(|d| d.0).fold(0.0, f64::max);
        // The worst vertices: where they are and both solvers' values (luminance).
        diffs.sort_by(|a, b| b.0.total_cmp(&a.0));
        for &(_, m, v, a, b, d) in diffs.iter().take(5) {
            let mesh = &p.meshes[m];
            let poly = &p.scene.polygons[mesh.polygon];
            let x = poly.frame.world_from_plane(mesh.vertices[v]);
            println!(
                "  worst: mesh {m} (polygon {}, normal {:.2}) vertex {v} at ({:.3}, {:.3}, {:.3}): direct {d:.4}, progressive {a:.4}, hierarchical {b:.4}",
                mesh.polygon, poly.frame.n, x.x, x.y, x.z
            );
        }
        if let Some(spp) = self.reference {
            vertex_reference(p, h, &diffs, spp, self.points, self.worst)?;
        }
        let p95 = diffs[n / 20].0;
        println!("  95th percentile |dH| {:.4} of the mean H", p95 / mean);
        println!(
            "mean H: progressive {:.5}, hierarchical {:.5} (ratio {:.4}); mean indirect: {:.5} vs {:.5} (ratio {:.4})",
            mean,
            sum_h / n as f64,
            sum_h / sum_p,
            ind_p / n as f64,
            ind_h / n as f64,
            ind_h / ind_p
        );
        println!(
            "vertex |dH|: mean {:.4}, max {:.4} of the mean H; solve speed-up {:.2}x, bake {:.2}x",
            mean_diff / mean,
            max_diff / mean,
            p.stats.timings_s.solve / h.stats.timings_s.solve,
            p.stats.timings_s.total / h.stats.timings_s.total
        );
        Ok(())
    }
}

/// A vertex difference: `(|dH|, mesh, vertex, progressive, hierarchical, direct)` (luminance).
type Diff = (f64, usize, usize, f64, f64, f64);

/// Both bakes against a Monte Carlo reference at sampled vertices and at the 20 vertices of
/// `diffs` (sorted, largest first) where they differ most (see the module doc).
fn vertex_reference(
    p: &Bake,
    h: &Bake,
    diffs: &[Diff],
    spp: u32,
    wanted: usize,
    worst_listed: bool,
) -> anyhow::Result<()> {
    let scene = &p.scene;
    let vis = Visibility::new(scene);
    let total: usize = p.meshes.iter().map(|m| m.vertices.len()).sum();
    let stride = total.div_ceil(wanted.max(1)).max(1);
    let mut picked: Vec<(usize, usize)> = Vec::new();
    let mut k = 0usize;
    // Vertices inside closed geometry (the floor under a box) are never seen, and the path
    // tracer, started inside, lights them through the open bottom: left out, as the lightmap
    // comparison leaves out buried texels.
    // The test runs at the vertex's evaluation point (just inside its own triangles), so the
    // copy of a contact vertex on the buried side is buried.
    let points: Vec<Vec<SurfacePoint>> = p
        .meshes
        .iter()
        .map(|m| crate::solve::evaluation_points(scene, &vis, m))
        .collect();
    let is_buried = |m: usize, v: usize| {
        let at = &points[m][v];
        vis.buried(at.ray_origin - at.n * vis.epsilon(), at.n)
    };
    let mut buried = 0usize;
    for (m, mesh) in p.meshes.iter().enumerate() {
        for v in 0..mesh.vertices.len() {
            if k.is_multiple_of(stride) {
                if is_buried(m, v) {
                    buried += 1;
                } else {
                    picked.push((m, v));
                }
            }
            k += 1;
        }
    }
    let sampled = picked.len();
    let worst: Vec<(usize, usize)> = diffs
        .iter()
        .map(|d| (d.1, d.2))
        .filter(|&(m, v)| !is_buried(m, v))
        .take(20)
        .collect();
    picked.extend(&worst);
    let samples: Vec<Vec<SurfacePoint>> = picked.iter().map(|&(m, v)| vec![points[m][v]]).collect();
    let layout = TexelLayout {
        width: samples.len() as u32,
        height: 1,
        pages: 1,
        supersample: 1,
        samples,
    };
    let options = ReferenceOptions {
        spp,
        ..ReferenceOptions::default()
    };
    let t = std::time::Instant::now();
    let r = reference_with(scene, &vis, &layout, &options);
    println!(
        "vertex reference: {} vertices ({sampled} sampled, {buried} more sampled but buried, {} where the solvers differ most), {spp} paths each, {:.1} s",
        picked.len(),
        worst.len(),
        t.elapsed().as_secs_f64()
    );
    let lum = |b: &Bake, m: usize, v: usize| luminance(b.solution.irradiance[m][v]);
    let measure = |range: std::ops::Range<usize>, label: &str| {
        let n = range.len() as f64;
        let mean_ref = range.clone().map(|i| luminance(r.mean[i])).sum::<f64>() / n;
        let noise = range
            .clone()
            .map(|i| luminance(r.std_error[i]).powi(2))
            .sum::<f64>()
            / n;
        for (name, b) in [("progressive", p), ("hierarchical", h)] {
            let (mut sq, mut bias) = (0.0, 0.0);
            for i in range.clone() {
                let (m, v) = picked[i];
                let d = lum(b, m, v) - luminance(r.mean[i]);
                sq += d * d;
                bias += d;
            }
            println!(
                "  {label}: {name} RMSE {:.4}, bias {:+.4} of the reference mean {mean_ref:.4} (noise {:.4})",
                ((sq / n - noise).max(0.0)).sqrt() / mean_ref,
                bias / n / mean_ref,
                noise.sqrt() / mean_ref
            );
        }
    };
    // The direct light alone (both bakes share it), against the reference without bounces. Near
    // an area emitter a vertex holds its fan's mean ([`crate::solve::Solution::direct`]), not
    // its point value, and differs from the reference by the falloff's curvature there.
    let direct = reference_with(
        scene,
        &vis,
        &layout,
        &ReferenceOptions {
            bounces_max: Some(0),
            ..options.clone()
        },
    );
    let (mut sq, mut noise, mut mean_ref) = (0.0, 0.0, 0.0);
    for (i, &(m, v)) in picked.iter().enumerate().take(sampled) {
        let d = luminance(p.solution.direct[m][v]) - luminance(direct.mean[i]);
        sq += d * d;
        noise += luminance(direct.std_error[i]).powi(2);
        mean_ref += luminance(r.mean[i]);
    }
    // The sampled vertices by `error`, largest first, and where a vertex is.
    let worst_by = |error: &dyn Fn(usize) -> f64| {
        let mut e: Vec<(f64, usize)> = (0..sampled).map(|i| (error(i), i)).collect();
        e.sort_by(|a, b| b.0.total_cmp(&a.0));
        e.into_iter().map(|(_, i)| i).collect::<Vec<_>>()
    };
    let place = |m: usize, v: usize| {
        let mesh = &p.meshes[m];
        let poly = &scene.polygons[mesh.polygon];
        let x = poly.frame.world_from_plane(mesh.vertices[v]);
        format!(
            "mesh {m} ({} triangles, area {:.3}) n {:.2} at ({:.2}, {:.2}, {:.2})",
            mesh.triangles.len(),
            mesh.area(),
            poly.frame.n,
            x.x,
            x.y,
            x.z
        )
    };
    if worst_listed {
        let off = |i: usize| {
            let (m, v) = picked[i];
            (luminance(p.solution.direct[m][v]) - luminance(direct.mean[i])).abs()
        };
        for &i in worst_by(&off).iter().take(10) {
            let (m, v) = picked[i];
            println!(
                "    direct: {}: bake {:.4} reference {:.4} +- {:.4}",
                place(m, v),
                luminance(p.solution.direct[m][v]),
                luminance(direct.mean[i]),
                luminance(direct.std_error[i])
            );
        }
    }
    let n = sampled as f64;
    println!(
        "  sampled vertices: direct light RMSE {:.4} of the reference mean (noise {:.4})",
        ((sq - noise) / n).max(0.0).sqrt() / (mean_ref / n),
        (noise / n).sqrt() / (mean_ref / n)
    );
    measure(0..sampled, "sampled vertices");
    // Where the hierarchical error is: vertices on a contact line (an end of a D0 constraint,
    // either copy of a split vertex) against the others.
    let on_contact = |m: usize, v: usize| {
        let mesh = &p.meshes[m];
        let at = mesh.vertices[v];
        mesh.constraints
            .iter()
            .filter(|c| c.kind == Kind::D0)
            .any(|c| mesh.vertices[c.a as usize] == at || mesh.vertices[c.b as usize] == at)
    };
    // And on polygons of at most 8 elements (a sill's face), whose few elements leave the
    // vertex fit little to go on.
    let (mut contact, mut sq_contact, mut few, mut sq_few, mut sq_all) =
        (0usize, 0.0, 0usize, 0.0, 0.0);
    for (i, &(m, v)) in picked.iter().enumerate().take(sampled) {
        let d = (lum(h, m, v) - luminance(r.mean[i])).powi(2);
        sq_all += d;
        if on_contact(m, v) {
            contact += 1;
            sq_contact += d;
        } else if p.meshes[m].triangles.len() <= 8 {
            few += 1;
            sq_few += d;
        }
    }
    println!(
        "  sampled vertices on a contact line: {contact} of {sampled}, {:.0}% of the hierarchical squared error; elsewhere on polygons of at most 8 elements: {few}, {:.0}%",
        100.0 * sq_contact / sq_all,
        100.0 * sq_few / sq_all
    );
    if worst_listed {
        let off = |i: usize| {
            let (m, v) = picked[i];
            (lum(h, m, v) - luminance(r.mean[i])).abs()
        };
        for &i in worst_by(&off).iter().take(25) {
            let (m, v) = picked[i];
            println!(
                "    {}: direct {:.3} progressive {:.3} hierarchical {:.3} reference {:.3}",
                place(m, v),
                luminance(p.solution.direct[m][v]),
                lum(p, m, v),
                lum(h, m, v),
                luminance(r.mean[i])
            );
        }
    }
    measure(sampled..picked.len(), "most different");
    for (i, &(m, v)) in picked.iter().enumerate().skip(sampled).take(5) {
        println!(
            "  mesh {m} vertex {v}: direct {:.4}, progressive {:.4}, hierarchical {:.4}, reference {:.4} +- {:.4}",
            luminance(p.solution.direct[m][v]),
            lum(p, m, v),
            lum(h, m, v),
            luminance(r.mean[i]),
            luminance(r.std_error[i])
        );
    }
    Ok(())
}
