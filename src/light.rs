//! Shared light models: receiving points, area emitters (their convex pieces, sample points and
//! unoccluded form factor), the punctual light model, and luminance.
//!
//! Depends on [`crate::geometry`] and the plain data types of [`crate::scene`] only. Radiance
//! in W/(m² sr), irradiance in W/m², per linear RGB channel; lengths in scene units.

use crate::geometry::{
    convex_hull, convex_pieces, point_polygon_form_factor, polygon_light_vector, signed_area,
};
use crate::scene::{Frame, LightKind, PunctualLight, Scene};
use glam::{DVec2, DVec3};

/// Luminance of a linear RGB colour with the Rec. 709 / sRGB primaries (ITU-R BT.709 weights
/// 0.2126, 0.7152, 0.0722), in the colour's own units.
pub fn luminance(c: DVec3) -> f64 {
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}

// ---------------------------------------------------------------------------------------------
// Receiving points
/// A receiving point: where form factors are evaluated, the unit normal, and where its rays
/// start (off the surface, and off any neighbouring surface that meets it at an edge).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfacePoint {
    pub p: DVec3,
    pub n: DVec3,
    pub ray_origin: DVec3,
    /// The polygon the point lies on ([`NO_POLYGON`] if none): it never blocks its own rays.
    pub polygon: usize,
}

/// [`SurfacePoint::polygon`] of a point on no polygon.
pub const NO_POLYGON: usize = usize::MAX;

impl SurfacePoint {
    /// Where a shadow ray towards unit direction `dir` (a punctual light) starts: on the line
    /// through the surface point below [`SurfacePoint::ray_origin`] along `dir`, as far along
    /// it as `ray_origin` is above the surface, so the ray meets occluders where a ray from the
    /// surface itself would and a hard shadow's edge stays where it is. Lifted along the normal
    /// instead, a ray from a sunlit wall moves the wall's shadow edges by the lift times the
    /// tangent of the sun's angle (7 cm on a city's walls, with the lift at 3 cm), and a vertex
    /// evaluated a few centimetres beside a shadow line lands on its wrong side. Not farther
    /// along the ray than the lift: at a grazing sun that would step past an occluder a few
    /// centimetres from the wall (a parapet, a neighbour's roof edge).
    pub(crate) fn ray_origin_towards(&self, dir: DVec3) -> DVec3 {
        let lift = self.n.dot(self.ray_origin - self.p);
        let below = self.ray_origin - self.n * lift;
        below + dir * lift
    }

    /// A point inside a surface: rays start `2 epsilon` along the normal (`epsilon`: the ray
    /// offset of the scene's BVH, scene units).
    pub(crate) fn with_epsilon(p: DVec3, n: DVec3, polygon: usize, epsilon: f64) -> SurfacePoint {
        SurfacePoint {
            p,
            n,
            ray_origin: p + n * (2.0 * epsilon),
            polygon,
        }
    }

