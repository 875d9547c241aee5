//! The wedges of every light: VE and EV wedges of the area emitters through the occluders'
//! silhouette edges and vertices (culled by a bound on the significance their pieces could
//! reach), and the hard shadow wedges of punctual lights; the scene's welded mesh topology they
//! are found on.

use super::Kind;
use crate::light::luminance;
use crate::scene::{LightKind, Scene};
use glam::DVec3;
use std::collections::BTreeMap;

/// A convex region in a plane, given by half-spaces `m·(x - c) >= 0` (m in the plane).
pub(super) struct Wedge {
    pub(super) kind: Kind,
    /// A point of the wedge plane and its unit normal.
    pub(super) origin: DVec3,
    pub(super) normal: DVec3,
    pub(super) half_spaces: Vec<(DVec3, DVec3)>,
    /// Points whose bounding box (clipped to the scene) contains the wedge.
    pub(super) hull: Vec<DVec3>,
    /// The light it belongs to (area emitter polygon or punctual light index).
    pub(super) light: Light,
    /// The generator: emitter point or light position, and the occluder edge or vertex.
    pub(super) generator: Generator,
    /// Polygons that never receive this wedge (the emitter and the occluder feature's own).
    pub(super) skip: Vec<usize>,
}

impl Wedge {
    /// [`Segment::feature`](super::Segment::feature) of the wedge's pieces: FNV-1a over the light and the occluder
    /// feature's coordinates (an edge's ends in a fixed order), never 0 for an area light.
    pub(super) fn feature(&self) -> u64 {
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
pub(super) enum Light {
    Area(usize),
    Punctual(usize),
}

#[derive(Clone, Copy, Debug)]
pub(super) enum Generator {
    /// Emitter vertex (or point light) `v`, occluder edge `a-b`.
    VertexEdge { v: DVec3, a: DVec3, b: DVec3 },
    /// Emitter edge `e0-e1`, occluder vertex `w`.
    EdgeVertex { e0: DVec3, e1: DVec3, w: DVec3 },
    /// Direction `d` the light travels, occluder edge `a-b`.
    DirectionEdge { d: DVec3, a: DVec3, b: DVec3 },
}

/// Mesh connectivity of the whole scene with vertices welded by exact position: the occluders'
/// edges and vertices (alpha-tested triangles left out).
pub(super) struct Topology {
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
    pub(super) fn new(scene: &Scene) -> Topology {
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
            // An alpha-tested triangle's edges are not its shadow's outline: it casts no
            // wedges, and its shadow is left to the shadow rays, which see its holes.
            let Some(poly) = t.polygon.filter(|_| !scene.is_cut_out(i)) else {
                continue;
            };
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
pub(super) fn half_space(c: DVec3, m: DVec3, inside: DVec3) -> (DVec3, DVec3) {
    if m.dot(inside - c) >= 0.0 {
        (c, m)
    } else {
        (c, -m)
    }
}

/// Which lights a call of [`wedges`] builds.
#[derive(Clone, Copy)]
pub(super) enum Pass {
    /// This area emitter (if any) and every punctual light.
    Strongest(Option<usize>),
    /// Every area emitter but this one.
    Others(Option<usize>),
}

/// Wedges built, and the (emitter, occluder feature) pairs skipped by the significance bound.
pub(super) struct Built {
    pub(super) wedges: Vec<Wedge>,
    pub(super) culled: usize,
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

/// The wedges of every light, tangent to the occluders, in a fixed order.
///
/// `pass` says which lights; `cutoff` (a significance, W/m² of luminance) skips an area
/// emitter's wedges through an occluder edge or vertex where no piece could reach it. A piece
/// lies beyond the occluder feature, seen from the emitter point that generates it, so it is at
/// least the feature's distance from the emitter's centre less 3 emitter radii from every point
/// of the emitter; its unoccluded irradiance is then at most `L A / d²` (and never more than
/// `pi L`), with `L` the emitter's luminance and `A` its area. The same bound limits how far
/// beyond its feature a wedge's hull (the receivers queried) reaches.
pub(super) fn wedges(
    scene: &Scene,
    topo: &Topology,
    extent: f64,
    pass: Pass,
    cutoff: f64,
) -> Built {
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
