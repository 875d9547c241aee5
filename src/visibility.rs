//! Ray queries against the whole scene: one obvhs BVH2 over every static, non-degenerate
//! triangle.
//!
//! Triangles are stored in f32 relative to the scene's centre, so precision does not depend on
//! where the scene sits. The binary BVH2 is used rather than obvhs's 8-wide CWBVH, which misses
//! hits very close to the ray origin (measured in `benches/stages.rs`). Offsets scale with the scene's extent.
//!
//! For benchmarks only, [`record_rays`] makes every ray query remember the ray as the BVH sees
//! it, so that a bake's rays can be replayed against other traversal loops
//! ([`take_recorded_rays`]); it is off unless switched on, and never changes an answer.

use crate::scene::Scene;
use crate::scene::surface::{Cutout, Pane};
use crate::scene::texture::Image;
use glam::{DVec3, Vec3, Vec3A};
use obvhs::{BvhBuildParams, aabb::Aabb, bvh2::Bvh2, ray::Ray, ray::RayHit, triangle::Triangle};
use std::sync::Arc;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

/// How the BVH is built: obvhs's medium build (PLOC) with full reinsertion (Meister, Bittner,
/// "Parallel reinsertion for bounding volume hierarchy optimization", 2018): over every node
/// instead of 5% of them (and, after the leaves are collapsed, at twice that ratio, as the
/// medium build does), and PLOC's wider pairing search kept down to depth 1 instead of 3, as
/// obvhs's slowest preset does. Measured on a bake's recorded rays (about 2 M per scene, replayed one
/// after the other on one thread): 0.5x the medium build's traversal time on interior-20, 0.85x
/// on box-grid-40 and town-100k, for 0.06 s more build time on 20 000 triangles (0.25 s on
/// 100 000), once per bake.
///
/// Either tree's f32 ray-box tests miss a few grazing hits that the triangle test alone finds
/// (rays along axis-aligned walls meet boxes of zero thickness): on box-grid-40, of 1.77 M
/// rays, the two trees answer 172 differently, and brute force over every triangle sides with
/// this tree in 139 of them.
pub const BVH_BUILD: BvhBuildParams = {
    let mut p = BvhBuildParams::medium_build();
    p.reinsertion_batch_ratio = 1.0;
    p.search_depth_threshold = 1;
    p
};

/// A BVH over the scene's triangles.
pub struct Visibility {
    bvh: Bvh2,
    /// Triangles in BVH primitive order, relative to `center`.
    tris: Vec<Triangle>,
    /// Scene triangle index of each BVH primitive.
    ids: Vec<usize>,
    /// Polygon index of each BVH primitive.
    polygons: Vec<u32>,
    /// Per BVH primitive, its index in `cutouts` (alpha-tested triangles), or `u32::MAX`.
    cut: Vec<u32>,
    cutouts: Vec<Cutout>,
    /// Per BVH primitive, its index in `panes` (see-through triangles), or `u32::MAX`.
    pane: Vec<u32>,
    panes: Vec<Pane>,
    /// The images the cut-outs read.
    images: Arc<Vec<Image>>,
    center: DVec3,
    eps: f64,
}

/// Hits within this many [`Visibility::epsilon`] of each other are a tie, which the face
/// facing the ray wins (see [`Visibility::first_hit`]). Coincident triangles are met at
/// distances that differ by the f32 rounding of the intersection, about 1e-7 of the scene's
/// extent; epsilon is [`crate::scene::tolerance::RAY`] = 1e-5 of it, so the window is 1e-6 of
/// the extent.
pub(crate) const TIE: f64 = 0.1;

/// Slanted rays of [`Visibility::buried`], besides the one along the normal.
pub(crate) const BURIED_RAYS: usize = 8;

