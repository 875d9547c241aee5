//! Discontinuity segments: where the illumination of each receiver polygon, or one of its
//! derivatives, is discontinuous (Heckbert, "Discontinuity meshing for radiosity", 1992;
//! Lischinski, Tampieri, Greenberg, "Discontinuity meshing for accurate radiosity", 1992).
//!
//! * **D0**: where a surface touches or crosses a receiver (a box standing on a floor), the
//!   contact segment. Always kept: it stops light leaking under the box.
//! * **VE / EV wedges** of every area emitter: an emitter vertex with an occluder edge, and an
//!   emitter edge with an occluder vertex, kept when the wedge is tangent to the occluder
//!   (silhouette edge or vertex) and has the whole emitter on one side (the extremal events that
//!   bound umbra and penumbra). EEE events are not traced.
//! * **Punctual lights**: the hard shadow boundaries of silhouette edges (central projection for
//!   point and spot lights, parallel projection for directional lights).
//!
//! Each wedge is intersected with the receivers its bounding box reaches (those whose bounding
//! box its plane crosses), clipped to the wedge and to the receiver's triangles (a large
//! receiver's, such as a ground plane cut around thousands of buildings, found through a grid
//! of them: [`BoxGrid`]), and only the pieces whose generator is really visible from the
//! receiver and from the emitter are kept (shadow rays at sample points, transitions bisected to
//! 1e-6 of the scene extent). Pieces are ranked by significance, the share of the receiver's
//! unoccluded irradiance that the wedge's emitter carries at the piece; pieces under the
//! threshold are dropped, and the weakest go first when the element budget would be exceeded.

use crate::geometry::{BoxGrid, point_polygon_form_factor, triangle_bounds};
use crate::light::{luminance, punctual_unoccluded};
use crate::scene::{LightKind, Scene};
use crate::visibility::Visibility;
use glam::{DVec2, DVec3, Vec3A};
use obvhs::aabb::Aabb;
use rayon::prelude::*;
use std::collections::BTreeMap;

/// Geometric tolerance of the stage, relative to the scene's extent: contacts closer than this
/// count as touching, and the mesher merges segments closer than this.
pub const TOLERANCE: f64 = 1e-6;

/// A surface parallel to a receiver and closer to its front than this (relative to the scene's
/// extent) is treated as lying on it: its outline is a contact (D0) line.
pub const NEAR_CONTACT: f64 = 1e-3;

/// What made a discontinuity segment.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, serde::Serialize)]
pub enum Kind {
    /// A surface touching or crossing the receiver (value discontinuity).
    D0,
    /// Emitter vertex x occluder edge.
    Ve,
    /// Emitter edge x occluder vertex.
    Ev,
    /// Silhouette edge of a punctual light.
    Punctual,
}

impl Kind {
    /// A jump in the light (a contact, a punctual light's hard shadow): it cannot be
    /// interpolated across, so the mesher always keeps it and values its vertices per side.
    pub fn is_jump(self) -> bool {
        matches!(self, Kind::D0 | Kind::Punctual)
    }
}

/// A discontinuity segment on one receiver polygon, in its plane coordinates.
#[derive(Clone, Debug, PartialEq)]
pub struct Segment {
    pub a: DVec2,
    pub b: DVec2,
    pub kind: Kind,
    /// Id of the event (wedge or contact) that made it; unique within one [`segments`] call.
    pub event: u32,
    /// Unoccluded irradiance of the wedge's light at the segment, relative to the brightest
    /// wedge piece of the scene (0..1); 1 for D0.
    pub significance: f64,
    /// The area light and occluder feature (edge or vertex) of a wedge piece, hashed: the
    /// pieces that bound one penumbra (the same occluder edge seen from different emitter
    /// vertices) share it. 0 for D0 lines and punctual lights' lines, which bound none.
    pub feature: u64,
}

/// Options of the discontinuity stage.
#[derive(Clone, Debug)]
pub struct DmOptions {
    /// Pieces whose significance (relative unoccluded irradiance) is below this are dropped.
    pub threshold: f64,
    /// At most this many wedge pieces are kept over the scene (the most significant).
    pub max_pieces: usize,
    /// Skip the wedges whose generator the light does not see ([`DmStats::unseen`]); `false`
    /// traces them all (to measure what the skip saves and loses).
    pub skip_unseen: bool,
}

/// Counters, reported in `--stats`.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct DmStats {
    /// Wedges traced (tangent to the occluder, emitter on one side).
    pub wedges: usize,
    /// D0 (contact) segments.
    pub d0: usize,
    /// Wedge pieces kept as constraints.
    pub kept: usize,
    /// Wedge pieces whose generator was hidden.
    pub hidden: usize,
    /// Wedges whose generator the light does not see at any of [`GENERATOR_SAMPLES`] points
    /// (an occluder behind a wall, in another room): not intersected with any receiver, as
    /// every piece of them would be hidden.
    pub unseen: usize,
    /// Wedge pieces below the significance threshold.
    pub dropped_threshold: usize,
    /// (Area emitter, occluder edge or vertex) pairs whose wedges were not built: no piece of
    /// them could reach the threshold (bound from the emitter's power and distance).
    pub culled: usize,
    /// Wedge pieces dropped to stay within the element budget.
    pub dropped_budget: usize,
    /// Constraint pieces spade refused (they would have crossed another; should be 0).
    pub refused: usize,
    /// Wedge pieces left out by the mesher because they run along a stronger line (the
    /// outline, a D0 line, a stronger wedge piece) within half an element, or all along the
    /// other boundary of their own penumbra.
    pub crowded: usize,
}

