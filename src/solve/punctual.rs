//! Punctual lights at the mesh vertices: one light's irradiance at a point with its shadow
//! ray, and every light's at the vertices of a mesh, its visibility averaged over each
//! vertex's fan (what the solve's bounces start from; the lightmap takes these lights per
//! texel). Irradiance in W/m² per linear RGB channel.

use crate::light::{LightVector, NO_POLYGON, SurfacePoint, add_light, punctual_unoccluded, slant};
use crate::mesh::ReceiverMesh;
use crate::scene::{LightKind, PunctualLight, Scene};
use crate::visibility::Visibility;
use glam::DVec3;

/// Irradiance from one punctual light at a receiving point, and the rays it cast: the
/// unoccluded irradiance of [`punctual_unoccluded`] if one shadow ray towards the light is free.
pub fn punctual_irradiance(
    light: &PunctualLight,
    vis: &Visibility,
    at: &SurfacePoint,
) -> (DVec3, u64) {
    let Some(e) = punctual_unoccluded(light, at.p, at.n) else {
        return (DVec3::ZERO, 0);
    };
    (e * punctual_transmitted(light, vis, at), 1)
}

/// The unit direction from `p` towards a punctual light (a directional light: against its
/// direction).
pub(crate) fn towards(light: &PunctualLight, p: DVec3) -> DVec3 {
    match light.kind {
        LightKind::Directional => -light.direction,
        LightKind::Point | LightKind::Spot { .. } => (light.position - p).normalize_or_zero(),
    }
}

/// What of a punctual light one shadow ray from `at` lets through, per channel (it starts on
/// the line through the point, [`SurfacePoint::ray_origin_towards`]): 1 or 0, or less than 1
/// through see-through surfaces ([`Visibility::transmitted_skipping`]).
fn punctual_transmitted(light: &PunctualLight, vis: &Visibility, at: &SurfacePoint) -> DVec3 {
    match light.kind {
        LightKind::Directional => {
            let dir = -light.direction;
            vis.transmitted_towards(at.ray_origin_towards(dir), dir, at.polygon)
        }
        LightKind::Point | LightKind::Spot { .. } => {
            let dir = (light.position - at.p).normalize_or_zero();
            let origin = at.ray_origin_towards(dir);
            vis.transmitted_skipping(origin, light.position, [at.polygon, NO_POLYGON])
        }
    }
}

/// Barycentric coordinates of the points where [`punctual_over_fans`] tests a triangle: the
/// centroids of its four midpoint sub-triangles, a quadrature of equal weights.
const FAN_SAMPLES: [[f64; 3]; 4] = [
    [2.0 / 3.0, 1.0 / 6.0, 1.0 / 6.0],
    [1.0 / 6.0, 2.0 / 3.0, 1.0 / 6.0],
    [1.0 / 6.0, 1.0 / 6.0, 2.0 / 3.0],
    [1.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0],
];

/// Adds every punctual light's irradiance at the vertices of `mesh` to `h` and returns the rays
/// cast. A vertex gets the light's unoccluded irradiance at its point (`points`, one per vertex)
/// times the light's visibility averaged over its fan, weighted by the vertex's hat function:
/// V_v = ∫ φ_v V dA / ∫ φ_v dA, by [`FAN_SAMPLES`] in each triangle (shared by its three
/// vertices). This is the lumped L2 projection of the visibility onto the mesh's linear
/// elements (Heckbert, Winget, "Finite element methods for global illumination", 1991). Where the mesh holds a light's shadow lines (split per side), every fan
/// lies on one side and V_v is 0 or 1, as at the point; where a line is missing (a strip of
/// shadow thinner than the elements), the vertex gets its fan's share of shadow instead of
/// whatever its one point happens to see, so a 6 cm strip along a wall's corner no longer
/// darkens half the wall. Samples buried under other geometry ([`Visibility::buried`]) do not
/// count; a vertex without any other sample keeps the test at its point.
#[allow(clippy::too_many_arguments)]
pub(super) fn punctual_over_fans(
    scene: &Scene,
    vis: &Visibility,
    lights: &[usize],
    mesh: &ReceiverMesh,
    points: &[SurfacePoint],
    h: &mut [DVec3],
    mut light_vectors: Option<&mut [LightVector]>,
) -> u64 {
    let frame = &scene.polygons[mesh.polygon].frame;
    // Every triangle's samples in world space, once for all the lights.
    let samples: Vec<[DVec3; FAN_SAMPLES.len()]> = mesh
        .triangles
        .iter()
        .map(|t| {
            let c = t.map(|i| mesh.vertices[i as usize]);
            FAN_SAMPLES.map(|b| frame.world_from_plane(c[0] * b[0] + c[1] * b[1] + c[2] * b[2]))
        })
        .collect();
    let mut rays = 0;
    // Per vertex: the lit weight (per channel) and all the weight.
    let mut weights = vec![(DVec3::ZERO, 0.0f64); points.len()];
    for light in lights.iter().map(|&l| &scene.lights[l]) {
        let unoccluded: Vec<Option<DVec3>> = points
            .iter()
            .map(|q| punctual_unoccluded(light, q.p, q.n))
            .collect();
        if unoccluded.iter().all(Option::is_none) {
            continue;
        }
        weights.fill((DVec3::ZERO, 0.0));
        // The samples' visibility first, and which vertices see the light anywhere in their
        // fan; a triangle skipped (the light below every corner's horizon) is dark.
        let mut seen = vec![false; points.len()];
        let lit: Vec<Option<[DVec3; FAN_SAMPLES.len()]>> = mesh
            .triangles
            .iter()
            .zip(&samples)
            .map(|(t, at)| {
                if t.iter().all(|&i| unoccluded[i as usize].is_none()) {
                    return None;
                }
                let lit = at.map(|p| {
                    rays += 1;
                    let point = SurfacePoint::new(p, frame.n, mesh.polygon, vis);
                    punctual_transmitted(light, vis, &point)
                });
                if lit.iter().any(|l| *l != DVec3::ZERO) {
                    t.iter().for_each(|&i| seen[i as usize] = true);
                }
                Some(lit)
            })
            .collect();
        for ((t, lit), at) in mesh.triangles.iter().zip(&lit).zip(&samples) {
            let Some(lit) = lit else { continue };
            let area = mesh.triangle_area(t);
            for ((b, &lit), &p) in FAN_SAMPLES.iter().zip(lit).zip(at) {
                // A point buried under other geometry is never seen (its texels are left out
                // of the lightmap): its darkness must not reach the vertices beside it. That
                // matters beside a vertex that sees the light somewhere, and for a dark vertex
                // only until one of its samples counts (then it is 0, whatever else counts).
                let matters = t
                    .iter()
                    .any(|&i| seen[i as usize] || weights[i as usize].1 == 0.0);
                if lit == DVec3::ZERO && matters && vis.buried(p, frame.n) {
                    continue;
                }
                for (k, &i) in t.iter().enumerate() {
                    let w = area * b[k];
                    weights[i as usize].0 += lit * w;
                    weights[i as usize].1 += w;
                }
            }
        }
        for (i, e) in unoccluded.iter().enumerate() {
            let Some(e) = e else { continue };
            let (lit, all) = weights[i];
            let value = if all > 0.0 {
                *e * (lit / all)
            } else {
                let (value, r) = punctual_irradiance(light, vis, &points[i]);
                rays += r;
                value
            };
            h[i] += value;
            if let Some(q) = light_vectors.as_deref_mut() {
                let at = &points[i];
                add_light(&mut q[i], value, slant(towards(light, at.p), at.n));
            }
        }
    }
    rays
}
