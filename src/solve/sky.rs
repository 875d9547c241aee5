//! The sky (`--sky R,G,B`): a uniform environment radiance `L_sky` (W/(m² sr), linear RGB)
//! arriving from every direction the scene does not block, as direct light at the mesh vertices
//! (and at the patches of the patch solvers), reflected like any other direct light.
//!
//! At a receiving point `(p, n)` the sky gives the irradiance
//!
//! ```text
//! E = L_sky ∫_{unblocked hemisphere} cos(theta) dω = pi L_sky V,
//! ```
//!
//! with `V` in [0, 1] the cosine-weighted fraction of the hemisphere that no surface blocks
//! (an open plane: `V = 1`, `E = pi L_sky`). `V` is estimated with `N` fixed shadow rays
//! (`--sky-samples`), cosine-distributed so every ray weighs `1/N`:
//!
//! * the point set is the `N`-point Hammersley set in the unit square (`((k + 1/2)/N,
//!   radical_inverse_2(k))`; Hammersley, "Monte Carlo methods for solving multivariable
//!   problems", 1960), stratified in both coordinates;
//! * it is shifted modulo 1 by an offset hashed from the point's coordinates (a Cranley-Patterson
//!   rotation: Cranley, Patterson, "Randomization of number theoretic methods for multiple
//!   integration", SIAM J. Numer. Anal. 1976), so neighbouring vertices use different rays and
//!   the pattern's error is noise, not a structure that aliases across the lightmap; the same
//!   point always gets the same rays, whatever the thread count;
//! * it is mapped to the unit disk by Shirley and Chiu's concentric map ("A low distortion map
//!   between disk and square", JGT 1997), which keeps the strata compact, and lifted to the
//!   hemisphere (Malley's method: uniform on the disk is cosine-weighted on the hemisphere).
//!
//! A point whose tangent plane has the scene's whole bounding box at or below its ray origin
//! (a roof above everything, a plane alone) sees the open sky: `V = 1` exactly, and no ray is
//! cast.
//!
//! The sky does not reflect: light that leaves the scene is lost. Its noise is measured in
//! `tests/it/sky.rs` against the closed form `V = 1 - sum_faces F(p -> face)` of a box on a
//! ground plane (Lambert's contour formula, [`crate::geometry::point_polygon_form_factor`]).

use crate::error::Error;
use crate::geometry::box_corners;
use crate::light::{SurfacePoint, radical_inverse2};
use crate::rng::{GAMMA, unit_f64};
use crate::scene::Scene;
use crate::visibility::Visibility;
use glam::{DVec2, DVec3};
use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, PI};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

/// Default of `--sky-samples`: shadow rays per receiving point. Measured on the ground + box of
/// `tests/it/sky.rs` (README, "The sky").
pub const DEFAULT_SAMPLES: usize = 256;

/// The range of `--sky-samples`.
pub(crate) const SAMPLES_RANGE: std::ops::RangeInclusive<usize> = 1..=65536;

/// `--stats`: `solve.sky`.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct SkyStats {
    /// `L_sky`, W/(m² sr), linear RGB.
    pub radiance: [f64; 3],
    /// Shadow rays per receiving point (`--sky-samples`).
    pub samples: usize,
    /// Receiving points (vertices and patch centres) the sky was evaluated at.
    pub points: u64,
    /// Of those, the points that see the open sky by the bounding-box test (no ray cast).
    pub open: u64,
    /// Sky shadow rays cast.
    pub rays: u64,
    /// Time spent on the sky, summed over threads, s.
    pub seconds: f64,
}

/// The sky of a solve: its radiance, the fixed point set and the scene's bounds.
pub struct Sky {
    /// `L_sky`, W/(m² sr), linear RGB; some channel is positive.
    pub(crate) radiance: DVec3,
    /// The rays of every receiving point.
    rays_of: CosineRays,
    /// The scene's bounding-box corners.
    corners: [DVec3; 8],
    points: AtomicU64,
    open: AtomicU64,
    rays: AtomicU64,
    nanos: AtomicU64,
}

