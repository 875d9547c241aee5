//! The form factors of the patch solvers (`--form-factors`, for `--solver progressive` and
//! `--solver matrix`): from a receiving point to a patch, one pair at a time or a whole row.
//!
//! * [`FormFactors::ClosedForm`] (the default): Lambert's contour formula for the unoccluded
//!   factor of the patch, split in four up to twice near the receiver, each piece's visibility
//!   from one ray to its centroid ([`point_patch_form_factor`]).
//! * [`FormFactors::Raycast`]: Wallace, Elmquist and Haines, "A ray tracing algorithm for
//!   progressive radiosity", SIGGRAPH 1989: the patch as [`RAYCAST_SAMPLES`] small disks, each
//!   `dF = dA cos_r cos_s / (pi r² + dA)` times the visibility of one ray.
//! * [`FormFactors::Hemicube`]: Cohen and Greenberg 1985 ([`super::hemicube`]): one hemicube per
//!   gathering point or shooting patch gives the whole row, visibility by its depth buffer.
//!   In this mode the area emitters are patches too (radiosity `M = pi L`), as in the classic
//!   method: their light reaches the vertices through the hemicube, not through `--direct`.
//!
//! Form factors dimensionless; lengths in scene units.

use super::hemicube::Hemicube;
use super::patches::Patch;
use crate::geometry::point_polygon_form_factor;
use crate::light::SurfacePoint;
use crate::visibility::Visibility;
use glam::DVec3;
use rayon::prelude::*;
use std::f64::consts::PI;
use std::sync::atomic::{AtomicU64, Ordering};

/// How the patch solvers compute form factors (`--form-factors`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, serde::Serialize)]
#[cfg_attr(any(feature = "cli", feature = "measure"), derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum FormFactors {
    /// Exact unoccluded point-to-patch factor (contour formula), ray-cast visibility per piece.
    #[default]
    ClosedForm,
    /// Wallace et al. 1989: the patch as 16 disks, one visibility ray each.
    Raycast,
    /// Cohen and Greenberg 1985: a hemicube per point (`--hemicube-resolution`); the area
    /// emitters become patches of the solve.
    Hemicube,
}

impl FormFactors {
    /// `closed-form`, `raycast` or `hemicube`, as on the command line.
    pub fn name(self) -> &'static str {
        match self {
            FormFactors::ClosedForm => "closed-form",
            FormFactors::Raycast => "raycast",
            FormFactors::Hemicube => "hemicube",
        }
    }
}

/// Subdivision of a patch for [`FormFactors::Raycast`]: `k x k` sub-triangles, one sample at
/// each centroid.
const RAYCAST_SPLIT: usize = 4;

/// Sample points (disks) per patch of [`FormFactors::Raycast`].
pub(crate) const RAYCAST_SAMPLES: usize = RAYCAST_SPLIT * RAYCAST_SPLIT;

/// The culls shared by the point-to-patch factors: a planar polygon does not see itself; the
/// receiver behind (or in the plane of) the patch; the patch entirely below the receiver's
/// horizon.
fn culled(at: &SurfacePoint, patch: &Patch) -> bool {
    at.polygon == patch.polygon
        || patch.normal.dot(at.p - patch.centroid) <= 1e-9 * (at.p - patch.centroid).length()
        || patch.p.iter().all(|q| at.n.dot(*q - at.p) <= 0.0)
}

/// Form factor from a receiving surface point `(p, n)` to a patch, with visibility: exact unoccluded
/// form factor of each piece times the visibility of its centroid; pieces near `p` are split in
/// four, up to two levels. Returns the form factor and adds the rays cast to `rays`.
pub(crate) fn point_patch_form_factor(
    vis: &Visibility,
    at: &SurfacePoint,
    patch: &Patch,
    rays: &mut u64,
) -> f64 {
    let (p, n) = (at.p, at.n);
    if culled(at, patch) {
        return 0.0;
    }
    let skip = [at.polygon, patch.polygon];
    piece_form_factor(
        vis,
        p,
        at.ray_origin,
        n,
        skip,
        &patch.p,
        patch.radius,
        0,
        rays,
    )
}

