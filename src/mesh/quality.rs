//! The element quality of a meshing, measured: elements larger than the area cap, and angles
//! under [`ANGLE_LIMIT_DEG`] but where the constraints force one, in the elements larger than
//! [`SHAPE_FLOOR`] of the cap (the smaller ones are at the scale of the features that make
//! them). The repair of `mesh::cdt` leaves a meshing neither.

use super::cdt::SHAPE_FLOOR;
use super::{ANGLE_LIMIT_DEG, ReceiverMesh};
use glam::DVec2;
use std::collections::HashMap;

/// What [`measure`] found over a set of meshes.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Quality {
    pub elements: usize,
    /// Elements larger than the cap (by more than rounding), and the largest element's area
    /// as a multiple of the cap.
    pub over_cap: usize,
    pub largest: f64,
    /// Elements with an angle under the limit at a corner where constraints (the outline, the
    /// discontinuity lines) meet at less than the limit: the corner forces it.
    pub forced: usize,
    /// Elements larger than [`SHAPE_FLOOR`] of the cap with an angle under the limit elsewhere,
    /// and the smallest such angle (degrees; 180 when there is none).
    pub sharp: usize,
    pub sharpest: f64,
    /// Elements smaller than [`SHAPE_FLOOR`] of the cap with an angle under the limit elsewhere.
    pub sharp_below_floor: usize,
    /// Where the worst of each was: (polygon, element, area / cap or angle in degrees).
    pub worst_over: Option<(usize, usize, f64)>,
    pub worst_sharp: Option<(usize, usize, f64)>,
}

/// Measures the elements of `meshes` against the area cap `cap` (scene units²): their areas,
/// and their angles against [`ANGLE_LIMIT_DEG`] (Shewchuk 2002: Delaunay refinement bounds the
/// angles except at small input angles). A small angle is forced where it lies inside a
/// corner of two constraint edges (the outline's, the mesh's [`Constraint`](super::Constraint)s,
/// the cuts along the jumps) less than the limit apart, at the same vertex position.
pub fn measure(meshes: &[ReceiverMesh], cap: f64) -> Quality {
    let mut q = Quality {
        sharpest: 180.0,
        ..Default::default()
    };
    for m in meshes {
        let angles = small_angles(m);
        for (ti, t) in m.triangles.iter().enumerate() {
            q.elements += 1;
            let ratio = m.triangle_area(t) / cap;
            q.largest = q.largest.max(ratio);
            if ratio > 1.0 + 1e-6 {
                q.over_cap += 1;
                if q.worst_over.is_none_or(|w| ratio > w.2) {
                    q.worst_over = Some((m.polygon, ti, ratio));
                }
            }
            match angles[ti] {
                SmallAngle::Sharp(_) if ratio < SHAPE_FLOOR => q.sharp_below_floor += 1,
                SmallAngle::Sharp(a) => {
                    q.sharp += 1;
                    if a < q.sharpest {
                        q.sharpest = a;
                        q.worst_sharp = Some((m.polygon, ti, a));
                    }
                }
                SmallAngle::Forced => q.forced += 1,
                SmallAngle::None => {}
            }
        }
    }
    q
}

/// An element's angles against [`ANGLE_LIMIT_DEG`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SmallAngle {
    /// None under the limit.
    None,
    /// Under the limit only inside corners of constraints that meet at less than the limit.
    Forced,
    /// The smallest angle under the limit elsewhere (degrees).
    Sharp(f64),
}

/// Each element's [`SmallAngle`], in `m.triangles` order.
pub fn small_angles(m: &ReceiverMesh) -> Vec<SmallAngle> {
    let limit = ANGLE_LIMIT_DEG.to_radians();
    let corners = constraint_directions(m);
    m.triangles
        .iter()
        .map(|t| {
            let p = t.map(|i| m.vertices[i as usize]);
            let forced = |k: usize, a, b| {
                corners
                    .get(&key(p[k]))
                    .is_some_and(|dirs| crate::geometry::inside_narrow_corner(dirs, a, b, limit))
            };
            match crate::geometry::small_angles_of(&p, limit, forced) {
                (Some(s), _) => SmallAngle::Sharp(s.to_degrees()),
                (None, true) => SmallAngle::Forced,
                (None, false) => SmallAngle::None,
            }
        })
        .collect()
}

/// A vertex position as a hash key (split vertices share theirs).
fn key(p: DVec2) -> (u64, u64) {
    (p.x.to_bits(), p.y.to_bits())
}