impl Sky {
    /// The sky of `scene` with radiance `radiance` and `samples` rays per point; `None` when
    /// every channel of `radiance` is 0 (no sky).
    pub fn new(scene: &Scene, radiance: DVec3, samples: usize) -> Option<Sky> {
        if radiance.max_element() <= 0.0 {
            return None;
        }
        Some(Sky {
            radiance,
            rays_of: CosineRays::new(samples),
            corners: box_corners(scene.bounds_min, scene.bounds_max),
            points: AtomicU64::new(0),
            open: AtomicU64::new(0),
            rays: AtomicU64::new(0),
            nanos: AtomicU64::new(0),
        })
    }

    /// The cosine-weighted unblocked fraction `V` of the hemisphere of `at` (dimensionless,
    /// 0..1), and the rays cast: 1 without a ray when the scene's bounding box lies at or below
    /// the plane of `at`'s ray origin, else the fraction of the point's rays
    /// ([`Sky::directions`]) that leave the scene (the mean over the channels of
    /// [`Sky::transmitted_fraction`]).
    pub fn visible_fraction(&self, vis: &Visibility, at: &SurfacePoint) -> (f64, u64) {
        let (v, rays) = self.transmitted_fraction(vis, at);
        let mean = if v.x == v.y && v.y == v.z {
            v.x
        } else {
            v.element_sum() / 3.0
        };
        (mean, rays)
    }

    /// [`Sky::visible_fraction`] per linear RGB channel: a ray through see-through surfaces
    /// counts for what they let through ([`Visibility::transmitted_towards`]).
    pub(crate) fn transmitted_fraction(&self, vis: &Visibility, at: &SurfacePoint) -> (DVec3, u64) {
        self.transmitted(vis, at, None)
    }

    /// [`Sky::transmitted_fraction`], and with `light` the sky's light vector at `at` added to
    /// it: `pi L_sky / N` times what each ray lets through times its [`crate::light::slant`]
    /// (an open point: `pi L_sky n`).
    fn transmitted(
        &self,
        vis: &Visibility,
        at: &SurfacePoint,
        mut light: Option<&mut crate::light::LightVector>,
    ) -> (DVec3, u64) {
        let o = at.ray_origin;
        if self.corners.iter().all(|c| at.n.dot(*c - o) <= 0.0) {
            if let Some(light) = light {
                crate::light::add_light(light, self.radiance * PI, at.n);
            }
            return (DVec3::ONE, 0);
        }
        let n = self.rays_of.len() as f64;
        let mut free = DVec3::ZERO;
        for d in self.directions(at) {
            let t = vis.transmitted_towards(o, d, at.polygon);
            free += t;
            if let Some(light) = light.as_deref_mut() {
                let u = crate::light::slant(d, at.n);
                crate::light::add_light(light, self.radiance * (t * (PI / n)), u);
            }
        }
        (free / n, n as u64)
    }

