//! Diffuse radiosity at the vertices of the receiver meshes.
//!
//! * **Direct light** at every vertex from every emitter. For area emitters, by default
//!   ([`DirectMethod::Exact`]) the exact point-to-polygon form factor of the part of the emitter
//!   that the vertex sees, by backprojection ([`crate::backproject`]); with
//!   [`DirectMethod::Sampled`] (and as the fallback past an occluder cap) the exact unoccluded
//!   form factor (Lambert's contour formula, clipped to the receiver's horizon) times a
//!   visibility fraction from a fixed stratified set of shadow rays. Punctual lights: the exact
//!   term with one shadow ray.
//! * **Indirect light** by progressive refinement (Cohen, Chen, Wallace, Greenberg, "A progressive
//!   refinement approach to fast radiosity image generation", SIGGRAPH 1988) over coarse patches,
//!   with ray-cast form factors (Wallace, Elmquist, Haines, "A ray tracing algorithm for
//!   progressive radiosity", SIGGRAPH 1989): the point-to-patch form factor evaluated at the
//!   receiver, exact for the unoccluded part and subdivided near the receiver. The converged
//!   patch radiosities are then gathered at every mesh vertex (a final gather), so the mesh
//!   vertices receive the indirect light without the patch resolution showing.
//!
//! Quantities: radiance `L` in W/(m² sr), irradiance `H` and radiosity `B` in W/m², per linear RGB
//! channel. `B = M + rho H`. Everything is deterministic: fixed sample patterns, and every
//! parallel loop writes its own output slot.

use crate::backproject::{EmitterShape, Limits, Occluders, Scratch, Shaft};
use crate::mesh::ReceiverMesh;
use crate::scene::{LightKind, PunctualLight, Scene};
use crate::visibility::Visibility;
use glam::{DVec2, DVec3};
use rayon::prelude::*;
use std::f64::consts::PI;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

/// How the direct light of area emitters is computed (`--direct`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum DirectMethod {
    /// The exact form factor of the visible part of each emitter, by backprojection: occluders
    /// projected through the point onto the emitter and subtracted from it.
    #[default]
    Exact,
    /// The exact unoccluded form factor times a visibility fraction from a fixed set of
    /// stratified shadow rays (`shadow_samples` per point and emitter).
    Sampled,
}

/// Options of the solve.
#[derive(Clone, Debug)]
pub struct SolveOptions {
    /// How area emitters light the vertices.
    pub direct: DirectMethod,
    /// Shadow rays per vertex and area emitter for the visibility fraction (sampled direct
    /// light, and the exact method's fallback).
    pub shadow_samples: usize,
    /// Exact direct light: when more than this many occluders project onto an emitter from one
    /// point, that emitter's light at that point is sampled instead (counted in
    /// [`DirectStats::fallbacks`]).
    pub occluder_cap: usize,
    /// Number of light bounces after the direct light (`Some(0)`: direct only); `None` iterates
    /// until the unshot power is below `tolerance` of the power first received.
    pub bounces: Option<u32>,
    /// Target number of patches for the indirect solve.
    pub patches: usize,
    /// Convergence tolerance on the unshot power, relative to the directly received power.
    pub tolerance: f64,
}

impl Default for SolveOptions {
    fn default() -> Self {
        SolveOptions {
            direct: DirectMethod::Exact,
            shadow_samples: 64,
            occluder_cap: Limits::default().max_occluders,
            bounces: None,
            patches: 1024,
            tolerance: 1e-3,
        }
    }
}

/// Irradiance at every mesh vertex plus counters.
#[derive(Clone, Debug, Default)]
pub struct Solution {
    /// `irradiance[m][v]`: irradiance H (W/m², linear RGB) at vertex `v` of mesh `m`, direct plus
    /// indirect, without the surface's own emission.
    pub irradiance: Vec<Vec<DVec3>>,
    /// Direct part of `irradiance`, same layout.
    pub direct: Vec<Vec<DVec3>>,
    pub stats: SolveStats,
}

/// Counters of a solve, reported in `--stats`.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct SolveStats {
    pub patches: usize,
    pub shots: usize,
    pub rays: u64,
    /// Unshot power left at the end, relative to the power first received.
    pub unshot_fraction: f64,
    /// Power emitted by area emitters, W (mean over RGB).
    pub emitted_power: f64,
    /// Power received directly by all patches, W (mean over RGB).
    pub direct_power: f64,
    /// Power absorbed by all patches, W (mean over RGB).
    pub absorbed_power: f64,
    /// The direct light at the mesh vertices.
    pub direct: DirectStats,
}

/// Counters of the direct light at the mesh vertices (`--stats`: `solve.direct`).
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct DirectStats {
    pub method: DirectMethod,
    /// Wall time of the direct light at the vertices, s.
    pub seconds: f64,
    /// (vertex, area emitter) pairs with the emitter above the vertex's horizon.
    pub evaluations: u64,
    /// Exact method: pairs that fell back to shadow rays (occluders over `occluder_cap`, or
    /// too many visible pieces).
    pub fallbacks: u64,
    pub occluder_cap: usize,
    /// Exact method: candidate occluders (convex pieces) left after the shaft culling, summed
    /// over pairs: what the per-point clipping looked at.
    pub candidates: u64,
    /// Exact method: occluders clipped and subtracted, summed over pairs, and the most at one
    /// pair.
    pub occluders: u64,
    pub occluders_max: u64,
    /// Exact method: the most convex pieces the visible part of an emitter was cut into.
    pub pieces_max: u64,
    /// Cost per area emitter.
    pub emitters: Vec<EmitterCost>,
}

/// What one area emitter cost in the direct light at the vertices.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct EmitterCost {
    /// Index into [`Scene::polygons`].
    pub polygon: usize,
    /// Triangles of the emitter polygon and the convex pieces they were merged into.
    pub triangles: usize,
    pub convex_pieces: usize,
    pub evaluations: u64,
    pub occluders: u64,
    pub fallbacks: u64,
    /// Time spent on this emitter, summed over threads, s.
    pub seconds: f64,
}

// ---------------------------------------------------------------------------------------------
// Form factors