/// A convex region in a plane, given by half-spaces `m·(x - c) >= 0` (m in the plane).
struct Wedge {
    kind: Kind,
    /// A point of the wedge plane and its unit normal.
    origin: DVec3,
    normal: DVec3,
    half_spaces: Vec<(DVec3, DVec3)>,
    /// Points whose bounding box (clipped to the scene) contains the wedge.
    hull: Vec<DVec3>,
    /// The light it belongs to (area emitter polygon or punctual light index).
    light: Light,
    /// The generator: emitter point or light position, and the occluder edge or vertex.
    generator: Generator,
    /// Polygons that never receive this wedge (the emitter and the occluder feature's own).
    skip: Vec<usize>,
}

impl Wedge {
    /// [`Segment::feature`] of the wedge's pieces: FNV-1a over the light and the occluder
    /// feature's coordinates (an edge's ends in a fixed order), never 0 for an area light.
    fn feature(&self) -> u64 {
        let Light::Area(light) = self.light else {
            return 0;
        };
        let mut points = match self.generator {
            Generator::VertexEdge { a, b, .. } => vec![a, b],
            Generator::EdgeVertex { w, .. } => vec![w],
            Generator::DirectionEdge { .. } => return 0,
        };
        points.sort_by(|p, q| {
            p.to_array()
                .partial_cmp(&q.to_array())
                .unwrap_or(std::cmp::Ordering::Equal)
        });
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        let mut eat = |x: u64| {
            h ^= x;
            h = h.wrapping_mul(0x0000_0100_0000_01b3);
        };
        eat(light as u64);
        eat(points.len() as u64);
        for p in points {
            for c in p.to_array() {
                eat(c.to_bits());
            }
        }
        h.max(1)
    }
}

#[derive(Clone, Copy, Debug)]
enum Light {
    Area(usize),
    Punctual(usize),
}

#[derive(Clone, Copy, Debug)]
enum Generator {
    /// Emitter vertex (or point light) `v`, occluder edge `a-b`.
    VertexEdge { v: DVec3, a: DVec3, b: DVec3 },
    /// Emitter edge `e0-e1`, occluder vertex `w`.
    EdgeVertex { e0: DVec3, e1: DVec3, w: DVec3 },
    /// Direction `d` the light travels, occluder edge `a-b`.
    DirectionEdge { d: DVec3, a: DVec3, b: DVec3 },
}

/// Mesh connectivity of the whole scene with vertices welded by exact position.
struct Topology {
    /// Welded vertex positions.
    points: Vec<DVec3>,
    /// Edge (welded ids, low first) -> the triangles using it.
    edges: BTreeMap<(u32, u32), Vec<usize>>,
    /// Welded id -> neighbouring welded ids, sorted.
    neighbours: Vec<Vec<u32>>,
    /// Welded id -> polygons of the triangles using it, sorted.
    vertex_polygons: Vec<Vec<usize>>,
}

impl Topology {
    fn new(scene: &Scene) -> Topology {
        let mut ids: BTreeMap<[u64; 3], u32> = BTreeMap::new();
        let mut points = Vec::new();
        let mut edges: BTreeMap<(u32, u32), Vec<usize>> = BTreeMap::new();
        let mut corner_ids = Vec::with_capacity(scene.triangles.len());
        for t in &scene.triangles {
            let c = t.p.map(|p| {
                let key = [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()];
                *ids.entry(key).or_insert_with(|| {
                    points.push(p);
                    (points.len() - 1) as u32
                })
            });
            corner_ids.push(c);
        }
        let mut neighbours = vec![Vec::new(); points.len()];
        let mut vertex_polygons = vec![Vec::new(); points.len()];
        for (i, (t, c)) in scene.triangles.iter().zip(&corner_ids).enumerate() {
            let Some(poly) = t.polygon else { continue };
            for e in 0..3 {
                let (a, b) = (c[e], c[(e + 1) % 3]);
                edges.entry((a.min(b), a.max(b))).or_default().push(i);
                neighbours[a as usize].push(b);
                neighbours[b as usize].push(a);
                vertex_polygons[a as usize].push(poly);
            }
        }
        for n in &mut neighbours {
            n.sort_unstable();
            n.dedup();
        }
        for p in &mut vertex_polygons {
            p.sort_unstable();
            p.dedup();
        }
        Topology {
            points,
            edges,
            neighbours,
            vertex_polygons,
        }
    }
}

/// True when the faces at an edge are seen from different sides from `eye` (or the edge has one
/// face): a silhouette edge. `facing(t)` tells whether triangle `t` faces the eye. The back
/// sides of double-sided surfaces are left out: each coincides with its front and faces the
/// other way, so it would make every edge of the surface a silhouette (and its boundary edges
/// are silhouettes through the front alone).
fn is_silhouette(scene: &Scene, faces: &[usize], facing: impl Fn(usize) -> i8) -> bool {
    let (mut n, mut towards, mut away) = (0, false, false);
    for &t in faces.iter().filter(|&&t| !scene.is_back(t)) {
        n += 1;
        match facing(t) {
            1 => towards = true,
            -1 => away = true,
            _ => {}
        }
    }
    n == 1 || towards && away
}

fn sign(x: f64, tol: f64) -> i8 {
    if x > tol {
        1
    } else if x < -tol {
        -1
    } else {
        0
    }
}