    /// The rays of `at` ([`CosineRays::directions`]).
    pub(crate) fn directions<'s>(&'s self, at: &SurfacePoint) -> impl Iterator<Item = DVec3> + 's {
        self.rays_of.directions(at)
    }

    /// The fraction of the rays of `at` ([`Sky::directions`], cosine-weighted) whose first hit
    /// `accept` takes (it gets the hit triangle and the ray's direction): for example the
    /// cosine-weighted fraction of a point's hemisphere that sees reflecting surfaces, the
    /// independent estimate the hierarchical solver's link coefficients are tested against.
    pub fn hit_fraction(
        &self,
        vis: &Visibility,
        at: &SurfacePoint,
        accept: impl Fn(usize, DVec3) -> bool,
    ) -> f64 {
        let hits = self
            .directions(at)
            .filter(|d| {
                vis.first_hit(at.ray_origin, *d, 1e30)
                    .is_some_and(|hit| accept(hit.triangle, *d))
            })
            .count();
        hits as f64 / self.rays_of.len() as f64
    }

    /// Adds the sky's irradiance `pi L_sky V` (W/m²) of each of `points` to `h`, and with
    /// `light` its light vector ([`crate::light::LightVector`]): `pi L_sky` times the mean over
    /// the rays of what each lets through times its [`crate::light::slant`] (an open point:
    /// `pi L_sky n`). Counts the points, rays and time.
    pub(crate) fn add_light(
        &self,
        vis: &Visibility,
        points: &[SurfacePoint],
        h: &mut [DVec3],
        mut light: Option<&mut [crate::light::LightVector]>,
    ) {
        let start = Instant::now();
        let (mut open, mut rays) = (0, 0);
        for (i, (at, h)) in points.iter().zip(h).enumerate() {
            let (v, r) = self.transmitted(vis, at, light.as_deref_mut().map(|l| &mut l[i]));
            *h += self.radiance * (v * PI);
            rays += r;
            open += u64::from(r == 0);
        }
        self.points
            .fetch_add(points.len() as u64, Ordering::Relaxed);
        self.open.fetch_add(open, Ordering::Relaxed);
        self.rays.fetch_add(rays, Ordering::Relaxed);
        self.nanos
            .fetch_add(start.elapsed().as_nanos() as u64, Ordering::Relaxed);
    }

    /// The counters so far.
    pub(crate) fn stats(&self) -> SkyStats {
        let load = |a: &AtomicU64| a.load(Ordering::Relaxed);
        SkyStats {
            radiance: self.radiance.to_array(),
            samples: self.rays_of.len(),
            points: load(&self.points),
            open: load(&self.open),
            rays: load(&self.rays),
            seconds: load(&self.nanos) as f64 * 1e-9,
        }
    }

    /// Sky shadow rays cast so far.
    pub(crate) fn rays(&self) -> u64 {
        self.rays.load(Ordering::Relaxed)
    }
}

/// A fixed set of cosine-distributed directions over a point's hemisphere, each weighing
/// `1/N`: the `N`-point Hammersley set, shifted per point by a hash of its position (a
/// Cranley-Patterson rotation), mapped to the disk by the concentric map and lifted to the
/// hemisphere (see the module doc). The sky's shadow rays and the ambient occlusion's rays
/// ([`crate::lightmap::ao`]).
pub(crate) struct CosineRays {
    /// The Hammersley set in the unit square.
    square: Vec<DVec2>,
}

impl CosineRays {
    /// `n` (at least 1) directions per point.
    pub(crate) fn new(n: usize) -> CosineRays {
        let n = n.max(1);
        CosineRays {
            square: (0..n)
                .map(|k| DVec2::new((k as f64 + 0.5) / n as f64, radical_inverse2(k as u32)))
                .collect(),
        }
    }

    /// The same shifted point set lifted to the hemisphere about `at.n` with equal solid
    /// angle per direction (`cos θ` uniform in [0, 1)): unit directions, uniformly distributed.
    pub(crate) fn uniform_directions<'s>(
        &'s self,
        at: &SurfacePoint,
    ) -> impl Iterator<Item = DVec3> + 's {
        let shift = point_shift(at.p);
        let (t, b) = at.n.any_orthonormal_pair();
        let n = at.n;
        self.square.iter().map(move |q| {
            let s = (*q + shift).fract();
            let r = (1.0 - s.x * s.x).max(0.0).sqrt();
            let phi = 2.0 * std::f64::consts::PI * s.y;
            t * (r * phi.cos()) + b * (r * phi.sin()) + n * s.x
        })
    }

    /// Directions per point.
    pub(crate) fn len(&self) -> usize {
        self.square.len()
    }

    /// The rays of `at`: the point set shifted by the hash of `at.p`, mapped to the disk and
    /// lifted to the hemisphere about `at.n` (unit directions, cosine-distributed).
    pub(crate) fn directions<'s>(&'s self, at: &SurfacePoint) -> impl Iterator<Item = DVec3> + 's {
        let shift = point_shift(at.p);
        let (t, b) = at.n.any_orthonormal_pair();
        let n = at.n;
        self.square.iter().map(move |q| {
            let d = concentric_disk((*q + shift).fract());
            let z = (1.0 - d.length_squared()).max(0.0).sqrt();
            (t * d.x + b * d.y + n * z).normalize()
        })
    }
}