/// Clips a polygon to the half-space `n·(x - p) >= 0` (Sutherland-Hodgman).
pub fn clip_to_horizon(poly: &[DVec3], p: DVec3, n: DVec3) -> Vec<DVec3> {
    let mut out = Vec::with_capacity(poly.len() + 2);
    for i in 0..poly.len() {
        let a = poly[i];
        let b = poly[(i + 1) % poly.len()];
        let da = n.dot(a - p);
        let db = n.dot(b - p);
        if da >= 0.0 {
            out.push(a);
        }
        if (da >= 0.0) != (db >= 0.0) {
            let t = da / (da - db);
            out.push(a + (b - a) * t);
        }
    }
    out
}

/// Form factor from a differential area at `p` with unit normal `n` to a planar polygon,
/// by Lambert's contour formula: `F = 1/(2 pi) sum_i gamma_i n·unit(r_i x r_(i+1))`, after clipping
/// the polygon to the horizon of `p`. Unoccluded; either winding. Dimensionless.
pub fn point_polygon_form_factor(p: DVec3, n: DVec3, poly: &[DVec3]) -> f64 {
    let clipped = clip_to_horizon(poly, p, n);
    if clipped.len() < 3 {
        return 0.0;
    }
    // A polygon in the tangent plane (coplanar with the receiver, up to rounding) subtends no
    // projected solid angle; its contour terms would only add rounding noise.
    let reach = clipped
        .iter()
        .map(|v| (*v - p).length())
        .fold(0.0, f64::max);
    let height = clipped.iter().map(|v| n.dot(*v - p)).fold(0.0, f64::max);
    if height <= 1e-9 * reach {
        return 0.0;
    }
    let mut sum = 0.0;
    for i in 0..clipped.len() {
        let a = clipped[i] - p;
        let b = clipped[(i + 1) % clipped.len()] - p;
        let c = a.cross(b);
        let cl = c.length();
        if cl <= 0.0 {
            continue;
        }
        // atan2 keeps the angle accurate for tiny and near-straight angles.
        let gamma = cl.atan2(a.dot(b));
        sum += gamma * n.dot(c) / cl;
    }
    (sum / (2.0 * PI)).abs()
}

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
    /// A point inside a surface: rays start `2 epsilon` along the normal.
    pub fn new(p: DVec3, n: DVec3, polygon: usize, vis: &Visibility) -> SurfacePoint {
        SurfacePoint {
            p,
            n,
            ray_origin: p + n * (2.0 * vis.epsilon()),
            polygon,
        }
    }

    /// A point on or near a polygon's edge: `inward` is the unit in-plane direction into the
    /// polygon. Form factors are evaluated `1e-6` of the scene extent inside, rays start
    /// `4 epsilon` inside and `2 epsilon` off the surface.
    pub fn near_edge(
        p: DVec3,
        n: DVec3,
        inward: DVec3,
        polygon: usize,
        vis: &Visibility,
        extent: f64,
    ) -> SurfacePoint {
        let e = vis.epsilon();
        SurfacePoint {
            p: p + inward * (1e-6 * extent),
            n,
            ray_origin: p + inward * (4.0 * e) + n * (2.0 * e),
            polygon,
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Emitters and direct light

/// An area emitter: one emitting polygon with a fixed, stratified set of sample points.
pub struct AreaEmitter {
    /// Index into [`Scene::polygons`].
    pub polygon: usize,
    /// Emitted radiance (front face), W/(m² sr).
    pub radiance: DVec3,
    /// Front normal.
    pub normal: DVec3,
    /// The polygon's triangles, world space.
    pub triangles: Vec<[DVec3; 3]>,
    /// The polygon merged into convex pieces in its plane, for the form factors and the
    /// backprojection.
    pub shape: EmitterShape,
    /// Sample sets, each a stratified set of points with their area (the areas of a set sum to
    /// the emitter's area): `samples[0]` has the full count, each next set half as many.
    pub samples: Vec<Vec<(DVec3, f64)>>,
    /// Bounding sphere (centre, radius) for culling.
    pub center: DVec3,
    pub radius: f64,
}

/// The radical inverse in base 2 (van der Corput), the second Hammersley coordinate.
fn radical_inverse2(mut i: u32) -> f64 {
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
    pub fn all(scene: &Scene, samples: usize) -> Vec<AreaEmitter> {
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
                let radius = triangles
                    .iter()
                    .flatten()
                    .map(|q| q.distance(center))
                    .fold(0.0, f64::max);
                AreaEmitter {
                    polygon: id,
                    radiance: scene.materials[poly.material].radiance,
                    normal: poly.frame.n,
                    shape: EmitterShape::new(poly.frame, &poly.triangles_plane),
                    triangles,
                    samples: sets,
                    center,
                    radius,
                }
            })
            .collect()
    }

    /// Unoccluded form factor from `(p, n)` to the emitter's front face: Lambert's contour
    /// formula over its convex pieces, clipped to the horizon of `p`.
    pub fn form_factor(&self, p: DVec3, n: DVec3) -> f64 {
        self.shape.form_factor(p, n)
    }
}

/// Per-emitter counters of a [`Direct`].
#[derive(Default)]
struct EmitterCounters {
    evaluations: AtomicU64,
    occluders: AtomicU64,
    fallbacks: AtomicU64,
    nanos: AtomicU64,
}

/// Counters of one call, added to the shared ones at its end.
#[derive(Default)]
struct Tally {
    evaluations: u64,
    candidates: u64,
    fallbacks: u64,
    occluders: u64,
    occluders_max: u64,
    pieces_max: u64,
    rays: u64,
}

/// Direct irradiance at a surface point: the light of every emitter and punctual light.
///
/// With [`DirectMethod::Exact`], [`Direct::irradiance_points`] evaluates the points of one
/// receiver together: per emitter, the occluders in the box around the points and the emitter
/// come from the BVH once, then a kd-tree over the points culls them with the shaft (convex
/// hull) of each cluster and the emitter, down to clusters of a few points, so each point clips
/// only the occluders near its own view of the emitter.
pub struct Direct<'a> {
    pub scene: &'a Scene,
    pub vis: &'a Visibility,
    pub emitters: Vec<AreaEmitter>,
    pub rays: AtomicU64,
    pub method: DirectMethod,
    /// Caps of the exact method, past which it falls back to shadow rays.
    pub limits: Limits,
    /// The scene's polygons in convex pieces (exact method only; empty otherwise).
    pub occluders: Occluders,
    evaluations: AtomicU64,
    candidates: AtomicU64,
    fallbacks: AtomicU64,
    occluder_total: AtomicU64,
    occluders_max: AtomicU64,
    pieces_max: AtomicU64,
    per_emitter: Vec<EmitterCounters>,
}