/// Half-space through `c` with normal `m`, flipped so that `inside` is in it.
fn half_space(c: DVec3, m: DVec3, inside: DVec3) -> (DVec3, DVec3) {
    if m.dot(inside - c) >= 0.0 {
        (c, m)
    } else {
        (c, -m)
    }
}

/// Per receiver polygon: its discontinuity segments.
pub fn segments(
    scene: &Scene,
    vis: &Visibility,
    options: &DmOptions,
) -> (Vec<Vec<Segment>>, DmStats) {
    let extent = scene.extent();
    let tol = TOLERANCE * extent;
    let topo = Topology::new(scene);
    let index = PolygonIndex::new(scene);
    let mut stats = DmStats::default();

    // D0: contacts, per receiver.
    let d0: Vec<Vec<(DVec3, DVec3)>> = (0..scene.polygons.len())
        .into_par_iter()
        .map(|r| contacts(scene, &index, r, tol))
        .collect();

    // Wedges of every light, in a fixed order, in two passes. First the strongest area emitter
    // and the punctual lights: their brightest piece is a lower bound of the final peak. Then
    // the other area emitters, skipping every occluder feature too far from the emitter for
    // any of its pieces to reach `threshold` of that bound (their pieces would be dropped
    // below): significance before construction.
    let strongest = strongest_emitter(scene);
    let skip = options.skip_unseen;
    let first = wedges(scene, &topo, extent, Pass::Strongest(strongest), 0.0);
    let (mut pieces, hidden, unseen) = trace(scene, vis, &index, &first.wedges, 0, extent, skip);
    stats.hidden += hidden;
    stats.unseen += unseen;
    let peak_so_far = pieces.iter().map(|p| p.significance).fold(0.0, f64::max);
    let cutoff = options.threshold * peak_so_far;
    let rest = wedges(scene, &topo, extent, Pass::Others(strongest), cutoff);
    let (more, hidden, unseen) = trace(
        scene,
        vis,
        &index,
        &rest.wedges,
        first.wedges.len(),
        extent,
        skip,
    );
    pieces.extend(more);
    stats.hidden += hidden;
    stats.unseen += unseen;
    stats.wedges = first.wedges.len() + rest.wedges.len();
    stats.culled = first.culled + rest.culled;
    let wedge_count = stats.wedges;
    // Significance relative to the brightest piece: an event where its light is faint cannot
    // cause a visible change.
    let peak = pieces.iter().map(|p| p.significance).fold(0.0, f64::max);
    for p in &mut pieces {
        p.significance = if peak > 0.0 {
            p.significance / peak
        } else {
            0.0
        };
    }
    let before = pieces.len();
    pieces.retain(|p| p.significance >= options.threshold);
    stats.dropped_threshold = before - pieces.len();
    stats.kept = pieces.len();

    let mut out: Vec<Vec<Segment>> = vec![Vec::new(); scene.polygons.len()];
    let first_d0_event = wedge_count as u32;
    let mut event = first_d0_event;
    for (r, segs) in d0.iter().enumerate() {
        let frame = &scene.polygons[r].frame;
        for &(a, b) in segs {
            out[r].push(Segment {
                a: frame.plane_from_world(a),
                b: frame.plane_from_world(b),
                kind: Kind::D0,
                event,
                significance: 1.0,
                feature: 0,
            });
            event += 1;
            stats.d0 += 1;
        }
    }
    for p in pieces {
        let frame = &scene.polygons[p.polygon].frame;
        out[p.polygon].push(Segment {
            a: frame.plane_from_world(p.a),
            b: frame.plane_from_world(p.b),
            kind: p.kind,
            event: p.event,
            significance: p.significance,
            feature: p.feature,
        });
    }
    keep_most_significant(&mut out, options.max_pieces, &mut stats);
    (out, stats)
}

/// Keeps at most `max_pieces` wedge segments over the scene, the most significant (ties by
/// event, then polygon); D0 segments all stay. A polygon's kept wedge segments end up in event
/// order (then most significant first). Updates `kept` and `dropped_budget`. Applying it to
/// the output of [`segments`] with no limit gives the output of [`segments`] with this limit,
/// so the bake can trace the wedges before it knows its element budget.
pub fn keep_most_significant(
    segments: &mut [Vec<Segment>],
    max_pieces: usize,
    stats: &mut DmStats,
) {
    let mut wedge: Vec<(f64, u32, usize, usize)> = Vec::new();
    for (polygon, segs) in segments.iter().enumerate() {
        for (i, s) in segs.iter().enumerate() {
            if s.kind != Kind::D0 {
                wedge.push((s.significance, s.event, polygon, i));
            }
        }
    }
    if wedge.len() <= max_pieces {
        return;
    }
    // Most significant first; ties by event and polygon, then list position: a total order.
    wedge.sort_by(|x, y| {
        y.0.total_cmp(&x.0)
            .then(x.1.cmp(&y.1))
            .then(x.2.cmp(&y.2))
            .then(x.3.cmp(&y.3))
    });
    let mut keep: Vec<Vec<bool>> = segments.iter().map(|s| vec![false; s.len()]).collect();
    for &(_, _, polygon, i) in &wedge[..max_pieces] {
        keep[polygon][i] = true;
    }
    stats.dropped_budget += wedge.len() - max_pieces;
    stats.kept = stats.kept.saturating_sub(wedge.len() - max_pieces);
    for (segs, keep) in segments.iter_mut().zip(&keep) {
        let mut kept: Vec<Segment> = Vec::with_capacity(segs.len());
        let mut wedges: Vec<Segment> = Vec::new();
        for (s, &k) in std::mem::take(segs).into_iter().zip(keep) {
            if s.kind == Kind::D0 {
                kept.push(s);
            } else if k {
                wedges.push(s);
            }
        }
        wedges.sort_by(|x, y| {
            x.event
                .cmp(&y.event)
                .then(y.significance.total_cmp(&x.significance))
        });
        kept.extend(wedges);
        *segs = kept;
    }
}

