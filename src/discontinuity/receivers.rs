//! Where a wedge meets the receivers: a BVH over the polygons' boxes, a grid of a large
//! polygon's triangles, and the clipping of a segment or a wedge to a receiver polygon.

use super::wedges::{Light, Wedge, half_space};
use crate::geometry::{BoxGrid, GRID_TRIANGLES, grid_of_triangles};
use crate::scene::{LightKind, Scene};
use glam::{DVec3, Vec3A};
use obvhs::aabb::Aabb;
use rayon::prelude::*;

/// A BVH over polygon bounding boxes, for "which receivers can this reach" queries.
pub(super) struct PolygonIndex {
    bvh: obvhs::bvh2::Bvh2,
    boxes: Vec<Aabb>,
    center: DVec3,
    /// Per polygon of at least [`GRID_TRIANGLES`] triangles, a grid of them in its plane.
    grids: Vec<Option<BoxGrid>>,
}

impl PolygonIndex {
    pub(super) fn new(scene: &Scene) -> PolygonIndex {
        let center = (scene.bounds_min + scene.bounds_max) * 0.5;
        let pad = 1e-5 * scene.extent();
        let boxes: Vec<Aabb> = scene
            .polygons
            .iter()
            .map(|p| {
                let pts: Vec<Vec3A> = p
                    .triangles
                    .iter()
                    .flat_map(|&t| scene.triangles[t].p)
                    .map(|q| Vec3A::from((q - center).as_vec3()))
                    .collect();
                let b = Aabb::from_points(&pts);
                Aabb::new(b.min - pad as f32, b.max + pad as f32)
            })
            .collect();
        let bvh = if boxes.is_empty() {
            obvhs::bvh2::Bvh2::default()
        } else {
            obvhs::bvh2::builder::build_bvh2(
                &boxes,
                obvhs::BvhBuildParams::fast_build(),
                &mut std::time::Duration::default(),
            )
        };
        let grids = scene
            .polygons
            .par_iter()
            .map(|p| {
                (p.triangles_plane.len() >= GRID_TRIANGLES)
                    .then(|| grid_of_triangles(&p.triangles_plane))
                    .flatten()
            })
            .collect();
        PolygonIndex {
            bvh,
            boxes,
            center,
            grids,
        }
    }

    /// True when the plane through `origin` with unit `normal` meets polygon `r`'s (padded)
    /// bounding box: a wedge whose plane misses it cannot cross the polygon.
    pub(super) fn plane_meets(&self, r: usize, origin: DVec3, normal: DVec3) -> bool {
        let b = &self.boxes[r];
        let (lo, hi) = (b.min.as_dvec3(), b.max.as_dvec3());
        let (c, h) = ((lo + hi) * 0.5 + self.center, (hi - lo) * 0.5);
        normal.dot(c - origin).abs() <= normal.abs().dot(h)
    }

    /// Polygons whose boxes meet the box of `points`, sorted.
    pub(super) fn query(&self, points: &[DVec3]) -> Vec<usize> {
        let pts: Vec<Vec3A> = points
            .iter()
            .map(|q| Vec3A::from((*q - self.center).as_vec3()))
            .collect();
        let query = Aabb::from_points(&pts);
        let mut out = Vec::new();
        self.bvh.aabb_traverse(query, |bvh, node| {
            let n = &bvh.nodes[node as usize];
            for i in n.first_index..n.first_index + n.prim_count {
                let p = bvh.primitive_indices[i as usize] as usize;
                if self.boxes[p].intersect_aabb(&query) {
                    out.push(p);
                }
            }
            true
        });
        out.sort_unstable();
        out.dedup();
        out
    }
}

/// Clips the 3D segment `a-b` (in polygon `r`'s plane) to the polygon's triangles and to the
/// extra half-spaces; returns the pieces, merged where they touch.
pub(super) fn clip_segment_to_polygon(
    scene: &Scene,
    index: &PolygonIndex,
    r: usize,
    a: DVec3,
    b: DVec3,
    half_spaces: &[(DVec3, DVec3)],
    tol: f64,
) -> Vec<(DVec3, DVec3)> {
    let poly = &scene.polygons[r];
    let n = poly.frame.n;
    let u = b - a;
    let clip = |lo: &mut f64, hi: &mut f64, c: DVec3, m: DVec3| {
        // m·(a + t u - c) >= 0
        let base = m.dot(a - c);
        let slope = m.dot(u);
        if slope.abs() < 1e-300 {
            if base < 0.0 {
                *hi = -1.0;
            }
        } else {
            let t = -base / slope;
            if slope > 0.0 {
                *lo = lo.max(t);
            } else {
                *hi = hi.min(t);
            }
        }
    };
    let mut lo0 = 0.0;
    let mut hi0 = 1.0;
    for &(c, m) in half_spaces {
        clip(&mut lo0, &mut hi0, c, m);
    }
    if hi0 <= lo0 {
        return Vec::new();
    }
    let mut intervals = Vec::new();
    // The triangles the clipped segment can reach: all, or those its grid cells list (a
    // triangle farther than `tol` from the segment yields no interval either way).
    let near = index.grids[r].as_ref().map(|g| {
        let f = &poly.frame;
        let (p, q) = (
            f.plane_from_world(a + u * lo0),
            f.plane_from_world(a + u * hi0),
        );
        g.near_segment(p, q, tol)
    });
    let reached = near.as_ref().map_or(poly.triangles.len(), Vec::len);
    for i in 0..reached {
        let k = near.as_ref().map_or(i, |near| near[i] as usize);
        let p = scene.triangles[poly.triangles[k]].p;
        let (mut lo, mut hi) = (lo0, hi0);
        let centroid = (p[0] + p[1] + p[2]) / 3.0;
        for e in 0..3 {
            let (c, m) = half_space(p[e], n.cross(p[(e + 1) % 3] - p[e]), centroid);
            clip(&mut lo, &mut hi, c, m);
        }
        if hi > lo {
            intervals.push((lo, hi));
        }
    }
    // Pieces from neighbouring triangles meet (up to rounding) at shared edges: join them.
    let gap = tol / u.length().max(1e-300);
    intervals.sort_by(|x, y| x.0.total_cmp(&y.0));
    let mut merged: Vec<(f64, f64)> = Vec::new();
    for (lo, hi) in intervals {
        match merged.last_mut() {
            Some(last) if lo <= last.1 + gap => last.1 = last.1.max(hi),
            _ => merged.push((lo, hi)),
        }
    }
    let len = u.length();
    merged
        .into_iter()
        .filter(|(lo, hi)| (hi - lo) * len > tol)
        .map(|(lo, hi)| (a + u * lo, a + u * hi))
        .collect()
}