/// Points per leaf of the cluster tree of [`Direct::irradiance_points`].
const CLUSTER_LEAF: usize = 12;

impl<'a> Direct<'a> {
    /// Exact direct light, with `shadow_samples` rays for the fallback.
    pub fn new(scene: &'a Scene, vis: &'a Visibility, shadow_samples: usize) -> Direct<'a> {
        Direct::with_options(
            scene,
            vis,
            &SolveOptions {
                shadow_samples,
                ..SolveOptions::default()
            },
        )
    }

    /// Direct light as `options` asks (`direct`, `shadow_samples`, `occluder_cap`).
    pub fn with_options(
        scene: &'a Scene,
        vis: &'a Visibility,
        options: &SolveOptions,
    ) -> Direct<'a> {
        let emitters = AreaEmitter::all(scene, options.shadow_samples);
        let occluders = match options.direct {
            DirectMethod::Exact => Occluders::new(scene),
            DirectMethod::Sampled => Occluders::default(),
        };
        Direct {
            scene,
            vis,
            per_emitter: emitters
                .iter()
                .map(|_| EmitterCounters::default())
                .collect(),
            emitters,
            rays: AtomicU64::new(0),
            method: options.direct,
            limits: Limits {
                max_occluders: options.occluder_cap,
                ..Limits::default()
            },
            occluders,
            evaluations: AtomicU64::new(0),
            candidates: AtomicU64::new(0),
            fallbacks: AtomicU64::new(0),
            occluder_total: AtomicU64::new(0),
            occluders_max: AtomicU64::new(0),
            pieces_max: AtomicU64::new(0),
        }
    }

    /// Irradiance H (W/m²) at a receiving point.
    pub fn irradiance(&self, at: &SurfacePoint) -> DVec3 {
        match self.method {
            DirectMethod::Sampled => self.irradiance_sampled(at),
            DirectMethod::Exact => self.irradiance_points(std::slice::from_ref(at))[0],
        }
    }

    /// Irradiance H (W/m²) at each of `points`, best called with the points of one receiver
    /// polygon (a mesh's vertices): the exact method shares the occluder search between
    /// neighbouring points. The result of each point does not depend on the others, up to
    /// rounding in rare near-degenerate cases; it is deterministic for given `points`.
    pub fn irradiance_points(&self, points: &[SurfacePoint]) -> Vec<DVec3> {
        if self.method == DirectMethod::Sampled {
            return points.iter().map(|p| self.irradiance_sampled(p)).collect();
        }
        let mut h = vec![DVec3::ZERO; points.len()];
        let mut tally = Tally::default();
        let mut scale = vec![0.0; points.len()];
        let tree = ClusterTree::new(points);
        let mut scratch = Scratch::default();
        for (ei, e) in self.emitters.iter().enumerate() {
            let start = Instant::now();
            let before = (tally.evaluations, tally.occluders, tally.fallbacks);
            let f_un: Vec<f64> = points.iter().map(|q| e.form_factor(q.p, q.n)).collect();
            let active = f_un.iter().filter(|f| **f > 0.0).count();
            if active == 0 {
                continue;
            }
            // Candidate occluders: the BVH's triangles in the box around the points and the
            // emitter, as convex pieces, without the emitter itself.
            let hull = e.shape.hull_world();
            let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
            for q in (0..points.len())
                .filter(|&i| f_un[i] > 0.0)
                .map(|i| points[i].p)
                .chain(hull.iter().copied())
            {
                lo = lo.min(q);
                hi = hi.max(q);
            }
            let mut tris = Vec::new();
            self.vis.triangles_overlapping(lo, hi, &mut tris);
            let mut candidates: Vec<u32> = tris
                .iter()
                .map(|&t| self.occluders.piece_of_triangle[t])
                .filter(|&k| {
                    k != u32::MAX && self.occluders.pieces[k as usize].polygon != e.polygon
                })
                .collect();
            candidates.sort_unstable();
            candidates.dedup();
            let job = EmitterJob {
                emitter: e,
                hull: &hull,
                points,
                tree: &tree,
                f_un: &f_un,
            };
            self.exact_cluster(&job, 0, &candidates, &mut scale, &mut tally, &mut scratch);
            for (i, h) in h.iter_mut().enumerate() {
                if f_un[i] > 0.0 {
                    *h += e.radiance * scale[i];
                }
            }
            let c = &self.per_emitter[ei];
            c.evaluations
                .fetch_add(tally.evaluations - before.0, Ordering::Relaxed);
            c.occluders
                .fetch_add(tally.occluders - before.1, Ordering::Relaxed);
            c.fallbacks
                .fetch_add(tally.fallbacks - before.2, Ordering::Relaxed);
            c.nanos
                .fetch_add(start.elapsed().as_nanos() as u64, Ordering::Relaxed);
        }
        for (pt, h) in points.iter().zip(&mut h) {
            for light in &self.scene.lights {
                let (value, r) = punctual_irradiance(light, self.vis, pt);
                *h += value;
                tally.rays += r;
            }
        }
        self.rays.fetch_add(tally.rays, Ordering::Relaxed);
        self.evaluations
            .fetch_add(tally.evaluations, Ordering::Relaxed);
        self.fallbacks.fetch_add(tally.fallbacks, Ordering::Relaxed);
        self.candidates
            .fetch_add(tally.candidates, Ordering::Relaxed);
        self.occluder_total
            .fetch_add(tally.occluders, Ordering::Relaxed);
        self.occluders_max
            .fetch_max(tally.occluders_max, Ordering::Relaxed);
        self.pieces_max
            .fetch_max(tally.pieces_max, Ordering::Relaxed);
        h
    }

    /// Exact light of one emitter at the points of cluster `node` that see it: culls
    /// `candidates` with the shaft of the cluster and the emitter, then goes down to the two
    /// halves, or evaluates the points of a leaf. Writes `pi F_visible` of each point into
    /// `scale`.
    fn exact_cluster(
        &self,
        job: &EmitterJob,
        node: usize,
        candidates: &[u32],
        scale: &mut [f64],
        tally: &mut Tally,
        scratch: &mut Scratch,
    ) {
        let cluster = &job.tree.nodes[node];
        let members = &job.tree.order[cluster.start..cluster.end];
        if !members.iter().any(|&i| job.f_un[i] > 0.0) {
            return;
        }
        // A short list is left to the per-point clipping; a shaft costs more than it saves.
        let culled: Vec<u32>;
        let candidates = if candidates.len() <= 4 {
            candidates
        } else {
            let shaft = cluster.shaft(&job.emitter.shape, job.hull);
            culled = candidates
                .iter()
                .copied()
                .filter(|&k| !shaft.excludes(&self.occluders.pieces[k as usize].vertices))
                .collect();
            &culled
        };
        match cluster.children {
            Some([left, right]) if !candidates.is_empty() => {
                self.exact_cluster(job, left, candidates, scale, tally, scratch);
                self.exact_cluster(job, right, candidates, scale, tally, scratch);
            }
            _ => {
                for &i in members {
                    if job.f_un[i] > 0.0 {
                        scale[i] = self.exact_at(
                            job.emitter,
                            &job.points[i],
                            job.f_un[i],
                            candidates,
                            tally,
                            scratch,
                        );
                    }
                }
            }
        }
    }

    /// `pi F` of the visible part of `e` at one point, from the occluder pieces `candidates`
    /// (the point's own polygon left out); shadow rays past the caps.
    fn exact_at(
        &self,
        e: &AreaEmitter,
        at: &SurfacePoint,
        f_unoccluded: f64,
        candidates: &[u32],
        tally: &mut Tally,
        scratch: &mut Scratch,
    ) -> f64 {
        tally.evaluations += 1;
        if candidates.is_empty() {
            return PI * f_unoccluded;
        }
        tally.candidates += candidates.len() as u64;
        let pieces = &self.occluders.pieces;
        let occluders = candidates
            .iter()
            .map(|&k| &pieces[k as usize])
            .filter(|piece| piece.polygon != at.polygon)
            .map(|piece| piece.vertices.as_slice());
        let r = scratch.visible_form_factor(
            at.p,
            at.n,
            &e.shape,
            occluders,
            &self.limits,
            Some(f_unoccluded),
        );
        tally.occluders += r.occluders as u64;
        tally.occluders_max = tally.occluders_max.max(r.occluders as u64);
        tally.pieces_max = tally.pieces_max.max(r.pieces as u64);
        match r.form_factor {
            // Nothing in the way: the same value as the sampled method's unoccluded one.
            Some(_) if r.occluders == 0 => PI * f_unoccluded,
            Some(f) => PI * f,
            None => {
                tally.fallbacks += 1;
                let total = self.total_weight(at);
                let (visible, rays) = self.sampled_visibility(e, f_unoccluded, total, at);
                tally.rays += rays;
                PI * f_unoccluded * visible
            }
        }
    }

    /// Sum over the emitters of the unoccluded form factor times the summed radiance: how the
    /// sampled method shares its shadow rays between emitters.
    fn total_weight(&self, at: &SurfacePoint) -> f64 {
        self.emitters
            .iter()
            .map(|e| e.form_factor(at.p, at.n) * e.radiance.element_sum())
            .sum()
    }

    /// Visibility fraction of `e` from `at` by shadow rays: the emitter's share (`f` x radiance
    /// out of `total`) of its sample count, at least one set; each ray weighted by its
    /// form-factor kernel. Returns the fraction and the rays cast.
    fn sampled_visibility(
        &self,
        e: &AreaEmitter,
        f: f64,
        total: f64,
        at: &SurfacePoint,
    ) -> (f64, u64) {
        let (p, n, p_ray) = (at.p, at.n, at.ray_origin);
        let mut rays = 0;
        let wanted =
            e.samples[0].len() as f64 * f * e.radiance.element_sum() / total.max(f64::MIN_POSITIVE);
        let mut level = 0;
        while level + 1 < e.samples.len() && e.samples[level + 1].len() as f64 >= wanted {
            level += 1;
        }
        let mut seen = 0.0;
        let mut all = 0.0;
        for &(s, a) in &e.samples[level] {
            let d = s - p;
            let r2 = d.length_squared();
            let cos_r = n.dot(d);
            let cos_e = -e.normal.dot(d);
            if cos_r <= 0.0 || cos_e <= 0.0 {
                continue;
            }
            let w = a * cos_r * cos_e / (r2 * r2);
            all += w;
            rays += 1;
            if !self
                .vis
                .occluded_skipping(p_ray, s, [at.polygon, e.polygon])
            {
                seen += w;
            }
        }
        // When every sample is below the horizon the sliver that remains is taken as seen.
        (if all > 0.0 { seen / all } else { 1.0 }, rays)
    }

    /// Sampled direct light at one point: exact unoccluded form factor x visibility fraction
    /// from shadow rays, spent in proportion to each emitter's contribution (at least one per
    /// visible emitter), so scenes with many small emitters stay cheap.
    fn irradiance_sampled(&self, at: &SurfacePoint) -> DVec3 {
        let mut h = DVec3::ZERO;
        let mut rays = 0u64;
        let (p, n) = (at.p, at.n);
        let unoccluded: Vec<f64> = self.emitters.iter().map(|e| e.form_factor(p, n)).collect();
        let total: f64 = self
            .emitters
            .iter()
            .zip(&unoccluded)
            .map(|(e, &f)| f * e.radiance.element_sum())
            .sum();
        let mut evaluations = 0;
        for ((e, &f), c) in self.emitters.iter().zip(&unoccluded).zip(&self.per_emitter) {
            if f <= 0.0 {
                continue;
            }
            evaluations += 1;
            let start = Instant::now();
            let (visible, r) = self.sampled_visibility(e, f, total, at);
            c.evaluations.fetch_add(1, Ordering::Relaxed);
            c.nanos
                .fetch_add(start.elapsed().as_nanos() as u64, Ordering::Relaxed);
            rays += r;
            h += e.radiance * (PI * f * visible);
        }
        for light in &self.scene.lights {
            let (value, r) = punctual_irradiance(light, self.vis, at);
            h += value;
            rays += r;
        }
        self.evaluations.fetch_add(evaluations, Ordering::Relaxed);
        self.rays.fetch_add(rays, Ordering::Relaxed);
        h
    }

    /// The counters so far (all calls since [`Direct::new`]); `seconds` is left at 0.
    pub fn stats(&self) -> DirectStats {
        let load = |a: &AtomicU64| a.load(Ordering::Relaxed);
        DirectStats {
            method: self.method,
            seconds: 0.0,
            evaluations: load(&self.evaluations),
            candidates: load(&self.candidates),
            fallbacks: load(&self.fallbacks),
            occluder_cap: self.limits.max_occluders,
            occluders: load(&self.occluder_total),
            occluders_max: load(&self.occluders_max),
            pieces_max: load(&self.pieces_max),
            emitters: self
                .emitters
                .iter()
                .zip(&self.per_emitter)
                .map(|(e, c)| EmitterCost {
                    polygon: e.polygon,
                    triangles: e.triangles.len(),
                    convex_pieces: e.shape.pieces.len(),
                    evaluations: load(&c.evaluations),
                    occluders: load(&c.occluders),
                    fallbacks: load(&c.fallbacks),
                    seconds: load(&c.nanos) as f64 * 1e-9,
                })
                .collect(),
        }
    }
}