#[allow(clippy::too_many_arguments)]
fn piece_form_factor(
    vis: &Visibility,
    p: DVec3,
    p_ray: DVec3,
    n: DVec3,
    skip: [usize; 2],
    t: &[DVec3; 3],
    radius: f64,
    depth: u32,
    rays: &mut u64,
) -> f64 {
    let c = (t[0] + t[1] + t[2]) / 3.0;
    if depth < 2 && c.distance(p) < 3.0 * radius {
        let m = [
            (t[0] + t[1]) * 0.5,
            (t[1] + t[2]) * 0.5,
            (t[2] + t[0]) * 0.5,
        ];
        let kids = [
            [t[0], m[0], m[2]],
            [m[0], t[1], m[1]],
            [m[2], m[1], t[2]],
            [m[0], m[1], m[2]],
        ];
        return kids
            .iter()
            .map(|k| piece_form_factor(vis, p, p_ray, n, skip, k, radius * 0.5, depth + 1, rays))
            .sum();
    }
    let f = point_polygon_form_factor(p, n, t);
    if f <= 0.0 {
        return 0.0;
    }
    *rays += 1;
    f * passed(vis, p_ray, c, skip)
}

/// The fraction of light that passes from `a` to `b` (see [`Visibility::transmitted_skipping`]),
/// as the mean over the channels: 1 or 0, or less through glass. The patch solvers keep one
/// number per form factor, so their bounces through glass are dimmed, not tinted.
fn passed(vis: &Visibility, a: DVec3, b: DVec3, skip: [usize; 2]) -> f64 {
    crate::visibility::channel_mean(vis.transmitted_skipping(a, b, skip))
}

/// Ray-cast form factor from the receiving point `at` to `patch` (Wallace, Elmquist, Haines
/// 1989, their equation for a disk of area `dA` at distance `r`): the patch split into
/// [`RAYCAST_SAMPLES`] equal sub-triangles, each a disk at its centroid. Adds the rays cast.
pub(crate) fn raycast_form_factor(
    vis: &Visibility,
    at: &SurfacePoint,
    patch: &Patch,
    rays: &mut u64,
) -> f64 {
    if culled(at, patch) {
        return 0.0;
    }
    let k = RAYCAST_SPLIT as f64;
    let da = patch.area / (RAYCAST_SAMPLES as f64);
    let [a, b, c] = patch.p;
    let (e1, e2) = (b - a, c - a);
    let skip = [at.polygon, patch.polygon];
    let mut f = 0.0;
    let mut sample = |s: f64, t: f64| {
        let q = a + e1 * (s / k) + e2 * (t / k);
        let d = q - at.p;
        let r2 = d.length_squared();
        let r = r2.sqrt();
        let (cos_r, cos_s) = (at.n.dot(d) / r, -patch.normal.dot(d) / r);
        if !(cos_r > 0.0 && cos_s > 0.0) {
            return;
        }
        *rays += 1;
        let v = passed(vis, at.ray_origin, q, skip);
        if v > 0.0 {
            f += v * (da * cos_r * cos_s / (PI * r2 + da));
        }
    };
    for i in 0..RAYCAST_SPLIT {
        for j in 0..RAYCAST_SPLIT - i {
            sample(i as f64 + 1.0 / 3.0, j as f64 + 1.0 / 3.0);
            if i + j + 2 <= RAYCAST_SPLIT {
                sample(i as f64 + 2.0 / 3.0, j as f64 + 2.0 / 3.0);
            }
        }
    }
    f
}

/// The form factors of one solve: the patches, the method, and the hemicube's counters.
pub(crate) struct Kernel<'a> {
    vis: &'a Visibility,
    patches: &'a [Patch],
    method: FormFactors,
    triangles: Vec<[DVec3; 3]>,
    hemicube: Option<Hemicube>,
    hemicubes: AtomicU64,
}

/// Counters of the hemicube method, reported in `--stats` (`solve.hemicube`).
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct HemicubeStats {
    /// Cells across the top face.
    pub resolution: usize,
    /// Cells of one hemicube, `3 R²`.
    pub cells: usize,
    /// Sum of the delta form factors (1 in the limit).
    pub delta_sum: f64,
    /// Hemicubes rendered (shooting patches, matrix rows, gathering vertices).
    pub hemicubes: u64,
}

