//! Debug: row sums of the hierarchical links (B = 1 everywhere) on the furnace box.
use glam::DVec3;
use penumbra::solve::hierarchical::Hierarchy;
use penumbra::visibility::Visibility;
use penumbra::{BakeOptions, load};
use std::path::Path;

fn main() -> anyhow::Result<()> {
    let gltf = load::from_bytes(
        penumbra::fixtures::furnace_box_with(0.5, 1.0),
        Path::new("f.glb"),
    )?;
    let mut o = BakeOptions {
        budget: 2000,
        resolution: Some(128),
        ..Default::default()
    };
    o.solve.bounces = Some(0);
    let b = penumbra::bake(&gltf, &o, &|_, _, _| {})?;
    let vis = Visibility::new(&b.scene);
    let h = Hierarchy::build(&b.scene, &vis, &b.meshes, &b.solution.direct).unwrap();
    for (tol, var) in [(1e-3, 1e-2), (1e-4, 1e-2), (1e-4, 1e-3), (1e-5, 1e-3)] {
        let ones = vec![DVec3::ONE; h.elements.len()];
        let bn = h.pull(&ones);
        let sc: Vec<f64> = bn.iter().map(|b| b.x).collect();
        let total: f64 = h.elements.iter().map(|e| e.area).sum();
        let (links, _, _) = h.link(&vis, &sc, tol * total, var);
        let got = h.push(&h.gather(&links, &bn));
        let mean: f64 = h
            .elements
            .iter()
            .zip(&got)
            .map(|(e, g)| e.area * g.x)
            .sum::<f64>()
            / total;
        let min = got.iter().map(|g| g.x).fold(9.0, f64::min);
        let max = got.iter().map(|g| g.x).fold(0.0, f64::max);
        let leaf_links = links
            .iter()
            .filter(|l| {
                h.nodes[l.receiver as usize].kids.is_none()
                    && h.nodes[l.source as usize].kids.is_none()
            })
            .count();
        println!(
            "tol {tol:e} variation {var:e}: links {} (leaf-leaf {leaf_links}), row sum mean {mean:.4} min {min:.4} max {max:.4}",
            links.len()
        );
    }
    Ok(())
}