/// One emitter's exact pass over the points of one [`Direct::irradiance_points`] call.
struct EmitterJob<'a> {
    emitter: &'a AreaEmitter,
    /// The emitter's hull, world space.
    hull: &'a [DVec3],
    points: &'a [SurfacePoint],
    tree: &'a ClusterTree,
    /// Unoccluded form factor of each point (0: the emitter is behind or below its horizon).
    f_un: &'a [f64],
}

/// A kd-tree over receiving points, built once per call and shared by all emitters: each node
/// holds the points `order[start..end]`, halved along their widest axis down to
/// [`CLUSTER_LEAF`] points.
struct ClusterTree {
    order: Vec<usize>,
    nodes: Vec<Cluster>,
}

struct Cluster {
    start: usize,
    end: usize,
    /// Corners of the points' bounding box in a frame of the first point's normal: 4 when the
    /// points lie in one plane, 8 otherwise.
    corners: Vec<DVec3>,
    /// For points of one plane with one normal: the normal and the highest point's height along
    /// it, as a point. Occluders below that plane cannot block them.
    plane: Option<(DVec3, DVec3)>,
    children: Option<[usize; 2]>,
}

impl ClusterTree {
    fn new(points: &[SurfacePoint]) -> ClusterTree {
        let mut tree = ClusterTree {
            order: (0..points.len()).collect(),
            nodes: Vec::new(),
        };
        if !points.is_empty() {
            tree.build(points, 0, points.len());
        }
        tree
    }