/// A visible wedge piece on a receiver, before ranking.
struct Piece {
    polygon: usize,
    a: DVec3,
    b: DVec3,
    kind: Kind,
    event: u32,
    /// Unoccluded irradiance of its light at its midpoint (luminance, W/m²).
    significance: f64,
    /// See [`Segment::feature`].
    feature: u64,
}

/// Intersects each wedge with the receivers it reaches and keeps the visible pieces; wedge `k`
/// is event `first_event + k`. Returns the pieces, the number of hidden ones and the number of
/// unseen wedges.
fn trace(
    scene: &Scene,
    vis: &Visibility,
    index: &PolygonIndex,
    wedges: &[Wedge],
    first_event: usize,
    extent: f64,
    skip_unseen: bool,
) -> (Vec<Piece>, usize, usize) {
    let tol = TOLERANCE * extent;
    let traced: Vec<(Vec<Piece>, usize, usize)> = wedges
        .par_iter()
        .enumerate()
        .map(|(k, w)| {
            let mut out = Vec::new();
            let mut hidden = 0;
            if skip_unseen && !light_sees_generator(vis, w, extent) {
                return (out, hidden, 1);
            }
            let feature = w.feature();
            for r in index.query(&w.hull) {
                if w.skip.contains(&r)
                    || !index.plane_meets(r, w.origin, w.normal)
                    || !faces_light(scene, r, w)
                {
                    continue;
                }
                for (a, b) in clip_wedge_to_polygon(scene, index, r, w, tol) {
                    for (a, b, visible) in split_by_visibility(scene, vis, r, w, a, b, extent) {
                        if !visible {
                            hidden += 1;
                            continue;
                        }
                        let n = scene.polygons[r].frame.n;
                        let significance = unoccluded_irradiance(scene, w.light, (a + b) * 0.5, n);
                        out.push(Piece {
                            polygon: r,
                            a,
                            b,
                            kind: w.kind,
                            event: (first_event + k) as u32,
                            significance,
                            feature,
                        });
                    }
                }
            }
            (out, hidden, 0)
        })
        .collect();
    let mut pieces = Vec::new();
    let (mut hidden, mut unseen) = (0, 0);
    for (p, h, u) in traced {
        pieces.extend(p);
        hidden += h;
        unseen += u;
    }
    (pieces, hidden, unseen)
}

/// The area emitter with the most power (luminance of its radiance x area; ties: the first).
fn strongest_emitter(scene: &Scene) -> Option<usize> {
    let power = |p: usize| {
        let poly = &scene.polygons[p];
        luminance(scene.materials[poly.material].radiance) * poly.area
    };
    scene
        .emitters()
        .fold(None, |best: Option<usize>, e| match best {
            Some(b) if power(b) >= power(e) => Some(b),
            _ => Some(e),
        })
}

/// Which lights a call of [`wedges`] builds.
#[derive(Clone, Copy)]
enum Pass {
    /// This area emitter (if any) and every punctual light.
    Strongest(Option<usize>),
    /// Every area emitter but this one.
    Others(Option<usize>),
}

/// Wedges built, and the (emitter, occluder feature) pairs skipped by the significance bound.
struct Built {
    wedges: Vec<Wedge>,
    culled: usize,
}

/// Distance from `c` to the segment `a-b`.
fn distance_to_segment(c: DVec3, a: DVec3, b: DVec3) -> f64 {
    let ab = b - a;
    let t = if ab.length_squared() > 0.0 {
        ((c - a).dot(ab) / ab.length_squared()).clamp(0.0, 1.0)
    } else {
        0.0
    };
    c.distance(a + ab * t)
}

/// A BVH over polygon bounding boxes, for "which receivers can this reach" queries.
struct PolygonIndex {
    bvh: obvhs::bvh2::Bvh2,
    boxes: Vec<Aabb>,
    center: DVec3,
    /// Per polygon of at least [`GRID_TRIANGLES`] triangles, a grid of them in its plane.
    grids: Vec<Option<BoxGrid>>,
}

/// Polygons with at least this many triangles get a grid of them ([`grid_of_triangles`]): a
/// ground plane cut around thousands of buildings has tens of thousands, and every wedge that
/// reaches it would otherwise clip against each.
const GRID_TRIANGLES: usize = 32;

/// A polygon's triangle grid holds at most this many cell entries per triangle (its memory and the
/// cells a query visits stay linear in the triangles).
const GRID_ENTRIES_PER_TRIANGLE: usize = 16;

