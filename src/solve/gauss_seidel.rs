//! Gauss-Seidel on the patch system, the iterative method of classic matrix radiosity (Cohen and
//! Greenberg, "The hemi-cube: a radiosity solution for complex environments", SIGGRAPH 1985),
//! and the test oracle of the progressive solver.

use super::form_factors::{FormFactors, Kernel};
use super::matrix::FormFactorMatrix;
use super::progressive::{Patch, PatchSystem};
use crate::visibility::Visibility;
use glam::DVec3;

/// Gauss-Seidel sweeps on `B = S + rho F B` (`S` the source of `system`, `F` the matrix),
/// starting from `b` and updating it in place, until the power changed by one sweep is at most
/// `tolerance` of the source's power, or `max_sweeps`. Returns the sweeps done and the last
/// sweep's relative change. Sequential sums in index order: deterministic.
pub fn sweeps(
    f: &FormFactorMatrix,
    system: &PatchSystem<'_>,
    b: &mut [DVec3],
    tolerance: f64,
    max_sweeps: usize,
) -> (usize, f64) {
    let n = system.patches.len();
    let source = system.source();
    let scale = system.power(&source).max(f64::MIN_POSITIVE);
    let mut change = f64::INFINITY;
    let mut done = 0;
    while done < max_sweeps && (change > tolerance || change.is_nan()) {
        let mut moved = 0.0;
        for i in 0..n {
            let row = f.row(i);
            let gathered: DVec3 = (0..n).map(|j| b[j] * row[j]).sum();
            let new = source[i] + system.patches[i].rho * gathered;
            moved += (new - b[i]).abs().element_sum() / 3.0 * system.patches[i].area;
            b[i] = new;
        }
        change = moved / scale;
        done += 1;
    }
    (done, change)
}

/// The full patch system with closed-form form factors, solved by `sweeps` Gauss-Seidel
/// sweeps: returns each patch's irradiance like
/// [`progressive`](super::progressive::progressive). Quadratic memory: for small scenes and
/// tests.
pub fn gauss_seidel(
    vis: &Visibility,
    patches: &[Patch],
    direct: &[DVec3],
    sweeps_: usize,
) -> Vec<DVec3> {
    let kernel = Kernel::new(vis, patches, FormFactors::ClosedForm, 0);
    let system = PatchSystem::new(patches, direct.to_vec(), vec![DVec3::ZERO; patches.len()]);
    let (f, _) = FormFactorMatrix::new(&kernel, patches.len());
    let mut b = system.source();
    sweeps(&f, &system, &mut b, 0.0, sweeps_);
    f.irradiance(&system, &b)
}