    fn build(&mut self, points: &[SurfacePoint], start: usize, end: usize) -> usize {
        let members = &self.order[start..end];
        let first = &points[members[0]];
        let n0 = first.n;
        let u = n0.any_orthonormal_vector();
        let v = n0.cross(u);
        let o = first.p;
        let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
        let (mut wlo, mut whi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
        let mut one_normal = true;
        for &i in members {
            let d = points[i].p - o;
            let q = DVec3::new(d.dot(u), d.dot(v), d.dot(n0));
            lo = lo.min(q);
            hi = hi.max(q);
            wlo = wlo.min(points[i].p);
            whi = whi.max(points[i].p);
            one_normal &= points[i].n == n0;
        }
        let extent = (hi - lo).max_element();
        let flat = hi.z - lo.z <= 1e-9 * extent;
        let corners = (0..if flat { 4 } else { 8 })
            .map(|k| {
                let x = if k & 1 == 0 { lo.x } else { hi.x };
                let y = if k & 2 == 0 { lo.y } else { hi.y };
                let z = if flat || k & 4 == 0 { lo.z } else { hi.z };
                o + u * x + v * y + n0 * z
            })
            .collect();
        let id = self.nodes.len();
        self.nodes.push(Cluster {
            start,
            end,
            corners,
            plane: (flat && one_normal).then_some((n0, o + n0 * hi.z)),
            children: None,
        });
        if end - start > CLUSTER_LEAF {
            let d = whi - wlo;
            let axis = if d.x >= d.y && d.x >= d.z {
                0
            } else if d.y >= d.z {
                1
            } else {
                2
            };
            let mid = (end - start) / 2;
            self.order[start..end].select_nth_unstable_by(mid, |&a, &b| {
                points[a].p[axis]
                    .total_cmp(&points[b].p[axis])
                    .then(a.cmp(&b))
            });
            let left = self.build(points, start, start + mid);
            let right = self.build(points, start + mid, end);
            self.nodes[id].children = Some([left, right]);
        }
        id
    }
}

impl Cluster {
    /// The shaft of the cluster and an emitter: the convex hull of the cluster's corners and
    /// the emitter's hull (its bounding rectangle when the hull has many corners), less what
    /// lies on or behind the emitter's plane and, for a planar cluster, below its plane.
    fn shaft(&self, shape: &EmitterShape, hull: &[DVec3]) -> Shaft {
        let mut pts: Vec<DVec3> = Vec::with_capacity(self.corners.len() + 8);
        pts.extend_from_slice(&self.corners);
        if hull.len() <= 8 {
            pts.extend_from_slice(hull);
        } else {
            let (a, b) = shape.hull.iter().fold(
                (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY)),
                |(a, b), q| (a.min(*q), b.max(*q)),
            );
            for q in [a, DVec2::new(b.x, a.y), b, DVec2::new(a.x, b.y)] {
                pts.push(shape.frame.world_from_plane(q));
            }
        }
        let shaft = Shaft::hull(&pts);
        let tol = shaft.tolerance();
        let fr = &shape.frame;
        // Excluded when every corner is less than the plane tolerance in front of the emitter,
        // as the per-point clipping does.
        let mut shaft = shaft.with_plane(-fr.n, fr.origin + fr.n * (shape.plane_tolerance() + tol));
        if let Some((n, q)) = self.plane {
            // Excluded when every corner is below the receivers' plane (or in it, to within
            // the tolerance): such an occluder projects to nothing from points in that plane.
            shaft = shaft.with_plane(-n, q + n * (2.0 * tol));
        }
        shaft
    }
}

/// Irradiance from one punctual light at a receiving point, and the rays it cast: the
/// unoccluded irradiance of [`punctual_unoccluded`] if one shadow ray towards the light is free.
pub fn punctual_irradiance(
    light: &PunctualLight,
    vis: &Visibility,
    at: &SurfacePoint,
) -> (DVec3, u64) {
    let Some(e) = punctual_unoccluded(light, at) else {
        return (DVec3::ZERO, 0);
    };
    let lit = match light.kind {
        LightKind::Directional => {
            vis.unoccluded_towards(at.ray_origin, -light.direction, at.polygon)
        }
        LightKind::Point | LightKind::Spot { .. } => {
            !vis.occluded_skipping(at.ray_origin, light.position, [at.polygon, NO_POLYGON])
        }
    };
    (if lit { e } else { DVec3::ZERO }, 1)
}