/// True when receiver `r` can be lit by the wedge's light at all (some of the light above its
/// plane, the receiver in front of the emitter).
pub(super) fn faces_light(scene: &Scene, r: usize, w: &Wedge) -> bool {
    let f = &scene.polygons[r].frame;
    match w.light {
        Light::Area(e) => {
            let ep = &scene.polygons[e];
            let above = ep
                .triangles
                .iter()
                .flat_map(|&t| scene.triangles[t].p)
                .any(|q| f.n.dot(q - f.origin) > 0.0);
            let front = scene.polygons[r]
                .triangles
                .iter()
                .flat_map(|&t| scene.triangles[t].p)
                .any(|q| ep.frame.n.dot(q - ep.frame.origin) > 0.0);
            above && front
        }
        Light::Punctual(l) => {
            let light = &scene.lights[l];
            match light.kind {
                LightKind::Directional => f.n.dot(-light.direction) > 0.0,
                _ => f.n.dot(light.position - f.origin) > 0.0,
            }
        }
    }
}

/// The wedge's intersection with receiver `r`, as 3D segments inside the polygon.
pub(super) fn clip_wedge_to_polygon(
    scene: &Scene,
    index: &PolygonIndex,
    r: usize,
    w: &Wedge,
    tol: f64,
) -> Vec<(DVec3, DVec3)> {
    let f = &scene.polygons[r].frame;
    // Line of the two planes.
    let dir = w.normal.cross(f.n);
    let l2 = dir.length_squared();
    if l2 < 1e-18 {
        return Vec::new();
    }
    let dw = w.normal.dot(w.origin);
    let dr = f.n.dot(f.origin);
    let point = (f.n.cross(dir) * dw + dir.cross(w.normal) * dr) / l2;
    let dir = dir / l2.sqrt();
    // A segment long enough to cover the polygon, clipped by the wedge and the polygon.
    let reach = scene.extent() * 4.0 + (point - f.origin).length();
    let a = point - dir * reach;
    let b = point + dir * reach;
    clip_segment_to_polygon(scene, index, r, a, b, &w.half_spaces, tol)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec2;

    /// The grid's segment query finds every triangle the segment crosses or passes within
    /// the margin of (checked by brute force on random triangles and segments, including
    /// segments that start or end outside the grid and axis-parallel ones).
    #[test]
    fn grid_of_triangles_finds_every_triangle_near_a_segment() {
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut rand = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let point = |r: &mut dyn FnMut() -> f64| DVec2::new(10.0 * r(), 10.0 * r());
        let triangles: Vec<[DVec2; 3]> = (0..400)
            .map(|_| {
                let c = point(&mut rand);
                let s = 0.05 + rand() * if rand() < 0.1 { 4.0 } else { 0.5 };
                [0, 1, 2].map(|_| c + DVec2::new(rand() - 0.5, rand() - 0.5) * s)
            })
            .collect();
        let grid = grid_of_triangles(&triangles).expect("a grid");
        let margin = 1e-6;
        for k in 0..300 {
            let (mut p, mut q) = (point(&mut rand) * 1.4 - 2.0, point(&mut rand) * 1.4 - 2.0);
            if k % 10 == 0 {
                q.x = p.x;
            } else if k % 10 == 1 {
                q.y = p.y;
            } else if k % 10 == 2 {
                (p, q) = (p, p);
            }
            let near = grid.near_segment(p, q, margin);
            assert!(near.windows(2).all(|w| w[0] < w[1]), "sorted, each once");
            for (t, tri) in triangles.iter().enumerate() {
                let crosses = (0..=400).any(|i| {
                    let x = p + (q - p) * (i as f64 / 400.0);
                    crate::scene::point_in_triangle(x, tri)
                });
                assert!(
                    !crosses || near.contains(&(t as u32)),
                    "segment {k} {p} -> {q} crosses triangle {t} {tri:?}, not found"
                );
            }
        }
    }
}