    /// A point on or near a polygon's edge: `inward` is the unit in-plane direction into the
    /// polygon. Form factors are evaluated [`crate::scene::tolerance::INPUT`] of the scene extent
    /// (`extent`, scene units) inside, rays start `4 epsilon` inside and `2 epsilon` off the
    /// surface.
    pub(crate) fn near_edge_with_epsilon(
        p: DVec3,
        n: DVec3,
        inward: DVec3,
        polygon: usize,
        epsilon: f64,
        extent: f64,
    ) -> SurfacePoint {
        let e = epsilon;
        SurfacePoint {
            p: p + inward * (crate::scene::tolerance::INPUT * extent),
            n,
            ray_origin: p + inward * (4.0 * e) + n * (2.0 * e),
            polygon,
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Light vectors (directional lightmaps)

/// The first moment of the incident radiance at a surface point, `Q = ∫ L ω dω` over the
/// point's hemisphere (Gershun's light vector), per linear RGB channel: `Q[axis]` holds the
/// world axis `x`, `y` or `z` component of every channel, W/m². Its component along the
/// surface normal is the irradiance H; the part along the surface is what a normal map
/// turns towards or away from. Half of it is the L1 band of the irradiance's spherical
/// harmonics (Ramamoorthi, Hanrahan, "An efficient representation for irradiance environment
/// maps", SIGGRAPH 2001), which [`crate::lightmap::directional`] writes.
pub(crate) type LightVector = [DVec3; 3];

/// The smallest cosine to the normal that [`slant`] divides by: light arriving more grazing
/// than about 84° counts as arriving at 84°, so a sliver of light along the horizon cannot
/// blow the light vector up (its irradiance is small, its `ω / cos` is not).
pub(crate) const SLANT_MIN_COS: f64 = 0.1;

/// `ω / (n · ω)`: the light vector per unit irradiance of light arriving from unit direction
/// `w` at a surface of unit normal `n` (its normal component is 1; the cosine kept at least
/// [`SLANT_MIN_COS`]).
pub(crate) fn slant(w: DVec3, n: DVec3) -> DVec3 {
    w / n.dot(w).max(SLANT_MIN_COS)
}

/// `q += e ⊗ u`: irradiance `e` (W/m², per channel) arriving with slant `u` ([`slant`]).
pub(crate) fn add_light(q: &mut LightVector, e: DVec3, u: DVec3) {
    q[0] += e * u.x;
    q[1] += e * u.y;
    q[2] += e * u.z;
}

// ---------------------------------------------------------------------------------------------
// Area emitters

/// A planar area emitter as convex pieces in its own plane frame: for the unoccluded form factor
/// and for the backprojection ([`crate::solve::backproject`]).
#[derive(Clone, Debug)]
pub struct EmitterShape {
    /// The emitter's plane; `frame.n` is the emitting (front) side.
    pub frame: Frame,
    /// Convex pieces, counter-clockwise in `frame` coordinates (seen from the front).
    pub pieces: Vec<Vec<DVec2>>,
    /// The pieces in world space.
    pub(crate) pieces_world: Vec<Vec<DVec3>>,
    /// Convex hull of all pieces, counter-clockwise.
    pub(crate) hull: Vec<DVec2>,
    /// Area, scene units².
    pub(crate) area: f64,
    /// Diameter of the hull's bounding box: the length scale of the emitter's tolerances.
    pub(crate) size: f64,
}

impl EmitterShape {
    /// From the triangles of a planar polygon, in the plane coordinates of `frame`.
    pub(crate) fn new(frame: Frame, triangles_plane: &[[DVec2; 3]]) -> EmitterShape {
        let pieces: Vec<Vec<DVec2>> = convex_pieces(triangles_plane)
            .0
            .into_iter()
            .map(|p| {
                p.into_iter()
                    .map(|c| triangles_plane[c / 3][c % 3])
                    .collect()
            })
            .collect();
        let all: Vec<DVec2> = pieces.iter().flatten().copied().collect();
        let hull = convex_hull(&all);
        let (lo, hi) = all.iter().fold(
            (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY)),
            |(lo, hi), q| (lo.min(*q), hi.max(*q)),
        );
        EmitterShape {
            frame,
            area: pieces.iter().map(|p| signed_area(p)).sum(),
            pieces_world: pieces
                .iter()
                .map(|p| p.iter().map(|q| frame.world_from_plane(*q)).collect())
                .collect(),
            pieces,
            hull,
            size: if all.is_empty() {
                0.0
            } else {
                (hi - lo).length()
            },
        }
    }

    /// A convex polygon given by its world-space corners, counter-clockwise seen from the side
    /// it emits to.
    pub fn convex(corners: &[DVec3]) -> EmitterShape {
        // Newell's normal: the winding's area vector.
        let mut normal = DVec3::ZERO;
        for i in 0..corners.len() {
            normal += corners[i].cross(corners[(i + 1) % corners.len()]);
        }
        let frame = Frame::new(corners[0], normal, corners[1] - corners[0]);
        let q: Vec<DVec2> = corners.iter().map(|c| frame.plane_from_world(*c)).collect();
        let tris: Vec<[DVec2; 3]> = (1..q.len() - 1).map(|i| [q[0], q[i], q[i + 1]]).collect();
        EmitterShape::new(frame, &tris)
    }

    /// Occluders no farther than this in front of the emitter's plane (scene units) are taken
    /// to lie in it, and never block it.
    pub(crate) fn plane_tolerance(&self) -> f64 {
        1e-9 * self.size
    }

    /// The hull's corners in world space.
    pub(crate) fn hull_world(&self) -> Vec<DVec3> {
        self.hull
            .iter()
            .map(|q| self.frame.world_from_plane(*q))
            .collect()
    }

    /// The slant ([`slant`]) of the emitter's unoccluded light at `(p, n)`: the light vector
    /// of its part above the horizon of `p` (`∫ ω dω` over its solid angle, by the vector form
    /// of Lambert's contour formula, [`polygon_light_vector`]) over that part's `π F`. `None`
    /// behind the emitter or below the horizon.
    pub(crate) fn slant(&self, p: DVec3, n: DVec3) -> Option<DVec3> {
        if self.frame.n.dot(p - self.frame.origin) <= 0.0 {
            return None;
        }
        let v: DVec3 = self
            .pieces_world
            .iter()
            .map(|piece| polygon_light_vector(p, n, piece))
            .sum();
        let normal = n.dot(v);
        (normal > 0.0).then(|| {
            let u = v / normal;
            // At most as slanted as [`slant`] lets a single direction be.
            let t = u - n;
            let limit = (1.0 - SLANT_MIN_COS * SLANT_MIN_COS).sqrt() / SLANT_MIN_COS;
            n + t * (limit / t.length().max(limit))
        })
    }

    /// Unoccluded form factor from `(p, n)` to the emitter's front face (Lambert's contour
    /// formula over the pieces, each clipped to the horizon of `p`); 0 behind the emitter.
    pub fn form_factor(&self, p: DVec3, n: DVec3) -> f64 {
        if self.frame.n.dot(p - self.frame.origin) <= 0.0 {
            return 0.0;
        }
        self.pieces_world
            .iter()
            .map(|piece| point_polygon_form_factor(p, n, piece))
            .sum()
    }
}

/// An area emitter: one emitting polygon with a fixed, stratified set of sample points.
pub struct AreaEmitter {
    /// Index into [`Scene::polygons`].
    pub(crate) polygon: usize,
    /// Emitted radiance (front face), W/(m² sr).
    pub radiance: DVec3,
    /// Front normal.
    pub(crate) normal: DVec3,
    /// The polygon's triangles, world space.
    pub triangles: Vec<[DVec3; 3]>,
    /// The polygon merged into convex pieces in its plane, for the form factors and the
    /// backprojection.
    pub shape: EmitterShape,
    /// Sample sets, each a stratified set of points with their area (the areas of a set sum to
    /// the emitter's area): `samples[0]` has the full count, each next set half as many.
    pub(crate) samples: Vec<Vec<(DVec3, f64)>>,
    /// The mean of the triangles' corners, for the light tree.
    pub(crate) center: DVec3,
}

/// The radical inverse in base 2 (van der Corput), the second Hammersley coordinate, in [0, 1).
pub(crate) fn radical_inverse2(mut i: u32) -> f64 {
    i = i.reverse_bits();
    i as f64 / 4294967296.0
}

/// Maps the unit square to a triangle with uniform density.
fn square_to_triangle(t: &[DVec3; 3], u: f64, v: f64) -> DVec3 {
    let su = u.sqrt();
    t[0] * (1.0 - su) + t[1] * (su * (1.0 - v)) + t[2] * (su * v)
}

impl AreaEmitter {
    /// The emitters of a scene with `samples` points each: a Hammersley set spread over the
    /// polygon's triangles by area.
    pub(crate) fn all(scene: &Scene, samples: usize) -> Vec<AreaEmitter> {
        scene
            .emitters()
            .map(|id| {
                let poly = &scene.polygons[id];
                let triangles: Vec<[DVec3; 3]> = poly
                    .triangles
                    .iter()
                    .map(|&t| scene.triangles[t].p)
                    .collect();
                let areas: Vec<f64> = poly
                    .triangles
                    .iter()
                    .map(|&t| scene.triangles[t].area())
                    .collect();
                let total: f64 = areas.iter().sum();
                let mut sets = Vec::new();
                let mut n = samples.max(1);
                loop {
                    let mut pts = Vec::with_capacity(n);
                    for k in 0..n {
                        // First coordinate stratified over the cumulative area of the triangles.
                        let mut u = (k as f64 + 0.5) / n as f64 * total;
                        let mut tri = 0;
                        while tri + 1 < areas.len() && u > areas[tri] {
                            u -= areas[tri];
                            tri += 1;
                        }
                        let uu = (u / areas[tri]).clamp(0.0, 1.0);
                        let v = radical_inverse2(k as u32);
                        pts.push((square_to_triangle(&triangles[tri], uu, v), total / n as f64));
                    }
                    sets.push(pts);
                    if n == 1 {
                        break;
                    }
                    n /= 2;
                }
                let center = triangles.iter().flatten().copied().sum::<DVec3>()
                    / (3 * triangles.len()) as f64;
                AreaEmitter {
                    polygon: id,
                    radiance: scene.materials[poly.material].radiance,
                    normal: poly.frame.n,
                    shape: EmitterShape::new(poly.frame, &poly.triangles_plane),
                    triangles,
                    samples: sets,
                    center,
                }
            })
            .collect()
    }

    /// Unoccluded form factor from `(p, n)` to the emitter's front face: Lambert's contour
    /// formula over its convex pieces, clipped to the horizon of `p`.
    pub fn form_factor(&self, p: DVec3, n: DVec3) -> f64 {
        self.shape.form_factor(p, n)
    }

    /// Unoccluded irradiance at `(p, n)` from the emitter, `L π F` (W/m² per channel).
    pub fn irradiance(&self, p: DVec3, n: DVec3) -> DVec3 {
        self.radiance * (std::f64::consts::PI * self.form_factor(p, n))
    }
}

// ---------------------------------------------------------------------------------------------
// Punctual lights

/// Irradiance from one punctual light at point `p` with unit normal `n` if nothing blocked it,
/// W/m² per channel: point and spot `I cos(theta) / d^2` (`I` in W/sr, `d` in scene units)
/// times glTF KHR_lights_punctual's range window `clamp(1 - (d/range)^4, 0, 1)` and, for a spot,
/// its cone falloff (the square of a linear ramp in `cos` between the outer and inner cone
/// angles); directional `E cos(theta)`. `None` when the light cannot reach the point (behind
/// it, at or past the range, outside the cone).
///
/// The one model of punctual light: the direct light, the Monte Carlo reference and the
/// discontinuity ranking all use it.
pub(crate) fn punctual_unoccluded(light: &PunctualLight, p: DVec3, n: DVec3) -> Option<DVec3> {
    match light.kind {
        LightKind::Directional => {
            let cos = n.dot(-light.direction);
            (cos > 0.0).then(|| light.intensity * cos)
        }
        LightKind::Point | LightKind::Spot { .. } => {
            let d = light.position - p;
            let dist2 = d.length_squared();
            let dist = dist2.sqrt();
            if dist <= 0.0 {
                return None;
            }
            let to_light = d / dist;
            let cos = n.dot(to_light);
            if cos <= 0.0 {
                return None;
            }
            let mut atten = 1.0 / dist2;
            if let Some(range) = light.range.filter(|r| *r > 0.0) {
                atten *= (1.0 - (dist / range).powi(4)).clamp(0.0, 1.0);
            }
            if let LightKind::Spot {
                inner_cone,
                outer_cone,
            } = light.kind
            {
                // glTF KHR_lights_punctual reference falloff.
                let cd = light.direction.dot(-to_light);
                let scale = 1.0 / (inner_cone.cos() - outer_cone.cos()).max(0.001);
                let offset = -outer_cone.cos() * scale;
                let a = (cd * scale + offset).clamp(0.0, 1.0);
                atten *= a * a;
            }
            (atten > 0.0).then(|| light.intensity * (cos * atten))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn radical_inverse_is_van_der_corput() {
        assert_eq!(radical_inverse2(0), 0.0);
        assert_eq!(radical_inverse2(1), 0.5);
        assert_eq!(radical_inverse2(2), 0.25);
        assert_eq!(radical_inverse2(3), 0.75);
    }

    fn lamp(kind: LightKind, range: Option<f64>) -> PunctualLight {
        PunctualLight {
            kind,
            name: "lamp".into(),
            position: DVec3::new(0.0, 2.0, 0.0),
            direction: DVec3::NEG_Y,
            intensity: DVec3::splat(10.0),
            range,
            node: 0,
            index: 0,
        }
    }

    #[test]
    fn point_light_is_inverse_square_times_cosine() {
        let l = lamp(LightKind::Point, None);
        let h = punctual_unoccluded(&l, DVec3::new(1.0, 0.0, 0.0), DVec3::Y).unwrap();
        // I h / r³ with h = 2, r² = 5.
        assert!((h.x - 10.0 * 2.0 / 5f64.powf(1.5)).abs() < 1e-12, "{h}");
        assert!(punctual_unoccluded(&l, DVec3::ZERO, DVec3::NEG_Y).is_none());
    }

    #[test]
    fn range_window_cuts_the_light_off() {
        let far = DVec3::new(3.0, 0.0, 0.0);
        assert!(punctual_unoccluded(&lamp(LightKind::Point, Some(3.0)), far, DVec3::Y).is_none());
        let near = punctual_unoccluded(&lamp(LightKind::Point, Some(3.0)), DVec3::ZERO, DVec3::Y);
        let free = punctual_unoccluded(&lamp(LightKind::Point, None), DVec3::ZERO, DVec3::Y);
        // d = 2: the window is 1 - (2/3)^4.
        let w = 1.0 - (2.0f64 / 3.0).powi(4);
        assert!((near.unwrap().x - free.unwrap().x * w).abs() < 1e-12);
    }

    #[test]
    fn spot_cone_falls_off_between_inner_and_outer() {
        let spot = lamp(
            LightKind::Spot {
                inner_cone: 0.4,
                outer_cone: 0.6,
            },
            None,
        );
        let point = lamp(LightKind::Point, None);
        let at = |x: f64| DVec3::new(x, 0.0, 0.0);
        // Inside the inner cone (tan 0.4 x 2 = 0.85 m): the point light's value.
        assert_eq!(
            punctual_unoccluded(&spot, at(0.5), DVec3::Y),
            punctual_unoccluded(&point, at(0.5), DVec3::Y)
        );
        // Past the outer cone (tan 0.6 x 2 = 1.37 m): nothing.
        assert!(punctual_unoccluded(&spot, at(1.5), DVec3::Y).is_none());
        // Between: dimmer than the point light, brighter than nothing.
        let s = punctual_unoccluded(&spot, at(1.1), DVec3::Y).unwrap().x;
        let p = punctual_unoccluded(&point, at(1.1), DVec3::Y).unwrap().x;
        assert!(s > 0.0 && s < p, "{s} {p}");
    }

    #[test]
    fn luminance_of_white_is_its_value() {
        assert!((luminance(DVec3::splat(2.0)) - 2.0).abs() < 1e-15);
    }
}
