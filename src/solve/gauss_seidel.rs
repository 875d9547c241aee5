//! A direct matrix solve of the patch system, the test oracle of the progressive solver.

use super::progressive::{Patch, point_patch_form_factor};
use crate::light::SurfacePoint;
use crate::visibility::Visibility;
use glam::DVec3;

/// Gauss-Seidel on the full patch system `B_i = E_i + rho_i sum_j K_ij B_j`, where `E_i` is the
/// reflected direct light and `K_ij` the point-to-patch form factor at patch `i`'s centroid;
/// returns each patch's irradiance like [`progressive`](super::progressive::progressive). Quadratic memory: for small scenes and
/// tests.
pub fn gauss_seidel(
    vis: &Visibility,
    patches: &[Patch],
    direct: &[DVec3],
    sweeps: usize,
) -> Vec<DVec3> {
    let n = patches.len();
    let mut rays = 0;
    let k: Vec<Vec<f64>> = (0..n)
        .map(|i| {
            let r = &patches[i];
            let at = SurfacePoint::new(r.centroid, r.normal, r.polygon, vis);
            (0..n)
                .map(|j| {
                    if i == j {
                        0.0
                    } else {
                        point_patch_form_factor(vis, &at, &patches[j], &mut rays)
                    }
                })
                .collect()
        })
        .collect();
    // Reflected radiosity B = rho H.
    let mut b: Vec<DVec3> = (0..n).map(|i| patches[i].rho * direct[i]).collect();
    for _ in 0..sweeps {
        for i in 0..n {
            let gathered: DVec3 = (0..n).map(|j| b[j] * k[i][j]).sum();
            b[i] = patches[i].rho * (direct[i] + gathered);
        }
    }
    (0..n)
        .map(|i| direct[i] + (0..n).map(|j| b[j] * k[i][j]).sum::<DVec3>())
        .collect()
}