/// Shirley and Chiu's concentric map from the unit square to the unit disk (JGT 1997): the
/// square's concentric squares go to concentric circles, so strata stay compact and areas keep
/// their proportions (uniform in, uniform out).
pub(crate) fn concentric_disk(u: DVec2) -> DVec2 {
    let a = 2.0 * u.x - 1.0;
    let b = 2.0 * u.y - 1.0;
    if a == 0.0 && b == 0.0 {
        return DVec2::ZERO;
    }
    let (r, phi) = if a.abs() > b.abs() {
        (a, FRAC_PI_4 * (b / a))
    } else {
        (b, FRAC_PI_2 - FRAC_PI_4 * (a / b))
    };
    DVec2::new(r * phi.cos(), r * phi.sin())
}

/// The Cranley-Patterson offset of a point, in [0, 1)²: a hash of its coordinates' bits (the
/// finaliser of MurmurHash3's 64-bit variant, Appleby 2008, over a multiplicative mix).
fn point_shift(p: DVec3) -> DVec2 {
    let fmix = |mut k: u64| {
        k ^= k >> 33;
        k = k.wrapping_mul(0xFF51_AFD7_ED55_8CCD);
        k ^= k >> 33;
        k = k.wrapping_mul(0xC4CE_B9FE_1A85_EC53);
        k ^ (k >> 33)
    };
    let h = fmix(
        p.x.to_bits() ^ fmix(p.y.to_bits() ^ fmix(p.z.to_bits()).rotate_left(17)).rotate_left(31),
    );
    DVec2::new(unit_f64(h), unit_f64(fmix(h ^ GAMMA)))
}

/// Checks a sky radiance: three finite, non-negative numbers. The reason when not.
pub(crate) fn check_radiance(radiance: DVec3) -> Result<(), String> {
    if radiance.is_finite() && radiance.min_element() >= 0.0 {
        Ok(())
    } else {
        Err(format!(
            "the sky radiance must be three finite, non-negative numbers (W/(m² sr), linear \
             RGB); got {},{},{}",
            radiance.x, radiance.y, radiance.z
        ))
    }
}

