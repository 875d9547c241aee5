//! Discontinuity meshing against uniform meshing at the same element budget: the error of the
//! mesh interpolant against the exact direct light, in the shadowed regions of the floor.

use crate::discontinuity::dm;
use glam::DVec2;
use penumbra::fixtures;
use penumbra::lightmap::Locator;
use penumbra::mesh::Mesher;
use penumbra::solve::{Direct, SurfacePoint};
use penumbra::visibility::Visibility;
use penumbra::{Bake, BakeOptions};
use std::f64::consts::PI;

/// RMS and max error (relative to the floor's peak) of the direct light in the shadowed part of
/// the largest upward polygon, over a stratified grid of points.
fn shadow_error(b: &Bake, points_per_side: usize) -> (f64, f64, usize) {
    let scene = &b.scene;
    let vis = Visibility::new(scene);
    let direct = Direct::new(scene, &vis, 64);
    let floor = (0..scene.polygons.len())
        .filter(|&i| scene.polygons[i].frame.n.y > 0.99)
        .max_by(|&i, &j| scene.polygons[i].area.total_cmp(&scene.polygons[j].area))
        .unwrap();
    let poly = &scene.polygons[floor];
    let mi = b.meshes.iter().position(|m| m.polygon == floor).unwrap();
    let loc = Locator::new(&b.meshes[mi], &b.solution.irradiance[mi]);
    let mut errors = Vec::new();
    let mut peak: f64 = 0.0;
    for t in &poly.triangles_plane {
        for i in 0..points_per_side {
            for j in 0..points_per_side - i {
                let (u, v) = (
                    (i as f64 + 1.0 / 3.0) / points_per_side as f64,
                    (j as f64 + 1.0 / 3.0) / points_per_side as f64,
                );
                let q: DVec2 = t[0] + (t[1] - t[0]) * u + (t[2] - t[0]) * v;
                let p = poly.frame.world_from_plane(q);
                let exact = direct
                    .irradiance(&SurfacePoint::new(p, poly.frame.n, floor, &vis))
                    .x;
                let unoccluded: f64 = direct
                    .emitters
                    .iter()
                    .map(|e| PI * e.radiance.x * e.form_factor(p, poly.frame.n))
                    .sum();
                peak = peak.max(exact);
                if exact < 0.995 * unoccluded {
                    errors.push((loc.value(q).x - exact).abs());
                }
            }
        }
    }
    let rms = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len().max(1) as f64).sqrt();
    let max = errors.iter().copied().fold(0.0, f64::max);
    (rms / peak, max / peak, errors.len())
}

fn compare(name: &str, bytes: &[u8], budget: usize) -> (f64, f64) {
    let mut o = BakeOptions {
        budget,
        resolution: Some(512),
        ..dm()
    };
    o.solve.bounces = Some(0);
    let d = crate::bake(bytes, &o);
    let with = |mesher| BakeOptions {
        mesher,
        ..o.clone()
    };
    let u = crate::bake(bytes, &with(Mesher::Uniform));
    let a = crate::bake(bytes, &with(Mesher::Adaptive));
    let (dr, dmax, n) = shadow_error(&d, 120);
    let (ur, umax, _) = shadow_error(&u, 120);
    let (ar, amax, _) = shadow_error(&a, 120);
    println!(
        "{name} budget {budget}: shadowed points {n}; RMS uniform {ur:.5} adaptive {ar:.5} discontinuity {dr:.5} (uniform/discontinuity {:.2}); max uniform {umax:.4} adaptive {amax:.4} discontinuity {dmax:.4} (ratio {:.2}); elements {} / {} / {}",
        ur / dr,
        umax / dmax,
        u.stats.elements,
        a.stats.elements,
        d.stats.elements
    );
    assert!(
        a.stats.elements <= budget + budget / 10,
        "adaptive overshoots the budget: {}",
        a.stats.elements
    );
    (ur / dr, umax / dmax)
}

#[test]
fn discontinuity_beats_uniform_in_shadows_on_the_cornell_box() {
    let (rms, max) = compare("cornell-box", &fixtures::cornell_box(), 4000);
    assert!(rms > 1.2, "RMS ratio uniform/discontinuity {rms}");
    assert!(max > 1.2, "max ratio uniform/discontinuity {max}");
}

#[test]
fn discontinuity_beats_uniform_in_shadows_on_the_box_grid() {
    let (rms, _) = compare("box grid 5x5", &crate::stability::box_grid(5), 6000);
    assert!(rms > 1.2, "RMS ratio uniform/discontinuity {rms}");
}

#[test]
fn discontinuity_beats_uniform_on_the_square_occluder() {
    let (rms, max) = compare("square occluder", &fixtures::square_occluder(), 2000);
    assert!(rms > 1.5 && max > 1.5, "ratios {rms} {max}");
}