/// A ray's closest intersection.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Distance along the (unit) ray direction, scene units.
    pub t: f64,
    /// Index into [`Scene::triangles`].
    pub(crate) triangle: usize,
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
                BVH_BUILD,
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
        let mut cutouts = Vec::new();
        let cut = ids
            .iter()
            .map(|&i| match scene.cutout_of(i) {
                Some(c) => {
                    cutouts.push(c);
                    (cutouts.len() - 1) as u32
                }
                None => u32::MAX,
            })
            .collect();
        let mut panes = Vec::new();
        let pane = ids
            .iter()
            .map(|&i| match scene.pane_of(i) {
                Some(p) => {
                    panes.push(p);
                    (panes.len() - 1) as u32
                }
                None => u32::MAX,
            })
            .collect();
        Visibility {
            bvh,
            tris,
            ids,
            polygons,
            cut,
            cutouts,
            pane,
            panes,
            images: scene.images.clone(),
            center,
            eps: crate::scene::tolerance::RAY * scene.extent(),
        }
    }

    /// The distance used to keep rays off the surfaces they start and end on (scene units):
    /// [`crate::scene::tolerance::RAY`] of the scene's bounding-box diagonal.
    pub fn epsilon(&self) -> f64 {
        self.eps
    }

    /// The point that BVH coordinates are relative to (the centre of the scene's bounding
    /// box): a [`RecordedRay`]'s origin is `p_world - center`, in f32.
    pub fn center(&self) -> DVec3 {
        self.center
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
    /// Of two hits within [`TIE`] x epsilon of each other, a face facing the ray wins over one
    /// showing its back (the two sides of a double-sided surface), deterministically.
    pub fn first_hit(&self, origin: DVec3, dir: DVec3, tmax: f64) -> Option<Hit> {
        self.closest(origin, dir, tmax).map(|(t, k)| Hit {
            t,
            triangle: self.ids[k],
        })
    }

    /// [`Visibility::first_hit`] as (distance, BVH primitive).
    ///
    /// Ties go to the face that faces the ray: when the closest hit shows the ray its back and
    /// a triangle facing the ray lies within [`TIE`] x epsilon of it, that one is the hit. The
    /// two sides of a double-sided surface are coincident triangles of opposite winding, met at
    /// the same distance up to rounding; the ray must meet the side it sees (its light, its
    /// reflectance), not the back of the other, which neither emits nor reflects.
    fn closest(&self, origin: DVec3, dir: DVec3, tmax: f64) -> Option<(f64, usize)> {
        if self.tris.is_empty() {
            return None;
        }
        let ray = self.ray(origin, dir, self.eps, tmax);
        let mut hit = RayHit::none();
        let found = self
            .bvh
            .ray_traverse(ray, &mut hit, |r, id| self.intersect(r, id));
        if RECORDING.load(Ordering::Relaxed) {
            record(&ray, Query::FirstHit, [u32::MAX; 2], found);
        }
        if !found {
            return None;
        }
        let (t, k) = (hit.t as f64, hit.primitive_id as usize);
        let d = Vec3A::from(dir.as_vec3());
        if !self.shows_back(k, d) {
            return Some((t, k));
        }
        // A back face: is there a front face at the same distance?
        let tol = TIE * self.eps;
        let near = self.ray(origin, dir, (t - tol).max(self.eps), (t + tol).min(tmax));
        let mut front = RayHit::none();
        let found = self.bvh.ray_traverse(near, &mut front, |r, id| {
            if self.shows_back(id, d) {
                f32::INFINITY
            } else {
                self.intersect(r, id)
            }
        });
        Some(if found {
            (front.t as f64, front.primitive_id as usize)
        } else {
            (t, k)
        })
    }

    /// Where ray `r` meets BVH primitive `id` (infinity: it does not), the holes of an
    /// alpha-tested triangle let through (the any-hit test of ray tracers).
    fn intersect(&self, r: &Ray, id: usize) -> f32 {
        let t = self.tris[id].intersect(r);
        let c = self.cut[id];
        if c == u32::MAX || !t.is_finite() {
            return t;
        }
        let bary = self.barycentric(r, id, t);
        if self.cutouts[c as usize].hole(&self.images, bary) {
            f32::INFINITY
        } else {
            t
        }
    }

    /// True when BVH primitive `k`'s front normal points along `dir` (the ray meets its back).
    fn shows_back(&self, k: usize, dir: Vec3A) -> bool {
        let t = &self.tris[k];
        (t.v1 - t.v0).cross(t.v2 - t.v0).dot(dir) > 0.0
    }

    /// True when the first surface the ray from `origin` along unit `dir` meets shows it its
    /// back (the triangle's front normal points along `dir`).
    fn meets_back_face(&self, origin: DVec3, dir: DVec3) -> bool {
        self.closest(origin, dir, f64::from(f32::MAX))
            .is_some_and(|(_, k)| self.shows_back(k, Vec3A::from(dir.as_vec3())))
    }

    /// True when the surface point `p`, on a surface with front normal `n` (unit), is buried
    /// under other geometry: the floor under a box standing on it, a wall's foot inside the
    /// box that crosses it, the ceiling behind a light fitted against it. Such points are never
    /// seen, and their light (dark, or leaking) must not reach the lightmap.
    ///
    /// The test is the back-face test of lightmappers (Unity's "backface tolerance"):
    /// from `p`, lifted off its surface by [`Visibility::epsilon`], a ray along `n` and
    /// [`BURIED_RAYS`] rays at 60 degrees from it, evenly around `n`; the point is buried when
    /// the ray along `n` and most of all the rays (more than half) meet a back face first. One
    /// ray settles most points (it escapes, or meets a front face), and the slanted rays stop
    /// once their count decides (a buried point takes 5 rays, not 9). The point under a thin,
    /// one-sided overhang (a table top seen from below) is not buried: its slanted rays pass
    /// the overhang's edge. The rays are turned off the axes by odd angles (the first one by
    /// 1.5 degrees), so that in axis-aligned scenes they do not run exactly along an edge
    /// between two triangles, where a hit can slip through.
    pub fn buried(&self, p: DVec3, n: DVec3) -> bool {
        let origin = p + n * self.eps;
        let (a, b) = n.any_orthonormal_pair();
        let ray = |theta: f64, phi: f64| {
            let (sin, cos) = theta.to_radians().sin_cos();
            n * cos + (a * phi.cos() + b * phi.sin()) * sin
        };
        if !self.meets_back_face(origin, ray(1.5, 0.7)) {
            return false;
        }
        // Buried when more than half of all `BURIED_RAYS + 1` rays meet a back face: stop as
        // soon as the count decides it either way (same answer as casting them all).
        let need = BURIED_RAYS.div_ceil(2) + 1;
        let mut backs = 1;
        for k in 0..BURIED_RAYS {
            if backs >= need || backs + (BURIED_RAYS - k) < need {
                break;
            }
            let phi = std::f64::consts::TAU * (k as f64 + 0.382) / BURIED_RAYS as f64;
            backs += usize::from(self.meets_back_face(origin, ray(60.0, phi)));
        }
        backs >= need
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
        self.blocked(a, d / len, len - self.eps, skip, Query::Segment)
    }

    /// True when nothing blocks the ray from `a` in unit direction `dir` (to infinity);
    /// triangles of polygon `skip` never block (see [`Visibility::occluded_skipping`]).
    pub fn unoccluded_towards(&self, a: DVec3, dir: DVec3, skip: usize) -> bool {
        !self.blocked(
            a,
            dir,
            f64::from(f32::MAX),
            [skip, usize::MAX],
            Query::Towards,
        )
    }

    /// Any hit along `origin + t dir` for `t` in `(epsilon, tmax)`, skipping two polygons.
    /// `query`: which public query asks (for the benchmark recorder).
    fn blocked(
        &self,
        origin: DVec3,
        dir: DVec3,
        tmax: f64,
        skip: [usize; 2],
        query: Query,
    ) -> bool {
        if self.tris.is_empty() {
            return false;
        }
        let ray = self.ray(origin, dir, self.eps, tmax);
        let skip = skip.map(|s| s as u32);
        let polys = &self.polygons;
        let blocked = !self.bvh.ray_traverse_miss(ray, |r, id| {
            if polys[id] == skip[0] || polys[id] == skip[1] {
                f32::INFINITY
            } else {
                self.intersect(r, id)
            }
        });
        if RECORDING.load(Ordering::Relaxed) {
            record(&ray, query, skip, blocked);
        }
        blocked
    }

    /// The fraction of light (per linear RGB channel) that reaches `b` from `a` ([`Visibility::
    /// occluded_skipping`]'s segment, triangles of the polygons in `skip` left out): 0 where an
    /// opaque surface blocks it, else the product of the see-through surfaces' transmittances
    /// along it (`BLEND`, transmission; coincident panes count once). Without
    /// see-through surfaces in the scene, 1 or 0 exactly as `occluded_skipping` says.
    pub fn transmitted_skipping(&self, a: DVec3, b: DVec3, skip: [usize; 2]) -> DVec3 {
        let d = b - a;
        let len = d.length();
        if len <= 2.0 * self.eps {
            return DVec3::ONE;
        }
        self.transmitted(a, d / len, len - self.eps, skip, Query::Segment)
    }

    /// [`Visibility::transmitted_skipping`] along the ray from `a` in unit direction `dir` to
    /// infinity, polygon `skip` left out ([`Visibility::unoccluded_towards`]).
    pub(crate) fn transmitted_towards(&self, a: DVec3, dir: DVec3, skip: usize) -> DVec3 {
        self.transmitted(
            a,
            dir,
            f64::from(f32::MAX),
            [skip, usize::MAX],
            Query::Towards,
        )
    }

    fn transmitted(
        &self,
        origin: DVec3,
        dir: DVec3,
        tmax: f64,
        skip: [usize; 2],
        query: Query,
    ) -> DVec3 {
        if self.panes.is_empty() {
            return if self.blocked(origin, dir, tmax, skip, query) {
                DVec3::ZERO
            } else {
                DVec3::ONE
            };
        }
        if self.tris.is_empty() {
            return DVec3::ONE;
        }
        let ray = self.ray(origin, dir, self.eps, tmax);
        let skip = skip.map(|s| s as u32);
        let mut through = DVec3::ONE;
        // The distances of the panes counted: panes met at one distance are one pane (the two
        // sides of a double-sided one, its back written as a primitive of its own, the two
        // triangles at an edge the ray passes through).
        let mut counted: Vec<f32> = Vec::new();
        let tie = (TIE * self.eps) as f32;
        let blocked = !self.bvh.ray_traverse_miss(ray, |r, id| {
            if self.polygons[id] == skip[0] || self.polygons[id] == skip[1] {
                return f32::INFINITY;
            }
            let t = self.intersect(r, id);
            let k = self.pane[id];
            if k == u32::MAX || !t.is_finite() {
                return t;
            }
            // A see-through triangle: the ray goes on, dimmed once per pane.
            if !counted.iter().any(|&s| (s - t).abs() <= tie) {
                counted.push(t);
                let bary = self.barycentric(r, id, t);
                through *= self.panes[k as usize].transmittance(&self.images, bary);
            }
            f32::INFINITY
        });
        if RECORDING.load(Ordering::Relaxed) {
            record(&ray, query, skip, blocked);
        }
        if blocked { DVec3::ZERO } else { through }
    }

    /// Barycentric coordinates on BVH primitive `id` of the point at `t` along ray `r`.
    fn barycentric(&self, r: &Ray, id: usize, t: f32) -> [f64; 3] {
        let tri = &self.tris[id];
        let p = (r.origin + r.direction * t).as_dvec3();
        let corners = [tri.v0, tri.v1, tri.v2].map(|q| q.as_dvec3());
        crate::geometry::barycentric_3d(&corners, p)
    }

    /// Appends to `out` the scene triangles whose bounding boxes overlap the box `[min, max]`
    /// grown by `epsilon` (so f32 storage never loses one), then sorts `out` and removes
    /// duplicates. Conservative: every triangle that meets the box is listed, and some that do
    /// not.
    pub(crate) fn triangles_overlapping(&self, min: DVec3, max: DVec3, out: &mut Vec<usize>) {
        if RECORDING.load(Ordering::Relaxed) {
            COUNTS[Query::Box as usize].fetch_add(1, Ordering::Relaxed);
        }
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
    #[cfg(test)]
    pub(crate) fn triangles_overlapping_brute_force(&self, min: DVec3, max: DVec3) -> Vec<usize> {
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
    #[cfg(test)]
    pub(crate) fn first_hit_brute_force(
        &self,
        origin: DVec3,
        dir: DVec3,
        tmax: f64,
    ) -> Option<Hit> {
        let ray = self.ray(origin, dir, self.eps, tmax);
        let d = Vec3A::from(dir.as_vec3());
        let mut best: Option<(f64, usize)> = None;
        for (k, t) in self.tris.iter().enumerate() {
            let x = t.intersect(&ray);
            if x >= ray.tmin && x < ray.tmax && best.is_none_or(|b| (x as f64) < b.0) {
                best = Some((x as f64, k));
            }
        }
        let (t, k) = best?;
        // The tie-break of `closest`: the nearest face facing the ray within the window.
        let tol = TIE * self.eps;
        let mut front: Option<(f64, usize)> = None;
        if self.shows_back(k, d) {
            for (j, tri) in self.tris.iter().enumerate() {
                let x = tri.intersect(&ray) as f64;
                if !self.shows_back(j, d)
                    && (t - tol..=t + tol).contains(&x)
                    && front.is_none_or(|f| x < f.0)
                {
                    front = Some((x, j));
                }
            }
        }
        let (t, k) = front.unwrap_or((t, k));
        Some(Hit {
            t,
            triangle: self.ids[k],
        })
    }
}

// The ray recorder (benchmarks only).

/// Which [`Visibility`] query cast a ray.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Query {
    /// [`Visibility::first_hit`]: closest hit (`Bvh2::ray_traverse`).
    FirstHit,
    /// [`Visibility::occluded`] and [`Visibility::occluded_skipping`]: any hit on a segment
    /// (`Bvh2::ray_traverse_miss`).
    Segment,
    /// [`Visibility::unoccluded_towards`]: any hit on a ray to infinity
    /// (`Bvh2::ray_traverse_miss` with `tmax = f32::MAX`).
    Towards,
    /// [`Visibility::triangles_overlapping`]: a box query, counted but not recorded.
    Box,
}

impl Query {
    /// True for the closest-hit query; the others stop at any hit.
    pub fn closest_hit(self) -> bool {
        self == Query::FirstHit
    }
}

/// One ray query as the BVH saw it: in f32, relative to [`Visibility::center`], direction of
/// unit length, hits counted for `t` in `(tmin, tmax)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RecordedRay {
    pub origin: Vec3,
    pub dir: Vec3,
    pub tmin: f32,
    pub tmax: f32,
    /// Polygons whose triangles never block (`u32::MAX`: none). Always none for
    /// [`Query::FirstHit`].
    pub skip: [u32; 2],
    pub query: Query,
    /// The answer the query gave: a hit (closest-hit) or blocked (any-hit).
    pub hit: bool,
}

