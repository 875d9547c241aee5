//! The sky's noise against its cost: the sky's visible fraction `V` (`E = pi L_sky V`) at
//! points of the ground and the box walls of `fixtures::box_on_ground`, estimated with each
//! ray count, against the closed form `fixtures::box_on_ground_open_sky`.
//!
//! ```text
//! cargo bench --bench sky
//! ```
//!
//! Prints, per ray count, the RMS and largest error of `V` (a fraction of `pi L_sky`; on the
//! ground also the mean error, the bias) over ground points (a grid), over contact points (1 mm
//! off the walls' bases, where the box blocks half) and over points of a wall, and the time per
//! point on one thread (no flags). docs/how-it-works.md ("The sky") quotes it.

use glam::DVec3;
use penumbra::fixtures;
use penumbra::solve::SurfacePoint;
use penumbra::solve::sky::Sky;
use penumbra::visibility::Visibility;
use std::path::Path;
use std::time::Instant;

fn main() -> penumbra::Result<()> {
    let gltf = penumbra::load::from_bytes(fixtures::box_on_ground(), Path::new("box_on_ground"))?;
    let scene = penumbra::load::scene(&gltf)?;
    let vis = Visibility::new(&scene);
    let ground = scene
        .polygons
        .iter()
        .position(|p| p.frame.n.y > 0.5 && p.frame.origin.y.abs() < 1e-9)
        .expect("the ground");
    let lo = DVec3::from(fixtures::SKY_BOX_MIN);
    let hi = DVec3::from(fixtures::SKY_BOX_MAX);
    // Ground: a grid over [-4, 4]² outside the box, and points 1 mm off the walls' bases.
    let mut points: Vec<(String, SurfacePoint)> = Vec::new();
    let at = |p: DVec3, n: DVec3, polygon: usize| SurfacePoint::new(p, n, polygon, &vis);
    for i in 0..41 {
        for j in 0..41 {
            let p = DVec3::new(
                -4.0 + 0.2 * i as f64 + 0.013,
                0.0,
                -4.0 + 0.2 * j as f64 + 0.007,
            );
            if p.x > lo.x && p.x < hi.x && p.z > lo.z && p.z < hi.z {
                continue;
            }
            points.push(("ground".into(), at(p, DVec3::Y, ground)));
        }
    }
    for k in 0..=30 {
        let t = k as f64 / 30.0;
        let x = lo.x + (hi.x - lo.x) * t;
        let z = lo.z + (hi.z - lo.z) * t;
        for p in [
            DVec3::new(x, 0.0, hi.z + 1e-3),
            DVec3::new(x, 0.0, lo.z - 1e-3),
            DVec3::new(hi.x + 1e-3, 0.0, z),
            DVec3::new(lo.x - 1e-3, 0.0, z),
        ] {
            points.push(("contact".into(), at(p, DVec3::Y, ground)));
        }
    }
    // Walls: the box's front (+z) wall, found by its normal.
    let wall = scene
        .polygons
        .iter()
        .position(|p| p.frame.n.z > 0.5)
        .expect("the +z wall");
    for i in 0..=12 {
        for j in 0..=8 {
            let p = DVec3::new(
                lo.x + (hi.x - lo.x) * (0.02 + 0.96 * i as f64 / 12.0),
                hi.y * (0.01 + 0.98 * j as f64 / 8.0),
                hi.z,
            );
            points.push(("wall".into(), at(p, DVec3::Z, wall)));
        }
    }
    println!("{} points", points.len());
    println!("rays | ground RMS, max, mean | contact RMS, max | wall RMS, max | us per point");
    for n in [16, 32, 64, 128, 256, 512, 1024, 4096] {
        let sky = Sky::new(&scene, DVec3::ONE, n).expect("a sky");
        let start = Instant::now();
        let errors: Vec<(&str, f64)> = points
            .iter()
            .map(|(kind, sp)| {
                let (v, _) = sky.visible_fraction(&vis, sp);
                (
                    kind.as_str(),
                    v - fixtures::box_on_ground_open_sky(sp.p, sp.n),
                )
            })
            .collect();
        let us = start.elapsed().as_secs_f64() * 1e6 / points.len() as f64;
        let stat = |kind: &str| {
            let e: Vec<f64> = errors
                .iter()
                .filter(|(k, _)| *k == kind)
                .map(|(_, e)| *e)
                .collect();
            let rms = (e.iter().map(|e| e * e).sum::<f64>() / e.len() as f64).sqrt();
            let max = e.iter().fold(0.0f64, |m, e| m.max(e.abs()));
            let bias = e.iter().sum::<f64>() / e.len() as f64;
            (rms, max, bias)
        };
        let (g, c, w) = (stat("ground"), stat("contact"), stat("wall"));
        println!(
            "{n:5} | {:.4} {:.4} {:+.5} | {:.4} {:.4} | {:.4} {:.4} | {us:.1}",
            g.0, g.1, g.2, c.0, c.1, w.0, w.1
        );
    }
    Ok(())
}
