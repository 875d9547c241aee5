//! Ray queries against the whole scene: one obvhs BVH2 over every static, non-degenerate
//! triangle.
//!
//! Triangles are stored in f32 relative to the scene's centre, so precision does not depend on
//! where the scene sits. The binary BVH2 is used rather than obvhs's 8-wide CWBVH, which misses
//! hits very close to the ray origin (see DESIGN). Offsets scale with the scene's extent.

use crate::scene::Scene;
use glam::{DVec3, Vec3A};
use obvhs::{BvhBuildParams, aabb::Aabb, bvh2::Bvh2, ray::Ray, ray::RayHit, triangle::Triangle};

/// A BVH over the scene's triangles.
pub struct Visibility {
    bvh: Bvh2,
    /// Triangles in BVH primitive order, relative to `center`.
    tris: Vec<Triangle>,
    /// Scene triangle index of each BVH primitive.
    ids: Vec<usize>,
    /// Polygon index of each BVH primitive.
    polygons: Vec<u32>,
    center: DVec3,
    eps: f64,
}

/// A ray's closest intersection.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Distance along the (unit) ray direction, scene units.
    pub t: f64,
    /// Index into [`Scene::triangles`].
    pub triangle: usize,
}

impl Visibility {
    /// Builds the BVH over every triangle that belongs to a polygon (degenerate ones are left out).
    pub fn new(scene: &Scene) -> Visibility {
        let center = if scene.triangles.is_empty() {
            DVec3::ZERO
        } else {
            (scene.bounds_min + scene.bounds_max) * 0.5
        };
        let to_f32 = |p: DVec3| Vec3A::from((p - center).as_vec3());
        let mut ids = Vec::new();
        let mut tris = Vec::new();
        for (i, t) in scene.triangles.iter().enumerate() {
            if t.polygon.is_some() {
                ids.push(i);
                tris.push(Triangle {
                    v0: to_f32(t.p[0]),
                    v1: to_f32(t.p[1]),
                    v2: to_f32(t.p[2]),
                });
            }
        }
        let bvh = if tris.is_empty() {
            Bvh2::default()
        } else {
            obvhs::bvh2::builder::build_bvh2_from_tris(
                &tris,
                BvhBuildParams::medium_build(),
                &mut std::time::Duration::default(),
            )
        };
        // Reorder primitives into BVH order so traversal indexes them directly.
        let (tris, ids) = if tris.is_empty() {
            (tris, ids)
        } else {
            bvh.primitive_indices
                .iter()
                .map(|&i| (tris[i as usize], ids[i as usize]))
                .unzip()
        };
        let polygons = ids
            .iter()
            .map(|&i| scene.triangles[i].polygon.map_or(u32::MAX, |p| p as u32))
            .collect();
        Visibility {
            bvh,
            tris,
            ids,
            polygons,
            center,
            eps: 1e-5 * scene.extent(),
        }
    }

    /// The distance used to keep rays off the surfaces they start and end on (scene units):
    /// 1e-5 of the scene's bounding-box diagonal.
    pub fn epsilon(&self) -> f64 {
        self.eps
    }

    fn ray(&self, origin: DVec3, dir: DVec3, tmin: f64, tmax: f64) -> Ray {
        Ray::new(
            Vec3A::from((origin - self.center).as_vec3()),
            Vec3A::from(dir.as_vec3()),
            tmin as f32,
            tmax as f32,
        )
    }

    /// The closest hit along `origin + t dir` for `t` in `(epsilon, tmax)`; `dir` must be unit.
    pub fn first_hit(&self, origin: DVec3, dir: DVec3, tmax: f64) -> Option<Hit> {
        if self.tris.is_empty() {
            return None;
        }
        let ray = self.ray(origin, dir, self.eps, tmax);
        let mut hit = RayHit::none();
        let tris = &self.tris;
        if self
            .bvh
            .ray_traverse(ray, &mut hit, |r, id| tris[id].intersect(r))
        {
            Some(Hit {
                t: hit.t as f64,
                triangle: self.ids[hit.primitive_id as usize],
            })
        } else {
            None
        }
    }

