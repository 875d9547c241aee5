//! Direct light at the mesh vertices: every area emitter (exact by backprojection, or sampled
//! with shadow rays), every punctual light and the sky ([`super::sky`]), per receiver with a cluster tree over its
//! vertices so the occluder search is shared.
//!
//! The exact method: the point-to-polygon form factor of the part of each emitter that a vertex
//! sees ([`super::backproject`]); occluders are culled per cluster of vertices by the shaft of
//! the cluster and the emitter (Haines, Wallace, "Shaft culling for efficient ray-cast
//! radiosity", 1991). The sampled method (and the exact method's fallback past its caps): the
//! exact unoccluded form factor times a visibility fraction from stratified shadow rays.
//! Irradiance in W/m² per linear RGB channel.

use super::lightcuts::LightTree;
pub use super::punctual::punctual_irradiance;
use super::punctual::{punctual_over_fans, towards};
use super::sky::Sky;
use super::texel_lights::TexelLights;
use super::{DirectMethod, SolveOptions, evaluation_points};
use crate::light::{AreaEmitter, LightVector, SurfacePoint, add_light, slant};
use crate::mesh::ReceiverMesh;
use crate::scene::Scene;
use crate::solve::backproject::{EmitterShape, Limits, Occluders, Scratch, Shaft};
use crate::visibility::Visibility;
use glam::{DVec2, DVec3};
use rayon::prelude::*;
use std::f64::consts::PI;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

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
    /// Exact method: nodes of the light tree over the area emitters ([`super::lightcuts`]).
    pub light_tree_nodes: usize,
    /// Exact method: (vertex, light-tree node) pairs bounded instead of evaluated exactly: each
    /// cost one shadow ray and carried under [`super::lightcuts::EPSILON`] of the vertex's
    /// estimated irradiance.
    pub bounded: u64,
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