/// The grid of a polygon's triangles in its plane ([`BoxGrid`], cells about square, about one
/// per triangle), or `None` when their boxes would fill more than
/// [`GRID_ENTRIES_PER_TRIANGLE`] cells each on average (long slivers across the polygon):
/// then every triangle is tested, as without a grid.
fn grid_of_triangles(triangles: &[[DVec2; 3]]) -> Option<BoxGrid> {
    let boxes: Vec<(DVec2, DVec2)> = triangles.iter().map(triangle_bounds).collect();
    let min = boxes.iter().fold(DVec2::INFINITY, |m, b| m.min(b.0));
    let max = boxes.iter().fold(DVec2::NEG_INFINITY, |m, b| m.max(b.1));
    let size = (max - min).max(DVec2::splat(1e-300));
    let cell = (size.x * size.y / triangles.len() as f64)
        .sqrt()
        .max(size.x.max(size.y) / 1024.0);
    let dims = (
        ((size.x / cell).ceil() as usize).clamp(1, 1024),
        ((size.y / cell).ceil() as usize).clamp(1, 1024),
    );
    let cell = DVec2::splat(cell);
    (BoxGrid::entries(min, cell, dims, &boxes) <= GRID_ENTRIES_PER_TRIANGLE * triangles.len())
        .then(|| BoxGrid::new(min, cell, dims, &boxes))
}