    /// True when any triangle blocks the open segment from `a` to `b`, ignoring `epsilon` at
    /// either end (callers offset `a` off its surface; `b` may lie on the emitter).
    pub fn occluded(&self, a: DVec3, b: DVec3) -> bool {
        self.occluded_skipping(a, b, [usize::MAX; 2])
    }

    /// Like [`Visibility::occluded`], but triangles of the polygons in `skip` never block. A
    /// planar polygon cannot block a ray that starts or ends on its front side, and skipping it
    /// removes the grazing-angle self-hits that f32 intersection produces near edges.
    pub fn occluded_skipping(&self, a: DVec3, b: DVec3, skip: [usize; 2]) -> bool {
        let d = b - a;
        let len = d.length();
        if len <= 2.0 * self.eps {
            return false;
        }
        self.blocked(a, d / len, len - self.eps, skip)
    }

    /// True when nothing blocks the ray from `a` in unit direction `dir` (to infinity);
    /// triangles of polygon `skip` never block (see [`Visibility::occluded_skipping`]).
    pub fn unoccluded_towards(&self, a: DVec3, dir: DVec3, skip: usize) -> bool {
        !self.blocked(a, dir, f64::from(f32::MAX), [skip, usize::MAX])
    }

    /// Any hit along `origin + t dir` for `t` in `(epsilon, tmax)`, skipping two polygons.
    fn blocked(&self, origin: DVec3, dir: DVec3, tmax: f64, skip: [usize; 2]) -> bool {
        if self.tris.is_empty() {
            return false;
        }
        let ray = self.ray(origin, dir, self.eps, tmax);
        let skip = skip.map(|s| s as u32);
        let (tris, polys) = (&self.tris, &self.polygons);
        !self.bvh.ray_traverse_miss(ray, |r, id| {
            if polys[id] == skip[0] || polys[id] == skip[1] {
                f32::INFINITY
            } else {
                tris[id].intersect(r)
            }
        })
    }

    /// Appends to `out` the scene triangles whose bounding boxes overlap the box `[min, max]`
    /// grown by `epsilon` (so f32 storage never loses one), then sorts `out` and removes
    /// duplicates. Conservative: every triangle that meets the box is listed, and some that do
    /// not.
    pub fn triangles_overlapping(&self, min: DVec3, max: DVec3, out: &mut Vec<usize>) {
        if !self.tris.is_empty() {
            let pad = DVec3::splat(self.eps);
            let query = Aabb::new(
                Vec3A::from((min - self.center - pad).as_vec3()),
                Vec3A::from((max - self.center + pad).as_vec3()),
            );
            let tris = &self.tris;
            let ids = &self.ids;
            self.bvh.aabb_traverse(query, |bvh, node| {
                let node = &bvh.nodes[node as usize];
                for k in node.first_index..node.first_index + node.prim_count {
                    let k = k as usize;
                    if query.intersect_aabb(&tris[k].aabb()) {
                        out.push(ids[k]);
                    }
                }
                true
            });
        }
        out.sort_unstable();
        out.dedup();
    }

    /// Brute force [`Visibility::triangles_overlapping`] (for tests).
    pub fn triangles_overlapping_brute_force(&self, min: DVec3, max: DVec3) -> Vec<usize> {
        let pad = DVec3::splat(self.eps);
        let query = Aabb::new(
            Vec3A::from((min - self.center - pad).as_vec3()),
            Vec3A::from((max - self.center + pad).as_vec3()),
        );
        let mut out: Vec<usize> = self
            .tris
            .iter()
            .zip(&self.ids)
            .filter(|(t, _)| query.intersect_aabb(&t.aabb()))
            .map(|(_, &i)| i)
            .collect();
        out.sort_unstable();
        out
    }