/// Irradiance from one punctual light at a receiving point if nothing blocked it, W/m²:
/// point and spot `I cos(theta) / d^2` with glTF's range window and spot falloff; directional
/// `E cos(theta)`. `None` when the light cannot reach the point (behind it, outside the range
/// or the cone).
pub fn punctual_unoccluded(light: &PunctualLight, at: &SurfacePoint) -> Option<DVec3> {
    let (p, n) = (at.p, at.n);
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

// ---------------------------------------------------------------------------------------------
// Patches and the indirect solve

/// A coarse patch of the indirect solve: one triangle.
#[derive(Clone, Debug)]
pub struct Patch {
    /// Index into [`Scene::polygons`].
    pub polygon: usize,
    pub p: [DVec3; 3],
    pub normal: DVec3,
    pub centroid: DVec3,
    pub area: f64,
    pub rho: DVec3,
    /// Bounding radius around the centroid.
    pub radius: f64,
}

impl Patch {
    fn new(polygon: usize, p: [DVec3; 3], normal: DVec3, rho: DVec3) -> Patch {
        let centroid = (p[0] + p[1] + p[2]) / 3.0;
        let area = 0.5 * (p[1] - p[0]).cross(p[2] - p[0]).length();
        let radius = p.iter().map(|q| q.distance(centroid)).fold(0.0, f64::max);
        Patch {
            polygon,
            p,
            normal,
            centroid,
            area,
            rho,
            radius,
        }
    }
}

/// Builds the patches: the polygons triangulated to about `target` triangles.
pub fn patches(scene: &Scene, target: usize) -> Vec<Patch> {
    let meshes = crate::mesh::uniform(scene, target);
    let mut out = Vec::new();
    for m in &meshes {
        let poly = &scene.polygons[m.polygon];
        let rho = scene.materials[poly.material].rho;
        for t in &m.triangles {
            let p = t.map(|i| poly.frame.world_from_plane(m.vertices[i as usize]));
            out.push(Patch::new(m.polygon, p, poly.frame.n, rho));
        }
    }
    out
}

/// Form factor from a receiving surface point `(p, n)` to a patch, with visibility: exact unoccluded
/// form factor of each piece times the visibility of its centroid; pieces near `p` are split in
/// four, up to two levels. Returns the form factor and adds the rays cast to `rays`.
pub fn point_patch_form_factor(
    vis: &Visibility,
    at: &SurfacePoint,
    patch: &Patch,
    rays: &mut u64,
) -> f64 {
    let (p, n) = (at.p, at.n);
    // Cull: a planar polygon does not see itself; the receiver behind (or in the plane of) the
    // patch; the patch entirely below the receiver's horizon.
    if at.polygon == patch.polygon
        || patch.normal.dot(p - patch.centroid) <= 1e-9 * (p - patch.centroid).length()
    {
        return 0.0;
    }
    if patch.p.iter().all(|q| n.dot(*q - p) <= 0.0) {
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
    if vis.occluded_skipping(p_ray, c, skip) {
        0.0
    } else {
        f
    }
}

/// Progressive refinement over patches: returns the irradiance of each patch, direct plus
/// indirect. `direct[i]` is the direct irradiance of patch `i`.
pub fn progressive(
    vis: &Visibility,
    patches: &[Patch],
    direct: &[DVec3],
    bounces: Option<u32>,
    tolerance: f64,
    stats: &mut SolveStats,
) -> Vec<DVec3> {
    let mut h = direct.to_vec();
    // Unshot radiosity (W/m²) of each patch: its reflected direct light.
    let mut unshot: Vec<DVec3> = patches
        .iter()
        .zip(direct)
        .map(|(p, d)| p.rho * *d)
        .collect();
    let power = |i: usize, u: &[DVec3]| u[i].element_sum() / 3.0 * patches[i].area;
    let initial: f64 = (0..patches.len()).map(|i| power(i, &unshot)).sum();
    let mut rays = 0u64;
    let mut shots = 0usize;
    // Shoots radiosity `b` from patch `i`: every other patch receives irradiance at its
    // centroid, and its reflected part becomes unshot radiosity in `next`.
    let mut shoot = |i: usize, b: DVec3, h: &mut Vec<DVec3>, next: &mut Vec<DVec3>| {
        let src = &patches[i];
        let received: Vec<(DVec3, u64)> = patches
            .par_iter()
            .enumerate()
            .map(|(j, r)| {
                if j == i {
                    return (DVec3::ZERO, 0);
                }
                let mut n = 0;
                let at = SurfacePoint::new(r.centroid, r.normal, r.polygon, vis);
                let f = point_patch_form_factor(vis, &at, src, &mut n);
                (b * f, n)
            })
            .collect();
        for (j, (dh, n)) in received.into_iter().enumerate() {
            rays += n;
            h[j] += dh;
            next[j] += patches[j].rho * dh;
        }
    };
    match bounces {
        Some(0) => {}
        Some(n) => {
            // n bounces in all: the final gather at the vertices is the last one, so the patches
            // exchange light n-1 times, one generation of unshot light at a time.
            for _ in 1..n {
                let mut next = vec![DVec3::ZERO; patches.len()];
                for (i, &b) in unshot.iter().enumerate() {
                    if b.max_element() > 0.0 {
                        shoot(i, b, &mut h, &mut next);
                        shots += 1;
                    }
                }
                unshot = next;
            }
        }
        None => {
            let limit = 100 * patches.len() + 1000;
            loop {
                let total: f64 = (0..patches.len()).map(|i| power(i, &unshot)).sum();
                if total <= tolerance * initial || shots >= limit {
                    break;
                }
                // The patch with the most unshot power; ties broken by index.
                let mut best = 0;
                let mut best_power = -1.0;
                for i in 0..patches.len() {
                    let pw = power(i, &unshot);
                    if pw > best_power {
                        best = i;
                        best_power = pw;
                    }
                }
                let b = std::mem::take(&mut unshot[best]);
                shoot(best, b, &mut h, &mut unshot);
                shots += 1;
            }
        }
    }
    let left: f64 = (0..patches.len()).map(|i| power(i, &unshot)).sum();
    stats.patches = patches.len();
    stats.shots = shots;
    stats.rays += rays;
    stats.unshot_fraction = if initial > 0.0 { left / initial } else { 0.0 };
    h
}

/// Gauss-Seidel on the full patch system `B_i = E_i + rho_i sum_j K_ij B_j`, where `E_i` is the
/// reflected direct light and `K_ij` the point-to-patch form factor at patch `i`'s centroid;
/// returns each patch's irradiance like [`progressive`]. Quadratic memory: for small scenes and
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

/// Where each mesh vertex is evaluated: the vertex as a [`SurfacePoint::near_edge`], pulled
/// toward the centroid of one of its triangles. A vertex on the polygon's edge then sees a
/// surface that meets the edge (a wall on the floor) as its limit from inside the polygon,
/// instead of lying in that surface's plane, where the contour integral and rays degenerate.
fn evaluation_points(scene: &Scene, vis: &Visibility, mesh: &ReceiverMesh) -> Vec<SurfacePoint> {
    let frame = &scene.polygons[mesh.polygon].frame;
    let mut toward = vec![None::<DVec2>; mesh.vertices.len()];
    for t in &mesh.triangles {
        let c = t.iter().map(|&i| mesh.vertices[i as usize]).sum::<DVec2>() / 3.0;
        for &i in t {
            toward[i as usize].get_or_insert(c);
        }
    }
    mesh.vertices
        .iter()
        .zip(&toward)
        .map(|(&v, c)| {
            let d = c
                .map(|c| (c - v).normalize_or_zero())
                .unwrap_or(DVec2::ZERO);
            let inward = frame.u * d.x + frame.v * d.y;
            SurfacePoint::near_edge(
                frame.world_from_plane(v),
                frame.n,
                inward,
                mesh.polygon,
                vis,
                scene.extent(),
            )
        })
        .collect()
}

/// Direct irradiance H (W/m², linear RGB) at every vertex of `meshes`, one mesh per task: the
/// vertices of one receiver are evaluated together ([`Direct::irradiance_points`]).
pub fn direct_light(
    scene: &Scene,
    vis: &Visibility,
    direct: &Direct<'_>,
    meshes: &[ReceiverMesh],
    progress: &crate::stats::Progress<'_>,
) -> Vec<Vec<DVec3>> {
    let total_vertices: u64 = meshes.iter().map(|m| m.vertices.len() as u64).sum();
    let done = AtomicU64::new(0);
    meshes
        .par_iter()
        .map(|m| {
            let pts = evaluation_points(scene, vis, m);
            let out = direct.irradiance_points(&pts);
            let d = done.fetch_add(m.vertices.len() as u64, Ordering::Relaxed);
            progress("direct light", d + m.vertices.len() as u64, total_vertices);
            out
        })
        .collect()
}

/// Solves direct and indirect light at every vertex of `meshes`.
pub fn radiosity(
    scene: &Scene,
    vis: &Visibility,
    meshes: &[ReceiverMesh],
    options: &SolveOptions,
    progress: &crate::stats::Progress<'_>,
) -> Solution {
    let direct = Direct::with_options(scene, vis, options);
    let mut stats = SolveStats::default();

    // Direct light at the vertices.
    let total_vertices: u64 = meshes.iter().map(|m| m.vertices.len() as u64).sum();
    let start = Instant::now();
    let direct_h = direct_light(scene, vis, &direct, meshes, progress);
    stats.direct = direct.stats();
    stats.direct.seconds = start.elapsed().as_secs_f64();

    let irradiance = if options.bounces == Some(0) {
        direct_h.clone()
    } else {
        // Indirect: patches, progressive refinement, final gather.
        let patches = patches(scene, options.patches);
        let patch_direct: Vec<DVec3> = patches
            .par_iter()
            .map(|p| direct.irradiance(&SurfacePoint::new(p.centroid, p.normal, p.polygon, vis)))
            .collect();
        let patch_h = progressive(
            vis,
            &patches,
            &patch_direct,
            options.bounces,
            options.tolerance,
            &mut stats,
        );
        stats.direct_power = patches
            .iter()
            .zip(&patch_direct)
            .map(|(p, h)| p.area * h.element_sum() / 3.0)
            .sum();
        stats.absorbed_power = patches
            .iter()
            .zip(&patch_h)
            .map(|(p, h)| p.area * ((DVec3::ONE - p.rho) * *h).element_sum() / 3.0)
            .sum();
        // Reflected radiosity of each patch, the source of the final gather.
        let reflected: Vec<DVec3> = patches
            .iter()
            .zip(&patch_h)
            .map(|(p, h)| p.rho * *h)
            .collect();
        let gather_rays = AtomicU64::new(0);
        let done = AtomicU64::new(0);
        let out = meshes
            .par_iter()
            .zip(&direct_h)
            .map(|(m, dh)| {
                let pts = evaluation_points(scene, vis, m);
                let mut rays = 0u64;
                let values = pts
                    .iter()
                    .zip(dh)
                    .map(|(p, &d)| {
                        let mut h = d;
                        for (patch, b) in patches.iter().zip(&reflected) {
                            if b.max_element() <= 0.0 {
                                continue;
                            }
                            h += *b * point_patch_form_factor(vis, p, patch, &mut rays);
                        }
                        h
                    })
                    .collect();
                gather_rays.fetch_add(rays, Ordering::Relaxed);
                let d = done.fetch_add(m.vertices.len() as u64, Ordering::Relaxed);
                progress(
                    "indirect light",
                    d + m.vertices.len() as u64,
                    total_vertices,
                );
                values
            })
            .collect();
        stats.rays += gather_rays.load(Ordering::Relaxed);
        out
    };
    stats.rays += direct.rays.load(Ordering::Relaxed);
    stats.emitted_power = direct
        .emitters
        .iter()
        .map(|e| PI * e.radiance.element_sum() / 3.0 * scene.polygons[e.polygon].area)
        .sum();
    Solution {
        irradiance,
        direct: direct_h,
        stats,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square(z: f64, size: f64) -> Vec<DVec3> {
        let h = size / 2.0;
        vec![
            DVec3::new(-h, -h, z),
            DVec3::new(h, -h, z),
            DVec3::new(h, h, z),
            DVec3::new(-h, h, z),
        ]
    }

    /// Corner formula for a differential element under a parallel rectangle (Howell's catalogue).
    fn corner(a: f64, b: f64, h: f64) -> f64 {
        let sa = (a * a + h * h).sqrt();
        let sb = (b * b + h * h).sqrt();
        (a / sa * (b / sa).atan() + b / sb * (a / sb).atan()) / (2.0 * PI)
    }

    #[test]
    fn differential_under_coaxial_disk_is_half() {
        // r = h: F = r²/(h²+r²) = 0.5; a 4096-gon approximates the disk to ~4e-7.
        let n = 4096;
        let disk: Vec<DVec3> = (0..n)
            .map(|k| {
                let a = 2.0 * PI * k as f64 / n as f64;
                DVec3::new(a.cos(), a.sin(), 1.0)
            })
            .collect();
        let f = point_polygon_form_factor(DVec3::ZERO, DVec3::Z, &disk);
        // The inscribed polygon is smaller than the disk by a relative 4e-7.
        assert!((f - 0.5).abs() < 1e-6, "{f}");
    }

    #[test]
    fn rectangle_corner_formula_matches_contour_integral() {
        // Axis-aligned rectangle [x0,x1]x[y0,y1] at height h above the point.
        let (x0, x1, y0, y1, h) = (-0.3, 1.2, 0.4, 2.0, 0.7);
        let exact = corner(x1, y1, h) - corner(x0, y1, h) - corner(x1, y0, h) + corner(x0, y0, h);
        let poly = vec![
            DVec3::new(x0, y0, h),
            DVec3::new(x1, y0, h),
            DVec3::new(x1, y1, h),
            DVec3::new(x0, y1, h),
        ];
        let f = point_polygon_form_factor(DVec3::ZERO, DVec3::Z, &poly);
        assert!((f - exact).abs() < 1e-12, "{f} vs {exact}");
    }

    /// Area-to-area form factor by Gauss-Legendre quadrature of the point-to-polygon form factor
    /// over the receiving unit square.
    fn area_form_factor(receiver: &dyn Fn(f64, f64) -> (DVec3, DVec3), source: &[DVec3]) -> f64 {
        // 20-point Gauss-Legendre nodes and weights on [-1, 1], by Newton iteration.
        let n = 20;
        let mut nodes = vec![0.0; n];
        let mut weights = vec![0.0; n];
        for i in 0..n {
            let mut x = (PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
            for _ in 0..100 {
                let (mut p0, mut p1) = (1.0, x);
                for k in 2..=n {
                    let p2 = ((2 * k - 1) as f64 * x * p1 - (k - 1) as f64 * p0) / k as f64;
                    p0 = p1;
                    p1 = p2;
                }
                let dp = n as f64 * (x * p1 - p0) / (x * x - 1.0);
                let dx = p1 / dp;
                x -= dx;
                if dx.abs() < 1e-15 {
                    break;
                }
            }
            let (mut p0, mut p1) = (1.0, x);
            for k in 2..=n {
                let p2 = ((2 * k - 1) as f64 * x * p1 - (k - 1) as f64 * p0) / k as f64;
                p0 = p1;
                p1 = p2;
            }
            let dp = n as f64 * (x * p1 - p0) / (x * x - 1.0);
            nodes[i] = x;
            weights[i] = 2.0 / ((1.0 - x * x) * dp * dp);
        }
        // Composite over 4x4 cells so the edge singularity of adjacent squares converges.
        let cells = 4;
        let mut sum = 0.0;
        for cu in 0..cells {
            for cv in 0..cells {
                for i in 0..n {
                    for j in 0..n {
                        let u = (cu as f64 + 0.5 * (nodes[i] + 1.0)) / cells as f64;
                        let v = (cv as f64 + 0.5 * (nodes[j] + 1.0)) / cells as f64;
                        let (p, nn) = receiver(u, v);
                        let w = weights[i] * weights[j] * 0.25 / (cells * cells) as f64;
                        sum += w * point_polygon_form_factor(p, nn, source);
                    }
                }
            }
        }
        sum
    }

    #[test]
    fn parallel_unit_squares_match_howell() {
        for (d, exact) in [
            (1.0, 0.1998248957),
            (2.0, 0.0685895888),
            (0.5, 0.4152532836),
        ] {
            let src = square(d, 1.0);
            let f = area_form_factor(&|u, v| (DVec3::new(u - 0.5, v - 0.5, 0.0), DVec3::Z), &src);
            assert!((f - exact).abs() < 1e-6, "d={d}: {f} vs {exact}");
        }
    }

    #[test]
    fn perpendicular_unit_squares_match_howell() {
        // Receiver in z=0 (x in [0,1], y in [0,1]), source in the plane y=0 above it (x, z in
        // [0,1]), sharing the edge along x. Howell C-14: 0.2000437761.
        let src = vec![
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(1.0, 0.0, 0.0),
            DVec3::new(1.0, 0.0, 1.0),
            DVec3::new(0.0, 0.0, 1.0),
        ];
        let f = area_form_factor(&|u, v| (DVec3::new(u, v, 0.0), DVec3::Z), &src);
        // The edge singularity limits quadrature accuracy; 1e-5 still catches any real error.
        assert!((f - 0.2000437761).abs() < 1e-5, "{f}");
    }

    #[test]
    fn horizon_clipping_halves_a_symmetric_source() {
        // A point on a wall's base looking sideways sees exactly the half of a symmetric source
        // above its horizon.
        let src = vec![
            DVec3::new(-1.0, 1.0, -1.0),
            DVec3::new(1.0, 1.0, -1.0),
            DVec3::new(1.0, 1.0, 1.0),
            DVec3::new(-1.0, 1.0, 1.0),
        ];
        let full = point_polygon_form_factor(DVec3::ZERO, DVec3::Y, &src);
        let half = point_polygon_form_factor(DVec3::ZERO, DVec3::X, &src);
        // By symmetry the x-facing point sees the x>0 half, weighted by cos to x.
        let right = vec![
            DVec3::new(0.0, 1.0, -1.0),
            DVec3::new(1.0, 1.0, -1.0),
            DVec3::new(1.0, 1.0, 1.0),
            DVec3::new(0.0, 1.0, 1.0),
        ];
        let expected = point_polygon_form_factor(DVec3::ZERO, DVec3::X, &right);
        assert!((half - expected).abs() < 1e-14);
        assert!(full > half && half > 0.0);
    }

    #[test]
    fn radical_inverse_is_van_der_corput() {
        assert_eq!(radical_inverse2(0), 0.0);
        assert_eq!(radical_inverse2(1), 0.5);
        assert_eq!(radical_inverse2(2), 0.25);
        assert_eq!(radical_inverse2(3), 0.75);
    }
}
