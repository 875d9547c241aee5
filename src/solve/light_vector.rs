//! The indirect light's directions at the mesh vertices (`--directional`), by a gather of
//! rays over the solved irradiance.
//!
//! The direct light's light vector comes from each light's own direction
//! ([`super::direct`]); the indirect light arrives from everywhere, and its size is known (the
//! solve's indirect irradiance `H_ind` at the vertex) but not its direction. Each vertex casts
//! a fixed set of rays of equal solid angle over its hemisphere (the sky's Hammersley set,
//! [`super::sky::CosineRays::uniform_directions`]); a ray that hits a receiver brings that
//! point's reflected radiosity `rho H / pi` ([`super::reflected`]).
//! Their sums estimate the reflected light's irradiance `E = ∫ L cos θ dω` and light vector
//! `Q = ∫ L ω dω`; the vertex's indirect light vector is `H_ind (n + Q_t / E)`, with `Q_t` the
//! part of `Q` along the surface, per channel. Rays of equal solid angle, not
//! cosine-distributed ones: `Q`'s integrand is then bounded (with cosine-distributed rays it is
//! `ω / cos θ`, heavy-tailed at grazing angles). So the indirect light vector's component
//! along the normal is `H_ind` exactly, and only its direction comes from the rays (a final
//! gather's direction, as in Reichert's "A two-pass radiosity method driven by lights and
//! viewer position", 1992). Why rays and not the hierarchical solver's links:
//! `docs/decisions.md` ("Engine outputs").

use super::reflected::{Reflected, Seen};
use super::sky::CosineRays;
use super::{SolveOptions, evaluation_points};
use crate::light::{LightVector, add_light};
use crate::mesh::ReceiverMesh;
use crate::scene::Scene;
use crate::visibility::Visibility;
use glam::DVec3;
use rayon::prelude::*;

/// Default of [`SolveOptions::directional_rays`].
pub const DEFAULT_RAYS: usize = 128;

/// The indirect light vector at every vertex of `meshes` (see the module doc) from their
/// irradiance `irradiance` and its direct part `direct` (W/m², per vertex), and the rays cast.
pub(crate) fn indirect(
    scene: &Scene,
    vis: &Visibility,
    meshes: &[ReceiverMesh],
    irradiance: &[Vec<DVec3>],
    direct: &[Vec<DVec3>],
    options: &SolveOptions,
) -> (Vec<Vec<LightVector>>, u64) {
    let reflected = Reflected::new(scene, meshes, irradiance);
    let rays = CosineRays::new(options.directional_rays);
    let per_mesh: Vec<(Vec<LightVector>, u64)> = meshes
        .par_iter()
        .zip(irradiance.par_iter().zip(direct))
        .map(|(m, (h, d))| {
            let mut cast = 0;
            let light = evaluation_points(scene, vis, m)
                .iter()
                .zip(h.iter().zip(d))
                .map(|(at, (h, d))| {
                    // The reflected light the rays bring: its irradiance and light vector.
                    let (mut e, mut q) = (DVec3::ZERO, LightVector::default());
                    for w in rays.uniform_directions(at) {
                        cast += 1;
                        let Seen::Radiosity(b) = reflected.along(vis, at.ray_origin, w) else {
                            continue; // nothing, or the back of a one-sided surface
                        };
                        e += b * w.dot(at.n);
                        add_light(&mut q, b, w);
                    }
                    let indirect = (*h - *d).max(DVec3::ZERO);
                    let mut out = LightVector::default();
                    for c in 0..3 {
                        let qc = DVec3::new(q[0][c], q[1][c], q[2][c]);
                        let along = if e[c] > 0.0 {
                            (qc - at.n * qc.dot(at.n)) / e[c]
                        } else {
                            DVec3::ZERO
                        };
                        let u = at.n + along;
                        for (axis, o) in out.iter_mut().enumerate() {
                            o[c] = indirect[c] * u[axis];
                        }
                    }
                    out
                })
                .collect();
            (light, cast)
        })
        .collect();
    let rays = per_mesh.iter().map(|(_, r)| r).sum();
    (per_mesh.into_iter().map(|(l, _)| l).collect(), rays)
}