    /// Brute force closest hit over all triangles (for tests).
    pub fn first_hit_brute_force(&self, origin: DVec3, dir: DVec3, tmax: f64) -> Option<Hit> {
        let ray = self.ray(origin, dir, self.eps, tmax);
        let mut best: Option<Hit> = None;
        for (k, t) in self.tris.iter().enumerate() {
            let d = t.intersect(&ray);
            if d >= ray.tmin && d < ray.tmax && best.is_none_or(|b| (d as f64) < b.t) {
                best = Some(Hit {
                    t: d as f64,
                    triangle: self.ids[k],
                });
            }
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Instance, Material};

    /// A small deterministic generator (SplitMix64) for test inputs.
    pub(crate) struct SplitMix(pub u64);
    impl SplitMix {
        pub fn next_f64(&mut self) -> f64 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
        }
        pub fn vec(&mut self, lo: f64, hi: f64) -> DVec3 {
            DVec3::new(
                lo + (hi - lo) * self.next_f64(),
                lo + (hi - lo) * self.next_f64(),
                lo + (hi - lo) * self.next_f64(),
            )
        }
    }

    fn random_scene(rng: &mut SplitMix, n: usize, offset: DVec3) -> Scene {
        let mut scene = Scene::default();
        scene.materials.push(Material {
            name: "m".into(),
            rho: DVec3::splat(0.5),
            radiance: DVec3::ZERO,
        });
        for _ in 0..n {
            let c = rng.vec(-5.0, 5.0) + offset;
            let p = vec![c, c + rng.vec(-1.0, 1.0), c + rng.vec(-1.0, 1.0)];
            scene.add_instance(
                Instance {
                    node: 0,
                    mesh: 0,
                    primitive: 0,
                    gltf_material: None,
                    positions_world: p,
                    indices: vec![0, 1, 2],
                    mirrored: false,
                    first_triangle: 0,
                },
                0,
            );
        }
        scene
    }

    #[test]
    fn bvh_agrees_with_brute_force_on_random_rays() {
        for offset in [DVec3::ZERO, DVec3::new(1e4, -3e4, 2e4)] {
            let mut rng = SplitMix(7);
            let scene = random_scene(&mut rng, 300, offset);
            let vis = Visibility::new(&scene);
            let mut hits = 0;
            for _ in 0..3000 {
                let o = rng.vec(-7.0, 7.0) + offset;
                let d = (rng.vec(-1.0, 1.0)).normalize();
                let a = vis.first_hit(o, d, 100.0);
                let b = vis.first_hit_brute_force(o, d, 100.0);
                match (a, b) {
                    (Some(a), Some(b)) => {
                        hits += 1;
                        assert!((a.t - b.t).abs() < 1e-6 * (1.0 + a.t), "{a:?} vs {b:?}");
                    }
                    (None, None) => {}
                    other => panic!("bvh and brute force disagree: {other:?}"),
                }
                let end = o + d * 3.0;
                assert_eq!(
                    vis.occluded(o, end),
                    b.is_some_and(|h| h.t < 3.0 - vis.epsilon()),
                    "occlusion disagrees for {o} -> {end}"
                );
            }
            assert!(hits > 300, "too few hits to be a test: {hits}");
        }
    }

    #[test]
    fn box_query_agrees_with_brute_force() {
        let mut rng = SplitMix(3);
        let scene = random_scene(&mut rng, 400, DVec3::new(50.0, 0.0, -20.0));
        let vis = Visibility::new(&scene);
        let mut total = 0;
        for _ in 0..200 {
            let a = rng.vec(-7.0, 7.0) + DVec3::new(50.0, 0.0, -20.0);
            let b = a + rng.vec(0.0, 3.0);
            let mut got = Vec::new();
            vis.triangles_overlapping(a, b, &mut got);
            assert_eq!(got, vis.triangles_overlapping_brute_force(a, b));
            total += got.len();
        }
        assert!(total > 200, "too few hits to be a test: {total}");
    }

    #[test]
    fn near_origin_hits_are_found() {
        // A ray starting just above a plate must hit it when pointed at it: the CWBVH trap.
        let mut rng = SplitMix(1);
        let scene = random_scene(&mut rng, 50, DVec3::ZERO);
        let vis = Visibility::new(&scene);
        for t in &scene.triangles {
            if t.polygon.is_none() {
                continue;
            }
            let c = (t.p[0] + t.p[1] + t.p[2]) / 3.0;
            let o = c + t.normal * 20.0 * vis.epsilon();
            let h = vis
                .first_hit(o, -t.normal, 1.0)
                .expect("hit right below the origin");
            assert!((h.t - 20.0 * vis.epsilon()).abs() < 5.0 * vis.epsilon());
        }
    }
}