/// Rays cast per query kind since recording was switched on (every ray, including those past
/// the recorder's cap).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RayCounts {
    /// Indexed by [`Query`] (`q as usize`).
    pub(crate) by_query: [u64; 4],
}

impl RayCounts {
    /// Rays of every kind (box queries left out).
    pub fn rays(&self) -> u64 {
        self.by_query[..3].iter().sum()
    }

    /// The rays of one kind.
    pub fn of(&self, q: Query) -> u64 {
        self.by_query[q as usize]
    }

    /// Counts since `earlier`.
    pub fn since(&self, earlier: &RayCounts) -> RayCounts {
        RayCounts {
            by_query: std::array::from_fn(|i| self.by_query[i] - earlier.by_query[i]),
        }
    }
}

/// Checked by every query: is the recorder on?
static RECORDING: AtomicBool = AtomicBool::new(false);
static COUNTS: [AtomicU64; 4] = [const { AtomicU64::new(0) }; 4];
static RECORDER: Mutex<Recorder> = Mutex::new(Recorder {
    rays: Vec::new(),
    cap: 0,
    stride: 1,
    seen: 0,
});

/// The recorded sample: every `stride`-th ray, in arrival order.
struct Recorder {
    rays: Vec<RecordedRay>,
    cap: usize,
    stride: u64,
    seen: u64,
}