/// Per vertex position, the directions (radians) of the constraint edges that leave it: the
/// mesh's constraints and its boundary edges (the outline, and the cuts along the jumps).
fn constraint_directions(m: &ReceiverMesh) -> HashMap<(u64, u64), Vec<f64>> {
    let mut edges: HashMap<(u32, u32), u32> = HashMap::new();
    for t in &m.triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            *edges.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    let lines = edges
        .iter()
        .filter(|(_, n)| **n == 1)
        .map(|(e, _)| *e)
        .chain(m.constraints.iter().map(|c| (c.a, c.b)));
    let mut dirs: HashMap<(u64, u64), Vec<f64>> = HashMap::new();
    for (a, b) in lines {
        let (pa, pb) = (m.vertices[a as usize], m.vertices[b as usize]);
        if pa == pb {
            continue;
        }
        let d = pb - pa;
        dirs.entry(key(pa)).or_default().push(d.y.atan2(d.x));
        dirs.entry(key(pb)).or_default().push((-d.y).atan2(-d.x));
    }
    dirs
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::discontinuity::Kind;
    use crate::mesh::Constraint;

    fn mesh(vertices: &[(f64, f64)], triangles: &[[u32; 3]]) -> ReceiverMesh {
        ReceiverMesh {
            polygon: 0,
            vertices: vertices.iter().map(|&(x, y)| DVec2::new(x, y)).collect(),
            triangles: triangles.to_vec(),
            constraints: Vec::new(),
        }
    }

    /// A right triangle is fine; a sliver's small angle at the outline's 90-degree corner is
    /// not forced; inside a 10-degree corner of the outline it is; an element over the cap
    /// is counted whatever its shape.
    #[test]
    fn small_angles_are_forced_only_inside_narrow_corners() {
        let right = mesh(&[(0.0, 0.0), (1.0, 0.0), (0.0, 1.0)], &[[0, 1, 2]]);
        assert_eq!(small_angles(&right), vec![SmallAngle::None]);
        // A 4 x 0.5 rectangle in two triangles: each has a 7-degree angle at a right-angled
        // corner of the outline.
        let board = mesh(
            &[(0.0, 0.0), (4.0, 0.0), (4.0, 0.5), (0.0, 0.5)],
            &[[0, 1, 2], [0, 2, 3]],
        );
        let q = measure(&[board], 1.0);
        assert_eq!((q.sharp, q.forced, q.over_cap), (2, 0, 0), "{q:?}");
        assert!((q.sharpest - 0.5f64.atan2(4.0).to_degrees()).abs() < 1e-9);
        // A 10-degree wedge of the outline: the element at the apex keeps the outline's angle
        // (forced).
        let t = 10f64.to_radians();
        let (c, s) = (t.cos(), t.sin());
        let wedge = mesh(
            &[(0.0, 0.0), (1.0, 0.0), (c, s), (2.0, 0.0), (2.0 * c, 2.0 * s)],
            &[[0, 1, 2], [1, 3, 4], [1, 4, 2]],
        );
        let angles = small_angles(&wedge);
        assert_eq!(angles[0], SmallAngle::Forced);
        // The element beyond it, between the same two sides, has 20 degrees where the outline
        // runs straight: the measure excuses the corner's own elements only.
        assert!(matches!(angles[1], SmallAngle::Sharp(a) if a > 19.0 && a < 21.0));
        // A 10-degree element in a right-angled corner of the outline is not forced; with a
        // constraint along its side, the constraints meet at 10 degrees and it is.
        let mut corner = mesh(
            &[(0.0, 0.0), (1.0, 0.0), (c, s), (0.0, 1.0)],
            &[[0, 1, 2], [0, 2, 3]],
        );
        assert!(matches!(small_angles(&corner)[0], SmallAngle::Sharp(a) if (a - 10.0).abs() < 1e-9));
        assert_eq!(small_angles(&corner)[1], SmallAngle::None);
        corner.constraints.push(Constraint {
            a: 0,
            b: 2,
            kind: Kind::D0,
            event: 0,
        });
        assert_eq!(small_angles(&corner)[0], SmallAngle::Forced);
        // Over the cap, by area alone.
        let q = measure(&[right], 0.4);
        assert_eq!(q.over_cap, 1);
        assert!((q.largest - 1.25).abs() < 1e-12);
    }
}
