//! The indirect light by progressive refinement (Cohen, Chen, Wallace, Greenberg, "A progressive
//! refinement approach to fast radiosity image generation", SIGGRAPH 1988) over coarse patches,
//! then a final gather of the converged patch radiosities at every mesh vertex. The form
//! factors are [`super::form_factors`]'s (`--form-factors`): by default the exact unoccluded
//! point-to-patch factor with ray-cast visibility (after Wallace, Elmquist, Haines, "A ray
//! tracing algorithm for progressive radiosity", SIGGRAPH 1989). The patches and the patch
//! system ([`super::patches`](mod@super::patches)) and the final gather are shared with classic radiosity
//! ([`super::matrix`]).
//!
//! Irradiance `H` and radiosity `B` in W/m² per linear RGB channel; form factors dimensionless.

use super::form_factors::{FormFactors, Kernel};
use super::patches::{Patch, PatchSystem, patches};
use super::{SolveOptions, SolveStats, Solver, evaluation_points};
use crate::light::SurfacePoint;
use crate::mesh::ReceiverMesh;
use crate::scene::Scene;
use crate::solve::Direct;
use crate::visibility::Visibility;
use glam::DVec3;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU64, Ordering};

/// Progressive refinement over patches with closed-form form factors: returns the irradiance
/// of each patch, direct plus indirect. `direct[i]` is the direct irradiance of patch `i`.
pub fn progressive(
    vis: &Visibility,
    patches: &[Patch],
    direct: &[DVec3],
    bounces: Option<u32>,
    tolerance: f64,
    stats: &mut SolveStats,
) -> Vec<DVec3> {
    let kernel = Kernel::new(vis, patches, FormFactors::ClosedForm, 0);
    let system = PatchSystem::new(patches, direct.to_vec(), vec![DVec3::ZERO; patches.len()]);
    refine(&kernel, &system, bounces, tolerance, stats)
}

/// Progressive refinement of `system` (Cohen, Chen, Wallace, Greenberg 1988): the patch with
/// the most unshot power shoots it to all others through `kernel`, until the unshot power is
/// below `tolerance` of the initial source power, or `bounces` generations; returns each patch's
/// irradiance `H`.
pub(crate) fn refine(
    kernel: &Kernel<'_>,
    system: &PatchSystem<'_>,
    bounces: Option<u32>,
    tolerance: f64,
    stats: &mut SolveStats,
) -> Vec<DVec3> {
    let patches = system.patches;
    let mut h = system.direct.clone();
    // Unshot radiosity (W/m²) of each patch: its emitted and reflected direct light.
    let mut unshot = system.source();
    let power = |i: usize, u: &[DVec3]| u[i].element_sum() / 3.0 * patches[i].area;
    let initial: f64 = (0..patches.len()).map(|i| power(i, &unshot)).sum();
    let mut rays = 0u64;
    let mut shots = 0usize;
    // Shoots radiosity `b` from patch `i`: every other patch receives irradiance at its
    // centroid, and its reflected part becomes unshot radiosity in `next`.
    let mut shoot = |i: usize, b: DVec3, h: &mut Vec<DVec3>, next: &mut Vec<DVec3>| {
        for (j, (f, n)) in kernel.shoot(i).into_iter().enumerate() {
            let dh = b * f;
            rays += n;
            h[j] += dh;
            next[j] += patches[j].rho * dh;
        }
    };
    match bounces {
        Some(0) => {}
        Some(n) => {
            // n bounces in all: the final gather at the vertices is the last one, so the patches
            // exchange light n-1 times, one generation of unshot light at a time (n times when
            // the first generation is the emitted light).
            let first = if system.emits() { 0 } else { 1 };
            for _ in first..n {
                let mut next = vec![DVec3::ZERO; patches.len()];
                for (i, &b) in unshot.iter().enumerate() {
                    if b.max_element() > 0.0 {
                        shoot(i, b, &mut h, &mut next);
                        shots += 1;
                    }
                }
                unshot = next;
            }
        }
        None => {
            let limit = 100 * patches.len() + 1000;
            loop {
                let total: f64 = (0..patches.len()).map(|i| power(i, &unshot)).sum();
                // A shot passes on at most rho x (sum of form factors <= 1) of what it takes, so
                // the unshot power never grows; where it does (the surfaces around a receiver
                // are counted twice, as with coincident duplicated geometry) the solve diverges:
                // stop, and `unshot_fraction` > 1 says so.
                if total <= tolerance * initial
                    || shots >= limit
                    || total.is_nan()
                    || total > 2.0 * initial
                {
                    break;
                }
                // The patch with the most unshot power; ties broken by index.
                let mut best = 0;
                let mut best_power = -1.0;
                for i in 0..patches.len() {
                    let pw = power(i, &unshot);
                    if pw > best_power {
                        best = i;
                        best_power = pw;
                    }
                }
                let b = std::mem::take(&mut unshot[best]);
                shoot(best, b, &mut h, &mut unshot);
                shots += 1;
            }
        }
    }
    let left: f64 = (0..patches.len()).map(|i| power(i, &unshot)).sum();
    stats.patches = patches.len();
    stats.shots = shots;
    stats.rays += rays;
    stats.unshot_fraction = if initial > 0.0 { left / initial } else { 0.0 };
    h
}