/// Parses `R,G,B` (as `--sky` takes it) into a sky radiance, W/(m² sr); `option` names the
/// option in the error.
pub fn parse_radiance(text: &str, option: &'static str) -> Result<DVec3, Error> {
    let bad = |reason: String| Error::Option { option, reason };
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    let [r, g, b] = parts.as_slice() else {
        return Err(bad(format!(
            "expected R,G,B (three numbers separated by commas, e.g. 1,1,1), got {text:?}"
        )));
    };
    let mut c = [0.0; 3];
    for (value, part) in c.iter_mut().zip([r, g, b]) {
        *value = part
            .parse::<f64>()
            .map_err(|_| bad(format!("{part:?} in {text:?} is not a number")))?;
    }
    let radiance = DVec3::from_array(c);
    check_radiance(radiance).map_err(bad)?;
    Ok(radiance)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn concentric_map_is_area_preserving_and_onto_the_disk() {
        // A grid of cells: each maps into the disk, with area pi / cells (by the shoelace
        // formula over its mapped outline, each side cut into 16 pieces).
        let n = 32;
        let k = 16;
        let mut total = 0.0;
        for i in 0..n {
            for j in 0..n {
                let at = |x: f64, y: f64| {
                    concentric_disk(DVec2::new(
                        (i as f64 + x) / n as f64,
                        (j as f64 + y) / n as f64,
                    ))
                };
                let mut outline = Vec::new();
                for s in 0..k {
                    let t = s as f64 / k as f64;
                    outline.push(at(t, 0.0));
                }
                for s in 0..k {
                    outline.push(at(1.0, s as f64 / k as f64));
                }
                for s in 0..k {
                    outline.push(at(1.0 - s as f64 / k as f64, 1.0));
                }
                for s in 0..k {
                    outline.push(at(0.0, 1.0 - s as f64 / k as f64));
                }
                assert!(outline.iter().all(|p| p.length() <= 1.0 + 1e-12));
                let area = crate::geometry::signed_area(&outline).abs();
                let expected = PI / (n * n) as f64;
                assert!(
                    (area / expected - 1.0).abs() < 2e-3,
                    "cell {i},{j}: {area} against {expected}"
                );
                total += area;
            }
        }
        assert!((total / PI - 1.0).abs() < 1e-3, "{total}");
        // The centre and the edges' midpoints.
        assert_eq!(concentric_disk(DVec2::splat(0.5)), DVec2::ZERO);
        assert!((concentric_disk(DVec2::new(1.0, 0.5)) - DVec2::X).length() < 1e-15);
        assert!((concentric_disk(DVec2::new(0.5, 1.0)) - DVec2::Y).length() < 1e-15);
    }

    #[test]
    fn directions_are_cosine_weighted() {
        // Over many points' rotated sets, E[cos] = 2/3 and E[cos²] = 1/2 under cos/pi; each
        // set alone is within a few 1e-3 of them (stratified).
        let scene = Scene::default();
        let sky = Sky::new(&scene, DVec3::ONE, 256).unwrap();
        let n = DVec3::new(0.3, -0.8, 0.2).normalize();
        for k in 0..50 {
            let at = SurfacePoint::with_epsilon(DVec3::new(k as f64 * 0.37, 1.0, -2.0), n, 0, 0.0);
            let (mut c1, mut c2) = (0.0, 0.0);
            for d in sky.directions(&at) {
                assert!((d.length() - 1.0).abs() < 1e-12);
                let c = d.dot(n);
                assert!(c >= 0.0);
                c1 += c;
                c2 += c * c;
            }
            assert!((c1 / 256.0 - 2.0 / 3.0).abs() < 3e-3, "{}", c1 / 256.0);
            assert!((c2 / 256.0 - 0.5).abs() < 3e-3, "{}", c2 / 256.0);
        }
    }

    #[test]
    fn shifts_differ_between_points_and_repeat_for_one() {
        let a = point_shift(DVec3::new(0.1, 0.0, 0.2));
        let b = point_shift(DVec3::new(0.1, 0.0, 0.2000001));
        assert_eq!(a, point_shift(DVec3::new(0.1, 0.0, 0.2)));
        assert_ne!(a, b);
        assert!(a.min_element() >= 0.0 && a.max_element() < 1.0);
        // Spread over the square: the mean over many points is near the centre.
        let mean = (0..4000)
            .map(|i| point_shift(DVec3::new(i as f64 * 0.01, 0.0, 0.0)))
            .sum::<DVec2>()
            / 4000.0;
        assert!(
            (mean - DVec2::splat(0.5)).abs().max_element() < 0.02,
            "{mean}"
        );
    }

    #[test]
    fn radiance_parses_and_bad_values_are_refused() {
        assert_eq!(
            parse_radiance("1, 0.5,2e-1", "--sky").unwrap(),
            DVec3::new(1.0, 0.5, 0.2)
        );
        assert_eq!(parse_radiance("0,0,0", "--sky").unwrap(), DVec3::ZERO);
        for bad in [
            "1,1", "1,1,1,1", "", "a,b,c", "1,-1,1", "nan,1,1", "1,inf,1", "1;1;1",
        ] {
            let e = parse_radiance(bad, "--sky").unwrap_err().to_string();
            assert!(e.starts_with("invalid option --sky: "), "{bad}: {e}");
        }
    }
}
