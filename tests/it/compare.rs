//! Discontinuity meshing against uniform meshing at the same element budget: the error of the
//! mesh interpolant against the exact direct light, in the shadowed regions of the floor.

use crate::discontinuity::dm;
use penumbra::fixtures;
use penumbra::mesh::Mesher;
use penumbra::{Bake, BakeOptions};

fn shadow_error(b: &Bake, points_per_side: usize) -> (f64, f64, usize) {
    let e = penumbra::compare::shadow_error(b, points_per_side).expect("a floor");
    (e.rms, e.max, e.points)
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