/// The indirect light at every vertex of `meshes` by a patch solver (`--solver progressive` or
/// `matrix`), added to their direct light `direct_h`: patches, their direct light from `direct`,
/// the patch solve, and the final gather. With hemicube form factors the area emitters are
/// patches of the solve (`direct` then holds the punctual lights only) and their light at the
/// vertices is added to `direct_h` too. Fills the patch counters and powers of `stats` and adds
/// the rays cast.
#[allow(clippy::too_many_arguments)]
pub(crate) fn indirect(
    scene: &Scene,
    vis: &Visibility,
    direct: &Direct<'_>,
    meshes: &[ReceiverMesh],
    direct_h: &mut [Vec<DVec3>],
    options: &SolveOptions,
    stats: &mut SolveStats,
    progress: &crate::progress::Progress<'_>,
) -> Vec<Vec<DVec3>> {
    let total_vertices: u64 = meshes.iter().map(|m| m.vertices.len() as u64).sum();
    let patches = patches(scene, options.patches);
    let kernel = Kernel::new(
        vis,
        &patches,
        options.form_factors,
        options.hemicube_resolution,
    );
    let patch_direct: Vec<DVec3> = patches
        .par_iter()
        .map(|p| direct.irradiance(&SurfacePoint::new(p.centroid, p.normal, p.polygon, vis)))
        .collect();
    // Emitted radiosity M = pi L of the patches, when the form factors carry it.
    let emission: Vec<DVec3> = patches
        .iter()
        .map(|p| {
            if options.form_factors == FormFactors::Hemicube {
                std::f64::consts::PI * scene.materials[scene.polygons[p.polygon].material].radiance
            } else {
                DVec3::ZERO
            }
        })
        .collect();
    let system = PatchSystem::new(&patches, patch_direct, emission);
    let start = std::time::Instant::now();
    let patch_h = match options.solver {
        Solver::Matrix => super::matrix::solve(&kernel, &system, options, stats),
        _ => refine(&kernel, &system, options.bounces, options.tolerance, stats),
    };
    stats.patch_solve_seconds = start.elapsed().as_secs_f64();
    stats.hemicube = kernel.hemicube_stats();
    stats.direct_power = system.power(&system.direct);
    stats.absorbed_power = patches
        .iter()
        .zip(&patch_h)
        .map(|(p, h)| p.area * ((DVec3::ONE - p.rho) * *h).element_sum() / 3.0)
        .sum();
    // Radiosity of each patch, the source of the final gather: reflected, and emitted where the
    // form factors carry it (direct light only: emitted alone).
    let reflected: Vec<DVec3> = patches
        .iter()
        .zip(&patch_h)
        .zip(&system.emission)
        .map(|((p, h), m)| {
            if options.bounces == Some(0) {
                *m
            } else {
                *m + p.rho * *h
            }
        })
        .collect();
    let emits = system.emits();
    let gather_rays = AtomicU64::new(0);
    let done = AtomicU64::new(0);
    let (out, emitted): (Vec<Vec<DVec3>>, Vec<Vec<DVec3>>) = meshes
        .par_iter()
        .zip(direct_h.par_iter())
        .map(|(m, dh)| {
            let pts = evaluation_points(scene, vis, m);
            let mut rays = 0u64;
            let values = pts
                .iter()
                .zip(dh)
                .map(|(p, &d)| {
                    let f = kernel.gather(p, &|j| reflected[j].max_element() > 0.0, &mut rays);
                    let mut h = d;
                    let mut e = DVec3::ZERO;
                    for ((b, m), f) in reflected.iter().zip(&system.emission).zip(f) {
                        if b.max_element() <= 0.0 {
                            continue;
                        }
                        h += *b * f;
                        if emits {
                            e += *m * f;
                        }
                    }
                    (h, e)
                })
                .unzip();
            gather_rays.fetch_add(rays, Ordering::Relaxed);
            let d = done.fetch_add(m.vertices.len() as u64, Ordering::Relaxed);
            progress(
                "indirect light",
                d + m.vertices.len() as u64,
                total_vertices,
            );
            values
        })
        .unzip();
    if emits {
        for (dh, e) in direct_h.iter_mut().zip(emitted) {
            for (d, e) in dh.iter_mut().zip(e) {
                *d += e;
            }
        }
    }
    stats.hemicube = kernel.hemicube_stats();
    stats.rays += gather_rays.load(Ordering::Relaxed);
    out
}