impl<'a> Kernel<'a> {
    /// Form factors to `patches` by `method`; `resolution` is the hemicube's.
    pub(crate) fn new(
        vis: &'a Visibility,
        patches: &'a [Patch],
        method: FormFactors,
        resolution: u32,
    ) -> Kernel<'a> {
        Kernel {
            vis,
            patches,
            method,
            triangles: patches.iter().map(|p| p.p).collect(),
            hemicube: (method == FormFactors::Hemicube).then(|| Hemicube::new(resolution)),
            hemicubes: AtomicU64::new(0),
        }
    }

    /// The hemicube's counters (`None` for the other methods).
    pub(crate) fn hemicube_stats(&self) -> Option<HemicubeStats> {
        self.hemicube.as_ref().map(|h| HemicubeStats {
            resolution: h.resolution(),
            cells: h.cells(),
            delta_sum: h.delta_sum(),
            hemicubes: self.hemicubes.load(Ordering::Relaxed),
        })
    }

    /// Form factor from `at` to patch `j` alone (closed-form or ray-cast; a hemicube renders
    /// every patch, so one pair costs a whole row), adding the rays cast.
    fn pair(&self, at: &SurfacePoint, j: usize, rays: &mut u64) -> f64 {
        match self.method {
            FormFactors::Raycast => raycast_form_factor(self.vis, at, &self.patches[j], rays),
            _ => point_patch_form_factor(self.vis, at, &self.patches[j], rays),
        }
    }

    /// The hemicube at `at`: its form factor to every patch whose front faces it.
    fn hemicube_row(&self, hc: &Hemicube, at: &SurfacePoint) -> Vec<f64> {
        self.hemicubes.fetch_add(1, Ordering::Relaxed);
        let patches = self.patches;
        let mut f = hc
            .form_factors(at.p, at.n, &self.triangles, &|k| {
                patches[k].polygon == at.polygon
            })
            .form_factors;
        for (fk, patch) in f.iter_mut().zip(patches) {
            if patch.normal.dot(at.p - patch.centroid) <= 0.0 {
                *fk = 0.0;
            }
        }
        f
    }

    /// Form factors from the receiving point `at` to every patch `j` with `wanted(j)` (the
    /// others are 0 and, but for the hemicube, not evaluated), adding the rays cast.
    pub(crate) fn gather(
        &self,
        at: &SurfacePoint,
        wanted: &dyn Fn(usize) -> bool,
        rays: &mut u64,
    ) -> Vec<f64> {
        match &self.hemicube {
            Some(hc) => {
                let mut f = self.hemicube_row(hc, at);
                for (j, fj) in f.iter_mut().enumerate() {
                    if !wanted(j) {
                        *fj = 0.0;
                    }
                }
                f
            }
            None => (0..self.patches.len())
                .map(|j| {
                    if wanted(j) {
                        self.pair(at, j, rays)
                    } else {
                        0.0
                    }
                })
                .collect(),
        }
    }

    /// The receiving point at the centroid of patch `i`.
    pub(crate) fn centroid_point(&self, i: usize) -> SurfacePoint {
        let r = &self.patches[i];
        SurfacePoint::new(r.centroid, r.normal, r.polygon, self.vis)
    }

    /// Shooting from patch `i`: for every patch `j`, the form factor from `j`'s centroid to `i`
    /// (the irradiance at `j` per unit radiosity of `i`) and the rays it cast; 0 for `j = i`.
    /// The hemicube renders one hemicube at `i`'s centroid and uses reciprocity,
    /// `F_ji = F_ij A_i / A_j`, capped at 1 (Cohen, Chen, Wallace, Greenberg 1988); the others
    /// evaluate every receiver in parallel.
    pub(crate) fn shoot(&self, i: usize) -> Vec<(f64, u64)> {
        match &self.hemicube {
            Some(hc) => {
                let src = &self.patches[i];
                let f = self.hemicube_row(hc, &self.centroid_point(i));
                f.iter()
                    .zip(self.patches)
                    .enumerate()
                    .map(|(j, (&fij, r))| {
                        // The receiver's front must face the shooter's centre.
                        if j == i || fij <= 0.0 || r.normal.dot(src.centroid - r.centroid) <= 0.0 {
                            (0.0, 0)
                        } else {
                            ((fij * src.area / r.area).min(1.0), 0)
                        }
                    })
                    .collect()
            }
            None => (0..self.patches.len())
                .into_par_iter()
                .map(|j| {
                    if j == i {
                        return (0.0, 0);
                    }
                    let mut n = 0;
                    let f = self.pair(&self.centroid_point(j), i, &mut n);
                    (f, n)
                })
                .collect(),
        }
    }
}