impl PolygonIndex {
    fn new(scene: &Scene) -> PolygonIndex {
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
    fn plane_meets(&self, r: usize, origin: DVec3, normal: DVec3) -> bool {
        let b = &self.boxes[r];
        let (lo, hi) = (b.min.as_dvec3(), b.max.as_dvec3());
        let (c, h) = ((lo + hi) * 0.5 + self.center, (hi - lo) * 0.5);
        normal.dot(c - origin).abs() <= normal.abs().dot(h)
    }

    /// Polygons whose boxes meet the box of `points`, sorted.
    fn query(&self, points: &[DVec3]) -> Vec<usize> {
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

/// Contact segments on receiver `r`: other triangles touching, crossing or lying in its plane,
/// or hovering in front of it within [`NEAR_CONTACT`].
fn contacts(scene: &Scene, index: &PolygonIndex, r: usize, tol: f64) -> Vec<(DVec3, DVec3)> {
    let poly = &scene.polygons[r];
    let frame = &poly.frame;
    let near = NEAR_CONTACT * scene.extent();
    let corners: Vec<DVec3> = poly
        .triangles
        .iter()
        .flat_map(|&t| scene.triangles[t].p)
        .collect();
    let mut out = Vec::new();
    let in_front: Vec<DVec3> = corners
        .iter()
        .flat_map(|&c| [c, c + frame.n * near])
        .collect();
    for other in index.query(&in_front) {
        // The back side of a double-sided surface coincides with its front, which gives the
        // same contacts (the receiver's own back side gives none: its outline is the
        // receiver's).
        if other == r || scene.is_back_polygon(other) {
            continue;
        }
        let op = &scene.polygons[other];
        let height = |p: DVec3| frame.n.dot(p - frame.origin);
        let flat = op.triangles.iter().all(|&t| {
            scene.triangles[t]
                .p
                .iter()
                .all(|&p| (-tol..=near).contains(&height(p)))
        });
        let mut raw = Vec::new();
        if flat {
            // Coplanar: its outline is where a different surface starts. Hovering just in
            // front (a light fitted a hair below a ceiling): it hides the whole hemisphere but
            // a sliver, so the light jumps across its outline as at a contact.
            raw.extend(
                op.boundary
                    .iter()
                    .map(|[a, b]| (op.frame.world_from_plane(*a), op.frame.world_from_plane(*b))),
            );
        }
        for &t in op.triangles.iter().filter(|_| !flat) {
            let tri = &scene.triangles[t];
            let d = tri.p.map(height);
            if d.iter().any(|&x| x <= tol) && d.iter().any(|&x| x >= -tol) {
                let mut pts = Vec::new();
                for e in 0..3 {
                    let (i, j) = (e, (e + 1) % 3);
                    if d[i].abs() <= tol {
                        pts.push(tri.p[i]);
                    }
                    if (d[i] < -tol && d[j] > tol) || (d[i] > tol && d[j] < -tol) {
                        let s = d[i] / (d[i] - d[j]);
                        pts.push(tri.p[i] + (tri.p[j] - tri.p[i]) * s);
                    }
                }
                // The two farthest apart points span the contact.
                let mut best = (0.0, DVec3::ZERO, DVec3::ZERO);
                for i in 0..pts.len() {
                    for j in i + 1..pts.len() {
                        let l = pts[i].distance_squared(pts[j]);
                        if l > best.0 {
                            best = (l, pts[i], pts[j]);
                        }
                    }
                }
                if best.0 > tol * tol {
                    raw.push((best.1, best.2));
                }
            }
        }
        for (a, b) in raw {
            // Project onto the plane, then keep the part inside the polygon and off its
            // outline (a contact along the outline adds nothing).
            let a = a - frame.n * frame.n.dot(a - frame.origin);
            let b = b - frame.n * frame.n.dot(b - frame.origin);
            for (p, q) in clip_segment_to_polygon(scene, index, r, a, b, &[], tol) {
                if !on_outline(
                    poly,
                    frame.plane_from_world(p),
                    frame.plane_from_world(q),
                    10.0 * tol,
                ) {
                    out.push((p, q));
                }
            }
        }
    }
    out
}

/// True when the plane segment `a-b` lies along one of the polygon's boundary edges.
fn on_outline(poly: &crate::scene::Polygon, a: DVec2, b: DVec2, tol: f64) -> bool {
    let near = |x: DVec2, p: DVec2, q: DVec2| {
        let d = q - p;
        let t = ((x - p).dot(d) / d.length_squared().max(1e-300)).clamp(0.0, 1.0);
        x.distance(p + d * t) <= tol
    };
    poly.boundary
        .iter()
        .any(|[p, q]| near(a, *p, *q) && near(b, *p, *q) && near((a + b) * 0.5, *p, *q))
}

/// Clips the 3D segment `a-b` (in polygon `r`'s plane) to the polygon's triangles and to the
/// extra half-spaces; returns the pieces, merged where they touch.
fn clip_segment_to_polygon(
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

/// The wedges of every light, tangent to the occluders, in a fixed order.
///
/// `pass` says which lights; `cutoff` (a significance, W/m² of luminance) skips an area
/// emitter's wedges through an occluder edge or vertex where no piece could reach it. A piece
/// lies beyond the occluder feature, seen from the emitter point that generates it, so it is at
/// least the feature's distance from the emitter's centre less 3 emitter radii from every point
/// of the emitter; its unoccluded irradiance is then at most `L A / d²` (and never more than
/// `pi L`), with `L` the emitter's luminance and `A` its area. The same bound limits how far
/// beyond its feature a wedge's hull (the receivers queried) reaches.
fn wedges(scene: &Scene, topo: &Topology, extent: f64, pass: Pass, cutoff: f64) -> Built {
    let tol = 1e-9 * extent;
    let far = 4.0 * extent;
    let mut out = Vec::new();
    let mut culled = 0;
    let emitters: Vec<usize> = scene
        .emitters()
        .filter(|&e| match pass {
            Pass::Strongest(s) => Some(e) == s,
            Pass::Others(s) => Some(e) != s,
        })
        .collect();
    for &e in &emitters {
        let poly = &scene.polygons[e];
        let lum = luminance(scene.materials[poly.material].radiance);
        let corners: Vec<DVec3> = poly
            .boundary
            .iter()
            .map(|s| poly.frame.world_from_plane(s[0]))
            .collect();
        let centre = corners.iter().copied().sum::<DVec3>() / corners.len().max(1) as f64;
        let radius = corners
            .iter()
            .map(|c| c.distance(centre))
            .fold(0.0, f64::max);
        let reaches = |d: f64| {
            let d = (d - 3.0 * radius).max(0.0);
            let bound = if d > 0.0 {
                (lum * poly.area / (d * d)).min(std::f64::consts::PI * lum)
            } else {
                std::f64::consts::PI * lum
            };
            bound >= cutoff
        };
        // How far beyond a feature at distance `d` from the centre a wedge can still carry a
        // piece above `cutoff`: pieces farther out are dropped anyway, so receivers beyond it
        // need not be queried (`far` bounds the wedge's hull).
        let reach_from = |d: f64| {
            if cutoff > 0.0 {
                far.min((lum * poly.area / cutoff).sqrt() + 3.0 * radius + d)
            } else {
                far
            }
        };
        let ne = poly.frame.n;
        let verts: Vec<DVec3> = {
            let mut v: Vec<DVec3> = poly
                .boundary
                .iter()
                .map(|s| poly.frame.world_from_plane(s[0]))
                .collect();
            v.dedup_by(|a, b| a == b);
            v
        };
        let edges: Vec<(DVec3, DVec3)> = poly
            .boundary
            .iter()
            .map(|s| {
                (
                    poly.frame.world_from_plane(s[0]),
                    poly.frame.world_from_plane(s[1]),
                )
            })
            .collect();
        let in_front = |p: DVec3| ne.dot(p - poly.frame.origin) > tol;
        // The emitter's own polygon, and its back side if it is double-sided.
        let twin = scene.twin_polygon(e);
        let own = |p: Option<usize>| p == Some(e) || p.is_some() && p == twin;
        // VE: emitter vertex x occluder silhouette edge.
        for (&(wa, wb), faces) in &topo.edges {
            if faces.iter().all(|&t| own(scene.triangles[t].polygon)) {
                continue;
            }
            let (a, b) = (topo.points[wa as usize], topo.points[wb as usize]);
            if !in_front(a) && !in_front(b) {
                continue;
            }
            if !reaches(distance_to_segment(centre, a, b)) {
                culled += 1;
                continue;
            }
            let far = reach_from(a.distance(centre).max(b.distance(centre)));
            for &v in &verts {
                let facing = |t: usize| {
                    let tri = &scene.triangles[t];
                    sign(tri.normal.dot(v - tri.p[0]), tol)
                };
                if !is_silhouette(scene, faces, facing) {
                    continue;
                }
                let nw = (a - v).cross(b - v);
                let Some(nw) = nw.try_normalize() else {
                    continue;
                };
                // The whole emitter on one side of the wedge plane.
                let sides: Vec<i8> = verts.iter().map(|q| sign(nw.dot(*q - v), tol)).collect();
                if sides.contains(&1) && sides.contains(&-1) {
                    continue;
                }
                let mut skip = vec![e];
                skip.extend(faces.iter().filter_map(|&t| scene.triangles[t].polygon));
                out.push(vertex_edge_wedge(
                    Kind::Ve,
                    Light::Area(e),
                    v,
                    a,
                    b,
                    nw,
                    far,
                    skip,
                ));
            }
        }
        // EV: emitter edge x occluder silhouette vertex.
        for (w_id, w) in topo.points.iter().enumerate() {
            let w = *w;
            if topo.neighbours[w_id].is_empty() || !in_front(w) {
                continue;
            }
            if topo.vertex_polygons[w_id].iter().all(|&p| own(Some(p))) {
                continue;
            }
            if !reaches(w.distance(centre)) {
                culled += 1;
                continue;
            }
            let far = reach_from(w.distance(centre));
            for &(e0, e1) in &edges {
                let nw = (e1 - e0).cross(w - e0);
                let Some(nw) = nw.try_normalize() else {
                    continue;
                };
                let sides: Vec<i8> = topo.neighbours[w_id]
                    .iter()
                    .map(|&q| sign(nw.dot(topo.points[q as usize] - w), tol))
                    .collect();
                if sides.contains(&1) && sides.contains(&-1) {
                    continue;
                }
                let esides: Vec<i8> = verts.iter().map(|q| sign(nw.dot(*q - w), tol)).collect();
                if esides.contains(&1) && esides.contains(&-1) {
                    continue;
                }
                let (d0, d1) = ((w - e0).normalize(), (w - e1).normalize());
                let mut skip = vec![e];
                skip.extend(&topo.vertex_polygons[w_id]);
                out.push(Wedge {
                    kind: Kind::Ev,
                    origin: w,
                    normal: nw,
                    half_spaces: vec![
                        half_space(w, nw.cross(d0), w + d1),
                        half_space(w, nw.cross(d1), w + d0),
                    ],
                    hull: vec![w, w + d0 * far, w + d1 * far],
                    light: Light::Area(e),
                    generator: Generator::EdgeVertex { e0, e1, w },
                    skip,
                });
            }
        }
    }
    // Punctual lights: silhouette edges (in the first pass).
    let punctual = if matches!(pass, Pass::Strongest(_)) {
        &scene.lights[..]
    } else {
        &[]
    };
    for (li, light) in punctual.iter().enumerate() {
        for (&(wa, wb), faces) in &topo.edges {
            let (a, b) = (topo.points[wa as usize], topo.points[wb as usize]);
            let mut skip: Vec<usize> = faces
                .iter()
                .filter_map(|&t| scene.triangles[t].polygon)
                .collect();
            skip.sort_unstable();
            skip.dedup();
            match light.kind {
                LightKind::Directional => {
                    let d = light.direction;
                    let facing = |t: usize| sign(-scene.triangles[t].normal.dot(d), 1e-12);
                    if !is_silhouette(scene, faces, facing) {
                        continue;
                    }
                    let Some(nw) = (b - a).cross(d).try_normalize() else {
                        continue;
                    };
                    out.push(Wedge {
                        kind: Kind::Punctual,
                        origin: a,
                        normal: nw,
                        half_spaces: vec![
                            half_space(a, nw.cross(b - a), a + d),
                            half_space(a, nw.cross(d), b),
                            half_space(b, nw.cross(d), a),
                        ],
                        hull: vec![a, b, a + d * far, b + d * far],
                        light: Light::Punctual(li),
                        generator: Generator::DirectionEdge { d, a, b },
                        skip,
                    });
                }
                LightKind::Point | LightKind::Spot { .. } => {
                    let v = light.position;
                    let facing = |t: usize| {
                        let tri = &scene.triangles[t];
                        sign(tri.normal.dot(v - tri.p[0]), tol)
                    };
                    if !is_silhouette(scene, faces, facing) {
                        continue;
                    }
                    let Some(nw) = (a - v).cross(b - v).try_normalize() else {
                        continue;
                    };
                    let light = Light::Punctual(li);
                    out.push(vertex_edge_wedge(
                        Kind::Punctual,
                        light,
                        v,
                        a,
                        b,
                        nw,
                        far,
                        skip,
                    ));
                }
            }
        }
    }
    Built {
        wedges: out,
        culled,
    }
}

/// The wedge swept by the rays from point `v` through edge `a-b`, beyond the edge (unit
/// normal `nw` of its plane; `far` bounds its extent).
#[allow(clippy::too_many_arguments)]
fn vertex_edge_wedge(
    kind: Kind,
    light: Light,
    v: DVec3,
    a: DVec3,
    b: DVec3,
    nw: DVec3,
    far: f64,
    skip: Vec<usize>,
) -> Wedge {
    let (da, db) = ((a - v).normalize(), (b - v).normalize());
    Wedge {
        kind,
        origin: v,
        normal: nw,
        half_spaces: vec![
            half_space(a, nw.cross(b - a), a + da),
            half_space(a, nw.cross(da), b),
            half_space(b, nw.cross(db), a),
        ],
        hull: vec![a, b, a + da * far, b + db * far],
        light,
        generator: Generator::VertexEdge { v, a, b },
        skip,
    }
}

/// True when receiver `r` can be lit by the wedge's light at all (some of the light above its
/// plane, the receiver in front of the emitter).
fn faces_light(scene: &Scene, r: usize, w: &Wedge) -> bool {
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
fn clip_wedge_to_polygon(
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

/// Splits a wedge piece by whether its generator is visible from the receiver and from the
/// light: sample points, transitions bisected.
fn split_by_visibility(
    scene: &Scene,
    vis: &Visibility,
    r: usize,
    w: &Wedge,
    a: DVec3,
    b: DVec3,
    extent: f64,
) -> Vec<(DVec3, DVec3, bool)> {
    let n_r = scene.polygons[r].frame.n;
    let visible = |t: f64| generator_visible(vis, r, n_r, w, a + (b - a) * t, extent);
    const SAMPLES: usize = 9;
    let ts: Vec<f64> = (0..SAMPLES)
        .map(|k| (k as f64 + 0.5) / SAMPLES as f64)
        .collect();
    let labels: Vec<bool> = ts.iter().map(|&t| visible(t)).collect();
    let len = (b - a).length();
    let mut cuts = vec![0.0];
    let mut states = vec![labels[0]];
    for k in 1..SAMPLES {
        if labels[k] != labels[k - 1] {
            let (mut lo, mut hi) = (ts[k - 1], ts[k]);
            while (hi - lo) * len > 1e-6 * extent {
                let mid = 0.5 * (lo + hi);
                if visible(mid) == labels[k - 1] {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            cuts.push(0.5 * (lo + hi));
            states.push(labels[k]);
        }
    }
    cuts.push(1.0);
    (0..states.len())
        .map(|i| (a + (b - a) * cuts[i], a + (b - a) * cuts[i + 1], states[i]))
        .collect()
}

/// Points along a wedge's generator at which [`light_sees_generator`] looks.
pub const GENERATOR_SAMPLES: usize = 9;

/// Does the light see the wedge's generator at one of [`GENERATOR_SAMPLES`] points along it,
/// with the same rays [`generator_visible`] casts towards the light? A VE wedge: its emitter
/// vertex sees a point of the occluder edge; an EV wedge: the occluder vertex sees a point of
/// the emitter edge; a punctual light's: always (its pieces test it themselves). A wedge whose
/// generator the light does not see anywhere has no visible piece (up to visible stretches
/// shorter than the sample spacing), so it is not traced: in a house, the lamp of one room and
/// the furniture of the others.
fn light_sees_generator(vis: &Visibility, w: &Wedge, extent: f64) -> bool {
    let gap = 1e-4 * extent;
    let Light::Area(e) = w.light else {
        return true;
    };
    let clear = |p: DVec3, q: DVec3| {
        let d = q - p;
        let len = d.length();
        if len <= 2.0 * gap {
            return true;
        }
        let u = d / len;
        !vis.occluded_skipping(p + u * gap, q - u * gap, [e, usize::MAX])
    };
    let along =
        |a: DVec3, b: DVec3, k: usize| a + (b - a) * ((k as f64 + 0.5) / GENERATOR_SAMPLES as f64);
    match w.generator {
        Generator::VertexEdge { v, a, b } => {
            (0..GENERATOR_SAMPLES).any(|k| clear(along(a, b, k), v))
        }
        Generator::EdgeVertex { e0, e1, w } => {
            (0..GENERATOR_SAMPLES).any(|k| clear(w, along(e0, e1, k)))
        }
        Generator::DirectionEdge { .. } => true,
    }
}

/// Is the wedge's generator seen from receiver point `x`, and the light from the generator?
fn generator_visible(
    vis: &Visibility,
    r: usize,
    n_r: DVec3,
    w: &Wedge,
    x: DVec3,
    extent: f64,
) -> bool {
    let gap = 1e-4 * extent;
    let x_ray = x + n_r * (2.0 * vis.epsilon());
    let clear = |p: DVec3, q: DVec3, skip: [usize; 2]| {
        let d = q - p;
        let len = d.length();
        if len <= 2.0 * gap {
            return true;
        }
        let u = d / len;
        !vis.occluded_skipping(p + u * gap, q - u * gap, skip)
    };
    let light_skip = match w.light {
        Light::Area(e) => e,
        Light::Punctual(_) => usize::MAX,
    };
    match w.generator {
        Generator::VertexEdge { v, a, b } => {
            // The point of edge a-b on the line from v through x.
            let q = closest_on_line(v, x, a, b);
            clear(x_ray, q, [r, usize::MAX]) && clear(q, v, [light_skip, usize::MAX])
        }
        Generator::EdgeVertex { e0, e1, w: wv } => {
            let s = closest_on_line(x, wv, e0, e1);
            clear(x_ray, wv, [r, usize::MAX]) && clear(wv, s, [light_skip, usize::MAX])
        }
        Generator::DirectionEdge { d, a, b } => {
            let q = closest_on_line(x, x - d, a, b);
            let to_light = -d;
            clear(x_ray, q, [r, usize::MAX])
                && vis.unoccluded_towards(q + to_light * gap, to_light, usize::MAX)
        }
    }
}

/// The point of line `c-d` closest to line `p-q` (their intersection when they meet).
fn closest_on_line(p: DVec3, q: DVec3, c: DVec3, d: DVec3) -> DVec3 {
    let u = q - p;
    let v = d - c;
    let w0 = c - p;
    let (uu, uv, vv) = (u.dot(u), u.dot(v), v.dot(v));
    let den = uu * vv - uv * uv;
    if den.abs() < 1e-300 {
        return c;
    }
    let s = (uv * u.dot(w0) - uu * v.dot(w0)) / den;
    c + v * s.clamp(0.0, 1.0)
}

/// Unoccluded irradiance (luminance, W/m²) that `light` gives at `p` with normal `n`: for a
/// punctual light the shared model ([`punctual_unoccluded`]), spot cone and range included, so
/// an event where the light does not reach ranks 0.
fn unoccluded_irradiance(scene: &Scene, light: Light, p: DVec3, n: DVec3) -> f64 {
    match light {
        Light::Area(e) => {
            let poly = &scene.polygons[e];
            if poly.frame.n.dot(p - poly.frame.origin) <= 0.0 {
                return 0.0;
            }
            let f: f64 = poly
                .triangles
                .iter()
                .map(|&t| point_polygon_form_factor(p, n, &scene.triangles[t].p))
                .sum();
            std::f64::consts::PI * f * luminance(scene.materials[poly.material].radiance)
        }
        Light::Punctual(l) => punctual_unoccluded(&scene.lights[l], p, n).map_or(0.0, luminance),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
