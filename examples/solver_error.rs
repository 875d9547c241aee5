//! Bakes one glb with each solver and measures every lightmap against one Monte Carlo
//! reference, by region (`penumbra compare`'s measure, and the signed mean error, a bias):
//! `cargo run --release --example solver_error -- scene.glb [spp] [budget] [hr_tolerance]`
//! (`RES` and `SS`: lightmap size and sub-samples per texel side; `BY_POLYGON=1`: the bias per
//! region and polygon; `ONLY=hierarchical` or `ONLY=progressive`: one solver; `PATCHES=a,b,..`
//! and `TOLS=a,b,..`: one bake per progressive patch count and hierarchical tolerance, a
//! speed/accuracy sweep against the one reference).

use penumbra::compare::{classify, lightmap_error, mean_lit_irradiance};
use penumbra::reference::{ReferenceOptions, reference_with, texel_layout};
use penumbra::solve::Solver;
use penumbra::visibility::Visibility;
use penumbra::{BakeOptions, load};
use std::path::Path;

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let path = args
        .next()
        .ok_or_else(|| anyhow::anyhow!("usage: solver_error SCENE.glb [SPP] [BUDGET] [TOL]"))?;
    let spp: u32 = args.next().map(|s| s.parse()).transpose()?.unwrap_or(256);
    let budget: Option<usize> = args.next().map(|s| s.parse()).transpose()?;
    let tol: Option<f64> = args.next().map(|s| s.parse()).transpose()?;
    let gltf = load::read(Path::new(&path))?;
    // `RES` and `SS` in the environment: lightmap size and sub-samples per texel side.
    let env = |k: &str, d: u32| {
        std::env::var(k)
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(d)
    };
    let mut options = BakeOptions {
        resolution: Some(env("RES", 256)),
        supersample: env("SS", 4),
        ..BakeOptions::default()
    };
    if let Some(b) = budget {
        options.budget = Some(b);
    }
    if let Some(t) = tol {
        options.solve.hr_tolerance = t;
    }
    let mut bakes = Vec::new();
    // `ONLY=hierarchical` (or `progressive`) in the environment: that solver alone.
    let only = std::env::var("ONLY").unwrap_or_default();
    // `PATCHES=a,b,..` and `TOLS=a,b,..`: one bake per progressive patch count and per
    // hierarchical tolerance (a speed/accuracy sweep against the one reference).
    let list = |k: &str| -> anyhow::Result<Vec<Option<f64>>> {
        match std::env::var(k) {
            Ok(v) => v.split(',').map(|x| Ok(Some(x.trim().parse()?))).collect(),
            Err(_) => Ok(vec![None]),
        }
    };
    for solver in [Solver::Progressive, Solver::Hierarchical] {
        if !only.is_empty() && !format!("{solver:?}").eq_ignore_ascii_case(&only) {
            continue;
        }
        let settings = match solver {
            Solver::Progressive => list("PATCHES")?,
            _ => list("TOLS")?,
        };
        for setting in settings {
            let mut o = options.clone();
            o.solve.solver = solver;
            let label = match (solver, setting) {
                (Solver::Progressive, Some(p)) => {
                    o.solve.patches = p as usize;
                    format!("{solver:?} ({p} patches)")
                }
                (_, Some(t)) => {
                    o.solve.hr_tolerance = t;
                    format!("{solver:?} (tolerance {t:e})")
                }
                (_, None) => format!("{solver:?}"),
            };
            let b = penumbra::bake(&gltf, &o, &|_, _, _| {})?;
            bakes.push((label, b));
        }
    }
    let tmp = std::env::temp_dir().join("penumbra-solver-error.glb");
    let bytes = penumbra::bake::glb_bytes(&gltf, &mut bakes[0].1, options.encoding)?;
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
            spp,
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
        // `BY_POLYGON=1`: the bias per region and polygon (polygons of 20 texels or more), to
        // find where a region's bias comes from.
        if std::env::var("BY_POLYGON").is_ok() {
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