/// Direct irradiance at a surface point: the light of every emitter and punctual light, and the
/// sky's.
///
/// With [`DirectMethod::Exact`], [`Direct::irradiance_points`] evaluates the points of one
/// receiver together: per emitter, the occluders in the box around the points and the emitter
/// come from the BVH once, then a kd-tree over the points culls them with the shaft (convex
/// hull) of each cluster and the emitter, down to clusters of a few points, so each point clips
/// only the occluders near its own view of the emitter.
pub struct Direct<'a> {
    pub(crate) scene: &'a Scene,
    pub(crate) vis: &'a Visibility,
    pub emitters: Vec<AreaEmitter>,
    pub(crate) rays: AtomicU64,
    pub method: DirectMethod,
    /// Caps of the exact method, past which it falls back to shadow rays.
    pub(crate) limits: Limits,
    /// The scene's polygons in convex pieces (exact method only; empty otherwise).
    pub(crate) occluders: Occluders,
    /// The light tree over `emitters` (exact method only; empty otherwise).
    tree: LightTree,
    /// The sky (`--sky`), if any.
    pub(crate) sky: Option<Sky>,
    /// The punctual lights it counts (indices into [`Scene::lights`]): all of them unless
    /// [`Direct::only`] kept fewer.
    lights: Vec<usize>,
    /// [`SolveOptions::light_error`].
    light_error: f64,
    bounded: AtomicU64,
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

    /// Direct light as `options` asks (`direct`, `shadow_samples`, `occluder_cap`, `sky`,
    /// `sky_samples`).
    pub fn with_options(
        scene: &'a Scene,
        vis: &'a Visibility,
        options: &SolveOptions,
    ) -> Direct<'a> {
        let emitters = AreaEmitter::all(scene, options.shadow_samples);
        let (occluders, tree) = match options.direct {
            DirectMethod::Exact => (Occluders::new(scene), LightTree::new(&emitters)),
            DirectMethod::Sampled => (Occluders::default(), LightTree::default()),
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
            tree,
            sky: Sky::new(scene, options.sky, options.sky_samples),
            lights: (0..scene.lights.len()).collect(),
            light_error: options.light_error,
            bounded: AtomicU64::new(0),
            evaluations: AtomicU64::new(0),
            candidates: AtomicU64::new(0),
            fallbacks: AtomicU64::new(0),
            occluder_total: AtomicU64::new(0),
            occluders_max: AtomicU64::new(0),
            pieces_max: AtomicU64::new(0),
        }
    }

    /// Leaves the area emitters out: the direct light is then the punctual lights' alone (the
    /// hemicube form factors carry the area emitters, [`super::form_factors`]).
    pub(crate) fn drop_area_emitters(&mut self) {
        self.emitters.clear();
        self.per_emitter.clear();
        self.tree = LightTree::default();
    }

    /// Keeps only the area emitters on the polygons `emitter` takes and the punctual lights
    /// `light` takes (indices into [`Scene::lights`]); the sky only when `sky`. The light of a
    /// group of lights alone ([`crate::scene::mixed`]).
    pub(crate) fn only(
        &mut self,
        emitter: impl Fn(usize) -> bool,
        light: impl Fn(usize) -> bool,
        sky: bool,
    ) {
        let keep: Vec<bool> = self.emitters.iter().map(|e| emitter(e.polygon)).collect();
        let mut k = keep.iter();
        self.emitters.retain(|_| *k.next().unwrap_or(&false));
        let mut k = keep.iter();
        self.per_emitter.retain(|_| *k.next().unwrap_or(&false));
        if self.method == DirectMethod::Exact {
            self.tree = LightTree::new(&self.emitters);
        }
        self.lights.retain(|&l| light(l));
        if !sky {
            self.sky = None;
        }
    }

    /// Irradiance H (W/m²) at a receiving point.
    pub fn irradiance(&self, at: &SurfacePoint) -> DVec3 {
        match self.method {
            DirectMethod::Sampled => self.irradiance_sampled(at, true, None).0,
            DirectMethod::Exact => self.irradiance_points(std::slice::from_ref(at))[0],
        }
    }

    /// Irradiance H (W/m²) at each of `points`, best called with the points of one receiver
    /// polygon (a mesh's vertices): the exact method shares the occluder search between
    /// neighbouring points. The result of each point does not depend on the others, up to
    /// rounding in rare near-degenerate cases; it is deterministic for given `points`.
    pub fn irradiance_points(&self, points: &[SurfacePoint]) -> Vec<DVec3> {
        self.evaluate(points, true, None).0
    }

    /// Irradiance H (W/m²) at the vertices of `mesh`, evaluated at `points` (one per vertex,
    /// [`evaluation_points`]): area emitters and the sky at the points, as
    /// [`Direct::irradiance_points`]; punctual lights unoccluded at the points times their
    /// visibility averaged over each vertex's fan ([`punctual_over_fans`]). Also the punctual
    /// lights' part of it (empty without punctual lights) and the area emitters' part, which
    /// the lightmap takes per sub-sample ([`TexelLights`]): `(all, punctual, area)`.
    pub(crate) fn irradiance_vertices(
        &self,
        mesh: &ReceiverMesh,
        points: &[SurfacePoint],
        mut light: Option<&mut [LightVector]>,
    ) -> (Vec<DVec3>, Vec<DVec3>, Vec<DVec3>) {
        let (mut h, area) = self.evaluate(points, false, light.as_deref_mut());
        if self.lights.is_empty() {
            return (h, Vec::new(), area);
        }
        let before = h.clone();
        let rays = punctual_over_fans(
            self.scene,
            self.vis,
            &self.lights,
            mesh,
            points,
            &mut h,
            light,
        );
        self.rays.fetch_add(rays, Ordering::Relaxed);
        let punctual = h.iter().zip(&before).map(|(a, b)| *a - *b).collect();
        (h, punctual, area)
    }

    /// [`Direct::irradiance_points`], with the punctual lights at the points or left out, and
    /// the area emitters' part of it; with
    /// `light`, each point's light vector ([`LightVector`]) is added to it: an area emitter's
    /// light takes the slant of its unoccluded part above the horizon
    /// ([`EmitterShape::slant`]), a punctual light's and a sky ray's their direction.
    fn evaluate(
        &self,
        points: &[SurfacePoint],
        punctual: bool,
        mut light: Option<&mut [LightVector]>,
    ) -> (Vec<DVec3>, Vec<DVec3>) {
        if self.method == DirectMethod::Sampled {
            return points
                .iter()
                .enumerate()
                .map(|(i, p)| {
                    let q = light.as_deref_mut().map(|l| &mut l[i]);
                    self.irradiance_sampled(p, punctual, q)
                })
                .unzip();
        }
        let mut h = vec![DVec3::ZERO; points.len()];
        let mut tally = Tally::default();
        let mut scale = vec![DVec3::ZERO; points.len()];
        let tree = ClusterTree::new(points);
        let mut scratch = Scratch::default();
        // Per point, the light tree's cut: the emitters to evaluate exactly (gathered per
        // emitter) and the bounded rest, added now.
        let mut wanted: Vec<Vec<u32>> = vec![Vec::new(); self.emitters.len()];
        let mut bounded = 0;
        for (i, q) in points.iter().enumerate() {
            let cut = self.tree.cut(&self.emitters, self.vis, q, self.light_error);
            h[i] += cut.bounded;
            if let Some(light) = light.as_deref_mut() {
                for (a, b) in light[i].iter_mut().zip(cut.bounded_light) {
                    *a += b;
                }
            }
            tally.rays += cut.rays;
            bounded += cut.bounded_nodes;
            for e in cut.exact {
                wanted[e as usize].push(i as u32);
            }
        }
        self.bounded.fetch_add(bounded, Ordering::Relaxed);
        for (ei, e) in self.emitters.iter().enumerate() {
            if wanted[ei].is_empty() {
                continue;
            }
            let start = Instant::now();
            let before = (tally.evaluations, tally.occluders, tally.fallbacks);
            let mut f_un = vec![0.0; points.len()];
            for &i in &wanted[ei] {
                let q = &points[i as usize];
                f_un[i as usize] = e.form_factor(q.p, q.n);
            }
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
                    if let Some(light) = light.as_deref_mut()
                        && let Some(u) = e.shape.slant(points[i].p, points[i].n)
                    {
                        add_light(&mut light[i], e.radiance * scale[i], u);
                    }
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
        let area = h.clone();
        for (i, (pt, h)) in points.iter().zip(&mut h).enumerate() {
            if !punctual {
                break;
            }
            for l in self.lights.iter().map(|&l| &self.scene.lights[l]) {
                let (value, r) = punctual_irradiance(l, self.vis, pt);
                *h += value;
                tally.rays += r;
                if let Some(light) = light.as_deref_mut() {
                    add_light(&mut light[i], value, slant(towards(l, pt.p), pt.n));
                }
            }
        }
        if let Some(sky) = &self.sky {
            sky.add_light(self.vis, points, &mut h, light);
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
        (h, area)
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
        scale: &mut [DVec3],
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
    ) -> DVec3 {
        tally.evaluations += 1;
        if candidates.is_empty() {
            return DVec3::splat(PI * f_unoccluded);
        }
        tally.candidates += candidates.len() as u64;
        let pieces = &self.occluders.pieces;
        let cut_out = candidates.iter().any(|&k| {
            let piece = &pieces[k as usize];
            piece.cut_out && piece.polygon != at.polygon
        });
        if cut_out {
            // An alpha-tested occluder in the way: shadow rays, which see through its holes.
            return self.fallback_visibility(e, f_unoccluded, at, tally) * (PI * f_unoccluded);
        }
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
            Some(_) if r.occluders == 0 => DVec3::splat(PI * f_unoccluded),
            Some(f) => DVec3::splat(PI * f),
            None => self.fallback_visibility(e, f_unoccluded, at, tally) * (PI * f_unoccluded),
        }
    }

    /// The exact method's fallback: the visible fraction of `e` at `at` from shadow rays (per
    /// channel: see-through surfaces tint it).
    fn fallback_visibility(
        &self,
        e: &AreaEmitter,
        f_unoccluded: f64,
        at: &SurfacePoint,
        tally: &mut Tally,
    ) -> DVec3 {
        tally.fallbacks += 1;
        let total = self.total_weight(at);
        let (visible, rays) = self.sampled_visibility(e, f_unoccluded, total, at);
        tally.rays += rays;
        visible
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
    ) -> (DVec3, u64) {
        let (p, n, p_ray) = (at.p, at.n, at.ray_origin);
        let mut rays = 0;
        let wanted =
            e.samples[0].len() as f64 * f * e.radiance.element_sum() / total.max(f64::MIN_POSITIVE);
        let mut level = 0;
        while level + 1 < e.samples.len() && e.samples[level + 1].len() as f64 >= wanted {
            level += 1;
        }
        let mut seen = DVec3::ZERO;
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
            seen += self
                .vis
                .transmitted_skipping(p_ray, s, [at.polygon, e.polygon])
                * w;
        }
        // When every sample is below the horizon the sliver that remains is taken as seen.
        (if all > 0.0 { seen / all } else { DVec3::ONE }, rays)
    }

    /// Sampled direct light at one point: exact unoccluded form factor x visibility fraction
    /// from shadow rays, spent in proportion to each emitter's contribution (at least one per
    /// visible emitter), so scenes with many small emitters stay cheap.
    fn irradiance_sampled(
        &self,
        at: &SurfacePoint,
        punctual: bool,
        mut light: Option<&mut LightVector>,
    ) -> (DVec3, DVec3) {
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
            h += e.radiance * (visible * (PI * f));
            if let Some(light) = light.as_deref_mut()
                && let Some(u) = e.shape.slant(p, n)
            {
                add_light(light, e.radiance * (visible * (PI * f)), u);
            }
        }
        let area = h;
        for l in self.lights.iter().map(|&l| &self.scene.lights[l]) {
            if !punctual {
                break;
            }
            let (value, r) = punctual_irradiance(l, self.vis, at);
            h += value;
            rays += r;
            if let Some(light) = light.as_deref_mut() {
                add_light(light, value, slant(towards(l, p), n));
            }
        }
        if let Some(sky) = &self.sky {
            sky.add_light(
                self.vis,
                std::slice::from_ref(at),
                std::slice::from_mut(&mut h),
                light.map(std::slice::from_mut),
            );
        }
        self.evaluations.fetch_add(evaluations, Ordering::Relaxed);
        self.rays.fetch_add(rays, Ordering::Relaxed);
        (h, area)
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
            light_tree_nodes: self.tree.len(),
            bounded: load(&self.bounded),
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
        // Flat to rounding, relative to the points' own extent.
        let flat = hi.z - lo.z <= crate::scene::tolerance::COINCIDENT * extent;
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