impl Recorder {
    fn new(cap: usize) -> Recorder {
        Recorder {
            rays: Vec::with_capacity(cap.min(1 << 24)),
            cap: cap.max(2),
            stride: 1,
            seen: 0,
        }
    }

    /// Keeps `ray` if it falls on the stride; when full, drops every other kept ray and
    /// doubles the stride.
    fn offer(&mut self, ray: RecordedRay) {
        self.seen += 1;
        if !self.seen.is_multiple_of(self.stride) {
            return;
        }
        self.rays.push(ray);
        if self.rays.len() >= self.cap {
            let mut k = 0u64;
            self.rays.retain(|_| {
                k += 1;
                k.is_multiple_of(2)
            });
            self.stride *= 2;
        }
    }
}

/// **Benchmarks only.** Switches the ray recorder on, process-wide, and clears it: from now on
/// every ray query of every [`Visibility`] is counted by kind ([`recorded_counts`]) and kept
/// as a [`RecordedRay`], up to `cap` of them. When the buffer fills, every other kept ray is
/// dropped and from then on only every second (fourth, ...) ray is kept, so the sample stays
/// spread evenly over the whole run, in order. Answers never change; queries slow down (one
/// lock per ray) while it is on. With several threads the order of the rays, and so the
/// sample, is not deterministic.
pub fn record_rays(cap: usize) {
    *RECORDER.lock().unwrap_or_else(|e| e.into_inner()) = Recorder::new(cap);
    for c in &COUNTS {
        c.store(0, Ordering::Relaxed);
    }
    RECORDING.store(true, Ordering::SeqCst);
}

