//! Bakes one glb's direct light with every emitter exact (`--light-error 0`) and with the light
//! tree's cut at the given error, and prints both direct-light times, the exact evaluations,
//! the bounded nodes and the lightmap's RMSE between the two, relative to its mean, for each
//! error given (default 0.01):
//! `cargo run --release --example light_error -- scene.glb [light_error ...]`.

use penumbra::{BakeOptions, load};
use std::path::Path;

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let path = args
        .next()
        .ok_or_else(|| anyhow::anyhow!("usage: light_error SCENE.glb [LIGHT_ERROR ...]"))?;
    let mut errors = vec![0.0];
    for a in args {
        errors.push(a.parse()?);
    }
    if errors.len() == 1 {
        errors.push(0.01);
    }
    let gltf = load::read(Path::new(&path))?;
    let mut bakes = Vec::new();
    for &e in &errors {
        let mut o = BakeOptions::default();
        o.solve.bounces = Some(0);
        o.solve.light_error = e;
        let b = penumbra::bake(&gltf, &o, &|_, _, _| {})?;
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
