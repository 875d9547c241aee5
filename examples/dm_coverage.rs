//! How much of the discontinuity lines the mesh follows, at the default options:
//!
//! ```text
//! cargo run --release --example dm_coverage -- SCENE.glb
//! ```
//!
//! For every wedge segment (all kinds but D0) of every receiver, 8 points along it count as
//! followed when they lie within 5 cm of a mesh edge on a discontinuity or of the polygon's
//! outline; prints the followed fraction of the segments' total length. Pieces dropped for the
//! budget, left out as crowded or shortened near the outline are what it misses.

use penumbra::bake::{BakeOptions, meshes};
use penumbra::discontinuity::Kind;
/// Prints the followed length fraction for the scene given as the first argument.
fn main() -> anyhow::Result<()> {
    let path = std::env::args().nth(1).unwrap();
    let gltf = penumbra::load::read(std::path::Path::new(&path))?;
    let (scene, segments, meshes) = meshes(&gltf, &BakeOptions::default())?;
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
        for s in segs.iter().filter(|s| s.kind != Kind::D0) {
            let len = s.a.distance(s.b);
            total += len;
            // sample 8 points; covered if within 1e-3*len of some constraint edge
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