/// Direct irradiance H (W/m², linear RGB) at every vertex of `meshes`, one mesh per task: the
/// vertices of one receiver are evaluated together ([`Direct::irradiance_points`]).
pub fn direct_light(
    scene: &Scene,
    vis: &Visibility,
    direct: &Direct<'_>,
    meshes: &[ReceiverMesh],
    progress: &crate::progress::Progress<'_>,
) -> Vec<Vec<DVec3>> {
    direct_light_shadows(scene, vis, direct, meshes, false, progress).0
}

/// [`direct_light`], and the part of it the lightmap takes per sub-sample ([`TexelLights`]);
/// with `directional`, the light vector
/// at every vertex too ([`LightVector`]; empty without).
pub(crate) fn direct_light_shadows(
    scene: &Scene,
    vis: &Visibility,
    direct: &Direct<'_>,
    meshes: &[ReceiverMesh],
    directional: bool,
    progress: &crate::progress::Progress<'_>,
) -> (Vec<Vec<DVec3>>, Vec<Vec<LightVector>>, TexelLights) {
    let total_vertices: u64 = meshes.iter().map(|m| m.vertices.len() as u64).sum();
    let done = AtomicU64::new(0);
    // Per mesh: all the direct light, its light vectors, the punctual and the area part.
    type PerMesh = (Vec<DVec3>, Vec<LightVector>, Vec<DVec3>, Vec<DVec3>);
    let per_mesh: Vec<PerMesh> = meshes
        .par_iter()
        .map(|m| {
            let pts = evaluation_points(scene, vis, m);
            let mut light = vec![LightVector::default(); if directional { pts.len() } else { 0 }];
            let (out, punctual, area) =
                direct.irradiance_vertices(m, &pts, directional.then_some(&mut light[..]));
            let d = done.fetch_add(m.vertices.len() as u64, Ordering::Relaxed);
            progress("direct light", d + m.vertices.len() as u64, total_vertices);
            (out, light, punctual, area)
        })
        .collect();
    let (mut h, mut light) = (Vec::new(), Vec::new());
    let (mut punctual, mut area) = (Vec::new(), Vec::new());
    for (a, b, c, d) in per_mesh {
        h.push(a);
        light.push(b);
        punctual.push(c);
        area.push(d);
    }
    let mut texel_lights = TexelLights::default();
    if !direct.lights.is_empty() {
        texel_lights.lights = direct.lights.clone();
        texel_lights.punctual = punctual;
    }
    if !direct.emitters.is_empty() {
        texel_lights.emitters = direct.emitters.iter().map(|e| e.polygon).collect();
        texel_lights.emitters.sort_unstable();
        texel_lights.area = area;
        texel_lights.light_error =
            (direct.method == DirectMethod::Exact).then_some(direct.light_error);
    }
    (
        h,
        if directional { light } else { Vec::new() },
        texel_lights,
    )
}