/// **Benchmarks only.** The rays cast per query kind since [`record_rays`], while recording is
/// on or after [`take_recorded_rays`].
pub fn recorded_counts() -> RayCounts {
    RayCounts {
        by_query: std::array::from_fn(|i| COUNTS[i].load(Ordering::Relaxed)),
    }
}

/// **Benchmarks only.** Switches the recorder off and returns the recorded rays with the
/// counts of every ray cast since [`record_rays`].
pub fn take_recorded_rays() -> (Vec<RecordedRay>, RayCounts) {
    RECORDING.store(false, Ordering::SeqCst);
    let mut r = RECORDER.lock().unwrap_or_else(|e| e.into_inner());
    (std::mem::take(&mut r.rays), recorded_counts())
}

/// Counts one ray and keeps it if it falls on the sample's stride.
#[cold]
#[inline(never)]
fn record(ray: &Ray, query: Query, skip: [u32; 2], hit: bool) {
    COUNTS[query as usize].fetch_add(1, Ordering::Relaxed);
    RECORDER
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .offer(RecordedRay {
            origin: ray.origin.into(),
            dir: ray.direction.into(),
            tmin: ray.tmin,
            tmax: ray.tmax,
            skip,
            query,
            hit,
        });
}

/// The mean over the channels of a transmittance ([`Visibility::transmitted_skipping`]):
/// exactly the value when the channels agree (1 or 0 without glass), so that scenes without
/// glass keep their arithmetic.
pub(crate) fn channel_mean(t: DVec3) -> f64 {
    if t.x == t.y && t.y == t.z {
        t.x
    } else {
        t.element_sum() / 3.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Instance, Material};

    use crate::rng::SplitMix64;

    /// A point uniform in the cube `[lo, hi)³`.
    trait RandomVec {
        fn vec(&mut self, lo: f64, hi: f64) -> DVec3;
    }

    impl RandomVec for SplitMix64 {
        fn vec(&mut self, lo: f64, hi: f64) -> DVec3 {
            DVec3::new(self.range(lo, hi), self.range(lo, hi), self.range(lo, hi))
        }
    }

    fn random_scene(rng: &mut SplitMix64, n: usize, offset: DVec3) -> Scene {
        let mut scene = Scene::default();
        scene.materials.push(Material {
            name: "m".into(),
            rho: DVec3::splat(0.5),
            radiance: DVec3::ZERO,
            base: None,
        });
        for _ in 0..n {
            let c = rng.vec(-5.0, 5.0) + offset;
            let p = vec![c, c + rng.vec(-1.0, 1.0), c + rng.vec(-1.0, 1.0)];
            scene.add_instance(Instance::new(p, vec![0, 1, 2]), 0);
        }
        scene
    }

    #[test]
    fn bvh_agrees_with_brute_force_on_random_rays() {
        for offset in [DVec3::ZERO, DVec3::new(1e4, -3e4, 2e4)] {
            let mut rng = SplitMix64(7);
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
        let mut rng = SplitMix64(3);
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
    fn recording_keeps_answers_and_the_rays_as_cast() {
        let mut rng = SplitMix64(11);
        let offset = DVec3::new(300.0, 20.0, -40.0);
        let scene = random_scene(&mut rng, 200, offset);
        let vis = Visibility::new(&scene);
        let queries: Vec<(DVec3, DVec3)> = (0..500)
            .map(|_| (rng.vec(-7.0, 7.0) + offset, rng.vec(-7.0, 7.0) + offset))
            .collect();
        // Polygons that do not exist tag this test's segment rays: the recorder is
        // process-wide and other tests may cast rays meanwhile.
        const TAG: [usize; 2] = [123_456_789, 987_654_321];
        let answer = |(a, b): &(DVec3, DVec3)| {
            let d = (*b - *a).normalize();
            let blocked = vis.occluded_skipping(*a, *b, TAG);
            (blocked, vis.first_hit(*a, d, 5.0).is_some())
        };
        let off: Vec<_> = queries.iter().map(answer).collect();
        let cap = 1 << 20;
        record_rays(cap);
        let on: Vec<_> = queries.iter().map(answer).collect();
        let (rays, counts) = take_recorded_rays();
        assert_eq!(on, off, "recording changed an answer");
        assert!(counts.of(Query::Segment) >= 500 && counts.of(Query::FirstHit) >= 500);
        let mine: Vec<&RecordedRay> = rays
            .iter()
            .filter(|r| r.skip == TAG.map(|t| t as u32))
            .collect();
        if (counts.rays() as usize) < cap {
            assert_eq!(mine.len(), 500);
        }
        assert!(!mine.is_empty());
        for r in mine {
            assert_eq!(r.query, Query::Segment);
            assert!((r.dir.length() - 1.0).abs() < 1e-6 && r.tmin == vis.epsilon() as f32);
            // The same ray through the API, from world coordinates, gives the same answer.
            let o = vis.center() + r.origin.as_dvec3();
            let b = o + r.dir.as_dvec3() * (r.tmax as f64 + vis.epsilon());
            assert_eq!(vis.occluded_skipping(o, b, TAG), r.hit, "{r:?}");
        }
        // Off again: nothing more is counted.
        queries.iter().for_each(|q| {
            answer(q);
        });
        assert_eq!(recorded_counts(), counts);
    }

    #[test]
    fn a_full_recorder_keeps_an_even_sample() {
        let ray = |i: usize| RecordedRay {
            origin: Vec3::splat(i as f32),
            dir: Vec3::X,
            tmin: 0.0,
            tmax: 1.0,
            skip: [u32::MAX; 2],
            query: Query::Segment,
            hit: false,
        };
        let mut r = Recorder::new(8);
        for i in 1..=100 {
            r.offer(ray(i));
        }
        // Full at 8 (keeps 2, 4, 6, 8; stride 2), at 16 (4, 8, 12, 16; stride 4), at 32, at
        // 64 (16, 32, 48, 64; stride 16), then 80 and 96.
        let kept: Vec<f32> = r.rays.iter().map(|r| r.origin.x).collect();
        assert_eq!(kept, [16.0, 32.0, 48.0, 64.0, 80.0, 96.0]);
        assert_eq!(r.stride, 16);
    }

    /// A double-sided square: the same two triangles twice, the second copy's winding
    /// reversed (as the loader adds a back side), in either order.
    fn back_to_back(back_first: bool) -> Scene {
        let mut scene = Scene::default();
        scene.materials.push(Material {
            name: "m".into(),
            rho: DVec3::splat(0.5),
            radiance: DVec3::ZERO,
            base: None,
        });
        let front = Instance::new(
            vec![
                DVec3::new(-1.0, 0.3, -1.0),
                DVec3::new(-1.0, 0.3, 1.0),
                DVec3::new(1.0, 0.3, 1.0),
                DVec3::new(1.0, 0.3, -1.0),
            ],
            vec![0, 1, 2, 0, 2, 3],
        );
        let back = front.back_side();
        let (a, b) = if back_first {
            (back, front)
        } else {
            (front, back)
        };
        scene.add_instance(a, 0);
        scene.add_instance(b, 0);
        scene
    }

    #[test]
    fn of_two_coincident_sides_the_ray_meets_the_one_facing_it() {
        let mut rng = SplitMix64(5);
        for back_first in [false, true] {
            let scene = back_to_back(back_first);
            let vis = Visibility::new(&scene);
            let mut hits = 0;
            for _ in 0..2000 {
                // From above or below, at random slants, at the square's interior.
                let target =
                    DVec3::new(rng.next_f64() * 1.8 - 0.9, 0.3, rng.next_f64() * 1.8 - 0.9);
                let from = rng.vec(-3.0, 3.0);
                if (from.y - 0.3).abs() < 0.05 {
                    continue;
                }
                let dir = (target - from).normalize();
                for hit in [
                    vis.first_hit(from, dir, 100.0),
                    vis.first_hit_brute_force(from, dir, 100.0),
                ] {
                    let hit = hit.expect("the ray meets the square");
                    let n = scene.triangles[hit.triangle].normal;
                    assert!(n.dot(dir) < 0.0, "met the back: {from} -> {target}");
                    assert!((hit.t - (target - from).length()).abs() < 1e-5);
                    hits += 1;
                }
                // So a point on either side is not buried (its rays meet no back face).
                let up = DVec3::Y * (from.y - 0.3).signum();
                assert!(!vis.buried(target, up));
            }
            assert!(hits > 3000, "{hits}");
        }
    }

    #[test]
    fn near_origin_hits_are_found() {
        // A ray starting just above a plate must hit it when pointed at it: the CWBVH trap.
        let mut rng = SplitMix64(1);
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
