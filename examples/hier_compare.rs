//! Bakes one glb with `--solver progressive` and `--solver hierarchical` in the same run and
//! prints the solve and bake seconds, the hierarchical counters and the difference of the
//! vertex irradiance (luminance) between the two, relative to the progressive mean:
//! `cargo run --release --example hier_compare -- scene.glb [hr_tolerance] [budget]`
//! (`PATCHES=n` in the environment sets the progressive solver's patch count, `PER_POLYGON=1`
//! prints the mean indirect light of each polygon).

use penumbra::light::luminance;
use penumbra::solve::Solver;
use penumbra::{BakeOptions, load};
use std::path::Path;

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let path = args
        .next()
        .ok_or_else(|| anyhow::anyhow!("usage: hier_compare SCENE.glb [TOL] [BUDGET]"))?;
    let tol: Option<f64> = args.next().map(|s| s.parse()).transpose()?;
    let budget: Option<usize> = args.next().map(|s| s.parse()).transpose()?;
    let gltf = load::read(Path::new(&path))?;
    let mut options = BakeOptions::default();
    if let Some(b) = budget {
        options.budget = Some(b);
    }
    // The progressive solver's patch count (a reference run with finer patches).
    if let Ok(p) = std::env::var("PATCHES") {
        options.solve.patches = p.parse()?;
    }
    let mut runs = Vec::new();
    for solver in [Solver::Progressive, Solver::Hierarchical] {
        let mut o = options.clone();
        o.solve.solver = solver;
        if let Some(t) = tol {
            o.solve.hr_tolerance = t;
        }
        let t = std::time::Instant::now();
        let mut b = penumbra::bake(&gltf, &o, &|_, _, _| {})?;
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
    if std::env::var("PER_POLYGON").is_ok() {
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
