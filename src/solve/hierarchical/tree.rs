//! The hierarchy: the leaves (mesh elements), the surface nodes above them per polygon, the
//! clusters above the polygons, each node's sample points and each surface node's outline.

use crate::geometry::triangle_area;
use crate::light::{NO_POLYGON, SurfacePoint};
use crate::mesh::ReceiverMesh;
use crate::scene::Scene;
use crate::visibility::Visibility;
use glam::{DVec2, DVec3};
use rayon::prelude::*;
use std::f64::consts::PI;

/// A leaf: one triangle of one receiver mesh.
#[derive(Clone, Debug)]
pub struct Element {
    /// Index into the `meshes` slice.
    pub(crate) mesh: usize,
    /// Triangle index in that mesh.
    pub(crate) triangle: usize,
    /// Index into [`Scene::polygons`].
    pub polygon: usize,
    /// World-space corners.
    pub p: [DVec3; 3],
    pub normal: DVec3,
    pub area: f64,
    pub rho: DVec3,
    /// Direct irradiance: the mean of the three vertices' exact values (W/m²).
    pub direct: DVec3,
    /// The mesh's vertex ids of the corners.
    pub(crate) v: [u32; 3],
}

/// A node of the hierarchy; it covers the elements `lo..hi`.
#[derive(Clone, Debug)]
pub struct Node {
    pub(crate) lo: u32,
    pub(crate) hi: u32,
    /// Children (both lower indices), `None` for a leaf.
    pub kids: Option<[u32; 2]>,
    /// The polygon of a surface node (or leaf), [`NO_POLYGON`] for a cluster.
    pub polygon: usize,
    /// Area, scene units².
    pub area: f64,
    /// Area-weighted reflectance.
    pub(crate) rho: DVec3,
    /// The largest direct irradiance of its elements (W/m², mean over RGB).
    pub(crate) direct: f64,
    pub(crate) min: DVec3,
    pub(crate) max: DVec3,
    /// Area-weighted centroid.
    pub(crate) center: DVec3,
    /// Bounding radius about `center`.
    pub(crate) radius: f64,
    /// Unit normal of a surface node; zero for a cluster.
    pub normal: DVec3,
    /// Projected areas (scene units²) along `+x, +y, +z` and `-x, -y, -z`: the sums over the
    /// node's elements of `area × max(0, ±n_axis)`; see
    /// [`projected_bound`](super::transfer::projected_bound).
    pub(crate) proj: [DVec3; 2],
}

/// A sample point of a node: where it is, its surface's normal, its ray origin, its polygon.
#[derive(Clone, Copy, Debug)]
pub(super) struct Sample {
    pub(super) p: DVec3,
    pub(super) n: DVec3,
    pub(super) ray: DVec3,
    pub(super) polygon: usize,
}

/// The element and cluster hierarchy of a set of receiver meshes.
#[derive(Clone, Debug)]
pub struct Hierarchy {
    /// Leaves, in node order (each node covers a contiguous range).
    pub elements: Vec<Element>,
    /// Nodes, children before parents; the last is the root.
    pub nodes: Vec<Node>,
    /// `leaf[e]`: the node of element `e`.
    pub(crate) leaf: Vec<u32>,
    pub(super) samples: Vec<Vec<Sample>>,
    /// Per surface node, its outline: the directed element edges whose reverse is not in the
    /// node (mesh vertex ids and world ends). Empty for clusters.
    pub(super) outline: Vec<Vec<Edge>>,
}

/// A directed edge of a surface node's outline: mesh vertex ids, world ends.
pub(super) type Edge = (u32, u32, DVec3, DVec3);

/// The outlines of every node, collinear runs merged ([`merge_collinear`]); empty for a
/// cluster. Interior edges appear once in each direction and cancel in Lambert's contour sum,
/// so the form factor of a whole surface node is the contour sum over its outline alone.
///
/// A polygon's surface nodes are numbered contiguously (children before parents), so each
/// run of nodes of one polygon is computed on its own, in parallel.
fn outlines(nodes: &[Node], elements: &[Element]) -> Vec<Vec<Edge>> {
    let mut runs = Vec::new();
    let mut start = 0;
    for i in 1..=nodes.len() {
        if i == nodes.len() || nodes[i].polygon != nodes[start].polygon {
            runs.push(start..i);
            start = i;
        }
    }
    let parts: Vec<Vec<Vec<Edge>>> = runs
        .into_par_iter()
        .map(|run| {
            if nodes[run.start].polygon == NO_POLYGON {
                return vec![Vec::new(); run.len()];
            }
            let raw = run_outlines(&nodes[run.clone()], run.start as u32, elements);
            raw.iter().map(|o| merge_collinear(o)).collect()
        })
        .collect();
    parts.into_iter().flatten().collect()
}

/// The outlines of the surface nodes `nodes`, numbered from `first`, children before parents
/// and all within `nodes`, each sorted by (from, to) vertex id.
fn run_outlines(nodes: &[Node], first: u32, elements: &[Element]) -> Vec<Vec<Edge>> {
    let mut out: Vec<Vec<Edge>> = Vec::with_capacity(nodes.len());
    for n in nodes {
        let edges = match n.kids {
            None => {
                let e = &elements[n.lo as usize];
                let mut edges: Vec<Edge> = (0..3)
                    .map(|i| (e.v[i], e.v[(i + 1) % 3], e.p[i], e.p[(i + 1) % 3]))
                    .collect();
                edges.sort_by_key(|e| (e.0, e.1));
                edges
            }
            Some([a, b]) => {
                // The children's outlines are sorted by (from, to): merged in order, and an edge
                // whose reverse is in the other child's outline is interior to the node.
                let (ea, eb) = (&out[(a - first) as usize], &out[(b - first) as usize]);
                let key = |e: &Edge| (e.0, e.1);
                let has =
                    |list: &[Edge], x: u32, y: u32| list.binary_search_by_key(&(x, y), key).is_ok();
                let mut all = Vec::with_capacity(ea.len() + eb.len());
                let (mut i, mut j) = (0, 0);
                while i < ea.len() || j < eb.len() {
                    let from_a = j == eb.len() || (i < ea.len() && key(&ea[i]) <= key(&eb[j]));
                    let (e, other) = if from_a {
                        i += 1;
                        (ea[i - 1], eb)
                    } else {
                        j += 1;
                        (eb[j - 1], ea)
                    };
                    if !has(other, e.1, e.0) {
                        all.push(e);
                    }
                }
                all
            }
        };
        out.push(edges);
    }
    out
}

/// The outline `edges` with every run of collinear edges through vertices of degree two merged
/// into one edge: Lambert's contour term of a straight edge is the sum of its pieces' terms
/// (they span one plane through the point), so the sum is unchanged and costs fewer terms (a
/// polygon boundary split at many mesh vertices becomes its few sides).
fn merge_collinear(edges: &[Edge]) -> Vec<Edge> {
    // The edges leaving and entering each vertex: indices sorted by (vertex, index), looked up
    // by binary search (a hash map of vectors allocated per vertex cost most of the build).
    let index = |end: fn(&Edge) -> u32| {
        let mut v: Vec<(u32, usize)> = edges.iter().enumerate().map(|(i, e)| (end(e), i)).collect();
        v.sort_unstable();
        v
    };
    let (from, into) = (index(|e| e.0), index(|e| e.1));
    let at = |list: &[(u32, usize)], v: u32| -> std::ops::Range<usize> {
        list.partition_point(|&(x, _)| x < v)..list.partition_point(|&(x, _)| x <= v)
    };
    let straight = |a: DVec3, b: DVec3, c: DVec3| {
        let (u, v) = (b - a, c - b);
        u.dot(v) > 0.0
            && u.cross(v).length_squared() <= 1e-24 * u.length_squared() * v.length_squared()
    };
    // The edge after each edge through a vertex joining only the two of them.
    let after: Vec<Option<usize>> = edges
        .iter()
        .map(|e| {
            let (out, inn) = (at(&from, e.1), at(&into, e.1));
            (out.len() == 1 && inn.len() == 1).then(|| from[out.start].1)
        })
        .collect();
    // Whether an edge continues the one before it straight on.
    let mut continues = vec![false; edges.len()];
    for (e, &j) in edges.iter().zip(&after) {
        if let Some(j) = j.filter(|&j| straight(e.2, e.3, edges[j].3)) {
            continues[j] = true;
        }
    }
    let mut used = vec![false; edges.len()];
    let mut out = Vec::new();
    // Runs from their first edge; then whatever is left (a closed loop cannot be straight).
    let heads = (0..edges.len()).filter(|&i| !continues[i]);
    for i in heads.chain(0..edges.len()) {
        if used[i] {
            continue;
        }
        used[i] = true;
        let (mut e, mut k) = (edges[i], i);
        // Straight on from the run's start, not only from the last edge.
        while let Some(j) = after[k].filter(|&j| !used[j] && straight(e.2, e.3, edges[j].3)) {
            used[j] = true;
            e = (e.0, edges[j].1, e.2, edges[j].3);
            k = j;
        }
        out.push(e);
    }
    out
}

struct Builder<'a> {
    scene: &'a Scene,
    items: Vec<Element>,
    elements: Vec<Element>,
    nodes: Vec<Node>,
    leaf: Vec<u32>,
}

impl Builder<'_> {
    fn leaf(&mut self, e: Element) -> u32 {
        let c = (e.p[0] + e.p[1] + e.p[2]) / 3.0;
        let (min, max) = (
            e.p[0].min(e.p[1]).min(e.p[2]),
            e.p[0].max(e.p[1]).max(e.p[2]),
        );
        let id = self.elements.len() as u32;
        let node = Node {
            lo: id,
            hi: id + 1,
            kids: None,
            polygon: e.polygon,
            area: e.area,
            rho: e.rho,
            direct: e.direct.element_sum() / 3.0,
            min,
            max,
            center: c,
            radius: e.p.iter().map(|q| q.distance(c)).fold(0.0, f64::max),
            normal: e.normal,
            proj: [
                e.normal.max(DVec3::ZERO) * e.area,
                (-e.normal).max(DVec3::ZERO) * e.area,
            ],
        };
        self.elements.push(e);
        self.leaf.push(self.nodes.len() as u32);
        self.nodes.push(node);
        (self.nodes.len() - 1) as u32
    }

    fn join(&mut self, a: u32, b: u32) -> u32 {
        let (na, nb) = (&self.nodes[a as usize], &self.nodes[b as usize]);
        let area = na.area + nb.area;
        let w = if area > 0.0 { na.area / area } else { 0.5 };
        let center = na.center * w + nb.center * (1.0 - w);
        let polygon = if na.polygon == nb.polygon {
            na.polygon
        } else {
            NO_POLYGON
        };
        let node = Node {
            lo: na.lo.min(nb.lo),
            hi: na.hi.max(nb.hi),
            kids: Some([a, b]),
            polygon,
            area,
            rho: na.rho * w + nb.rho * (1.0 - w),
            direct: na.direct.max(nb.direct),
            min: na.min.min(nb.min),
            max: na.max.max(nb.max),
            center,
            radius: (na.center.distance(center) + na.radius)
                .max(nb.center.distance(center) + nb.radius),
            normal: if polygon == NO_POLYGON {
                DVec3::ZERO
            } else {
                na.normal
            },
            proj: [na.proj[0] + nb.proj[0], na.proj[1] + nb.proj[1]],
        };
        self.nodes.push(node);
        (self.nodes.len() - 1) as u32
    }

    /// A surface tree over `items` (indices into `self.items`, all of one polygon).
    fn surface(&mut self, items: &mut [(DVec2, u32)]) -> u32 {
        if items.len() == 1 {
            let e = self.items[items[0].1 as usize].clone();
            return self.leaf(e);
        }
        let (lo, hi) = items.iter().fold(
            (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY)),
            |(lo, hi), &(c, _)| (lo.min(c), hi.max(c)),
        );
        let axis = usize::from(hi.y - lo.y > hi.x - lo.x);
        // The lower half by centroid along the axis (ties by item), in linear time: each half
        // is ordered again by its own split.
        let mid = items.len() / 2;
        items.select_nth_unstable_by(mid, |a, b| {
            a.0[axis].total_cmp(&b.0[axis]).then(a.1.cmp(&b.1))
        });
        let (l, r) = items.split_at_mut(mid);
        let a = self.surface(l);
        let b = self.surface(r);
        self.join(a, b)
    }

    /// A cluster tree over `polys`: (polygon bounding-box centre, that polygon's items).
    fn cluster(&mut self, polys: &mut [(DVec3, Vec<u32>)]) -> u32 {
        if polys.len() == 1 {
            // Each item with its centroid in the polygon's 2D frame.
            let frame = &self.scene.polygons[self.items[polys[0].1[0] as usize].polygon].frame;
            let mut items: Vec<(DVec2, u32)> = polys[0]
                .1
                .iter()
                .map(|&i| {
                    let e = &self.items[i as usize];
                    (frame.plane_from_world((e.p[0] + e.p[1] + e.p[2]) / 3.0), i)
                })
                .collect();
            return self.surface(&mut items);
        }
        let (lo, hi) = polys.iter().fold(
            (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
            |(lo, hi), (c, _)| (lo.min(*c), hi.max(*c)),
        );
        let ext = hi - lo;
        let axis = if ext.x >= ext.y && ext.x >= ext.z {
            0
        } else if ext.y >= ext.z {
            1
        } else {
            2
        };
        let mid = polys.len() / 2;
        polys.select_nth_unstable_by(mid, |a, b| {
            a.0[axis].total_cmp(&b.0[axis]).then(a.1.cmp(&b.1))
        });
        let (l, r) = polys.split_at_mut(mid);
        let a = self.cluster(l);
        let b = self.cluster(r);
        self.join(a, b)
    }
}
impl Hierarchy {
    /// Builds the hierarchy of `meshes` (their triangles are the leaves); `direct_h[m][v]` is
    /// the direct irradiance at vertex `v` of mesh `m`. `None` when no mesh has a triangle of
    /// positive area.
    pub fn build(
        scene: &Scene,
        vis: &Visibility,
        meshes: &[ReceiverMesh],
        direct_h: &[Vec<DVec3>],
    ) -> Option<Hierarchy> {
        // Per mesh, in parallel (the enclosure test casts rays): its elements and the centre
        // of its triangles' bounding box; then numbered in mesh order.
        let per_mesh: Vec<(Vec<Element>, DVec3)> = meshes
            .par_iter()
            .enumerate()
            .map(|(mi, m)| {
                let poly = &scene.polygons[m.polygon];
                let albedo = crate::scene::AlbedoOver::new(scene, m.polygon);
                let mut out = Vec::new();
                let (mut lo, mut hi) =
                    (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
                for (ti, t) in m.triangles.iter().enumerate() {
                    let p = t.map(|i| poly.frame.world_from_plane(m.vertices[i as usize]));
                    let area = triangle_area(&p);
                    if area.is_nan() || area <= 0.0 {
                        continue;
                    }
                    let direct = direct_h
                        .get(mi)
                        .map(|d| {
                            t.iter()
                                .map(|&i| d.get(i as usize).copied().unwrap_or(DVec3::ZERO))
                                .sum::<DVec3>()
                                / 3.0
                        })
                        .unwrap_or(DVec3::ZERO);
                    for q in &p {
                        lo = lo.min(*q);
                        hi = hi.max(*q);
                    }
                    if enclosed(scene, vis, &p, poly.frame.n, m.polygon) {
                        continue;
                    }
                    out.push(Element {
                        mesh: mi,
                        triangle: ti,
                        polygon: m.polygon,
                        p,
                        normal: poly.frame.n,
                        area,
                        rho: albedo.mean(&t.map(|i| m.vertices[i as usize])),
                        direct,
                        v: *t,
                    });
                }
                (out, (lo + hi) * 0.5)
            })
            .collect();
        let mut items = Vec::new();
        // Per polygon (in mesh order): its items.
        let mut groups: Vec<(DVec3, Vec<u32>)> = Vec::new();
        for (elements, centre) in per_mesh {
            if elements.is_empty() {
                continue;
            }
            let first = items.len() as u32;
            groups.push((centre, (first..first + elements.len() as u32).collect()));
            items.extend(elements);
        }
        if groups.is_empty() {
            return None;
        }
        let mut b = Builder {
            scene,
            items,
            elements: Vec::new(),
            nodes: Vec::new(),
            leaf: Vec::new(),
        };
        b.cluster(&mut groups);
        let mut area_before = Vec::with_capacity(b.elements.len() + 1);
        area_before.push(0.0);
        for e in &b.elements {
            area_before.push(area_before.last().copied().unwrap_or(0.0) + e.area);
        }
        let samples = b
            .nodes
            .par_iter()
            .map(|n| node_samples(n, &b.elements, &area_before, vis))
            .collect();
        let outline = outlines(&b.nodes, &b.elements);
        Some(Hierarchy {
            elements: b.elements,
            nodes: b.nodes,
            leaf: b.leaf,
            samples,
            outline,
        })
    }

    /// Per element, the mean of `at_vertices` (per mesh, per vertex, as the direct irradiance
    /// [`Hierarchy::build`] took) at its three corners.
    pub(crate) fn element_values(&self, at_vertices: &[Vec<DVec3>]) -> Vec<DVec3> {
        self.elements
            .iter()
            .map(|e| {
                let d = &at_vertices[e.mesh];
                e.v.iter()
                    .map(|&i| d.get(i as usize).copied().unwrap_or(DVec3::ZERO))
                    .sum::<DVec3>()
                    / 3.0
            })
            .collect()
    }

    /// The elements' area-weighted mean direct irradiance (W/m², mean over RGB).
    pub fn mean_direct(&self) -> f64 {
        let (sum, area) = self.elements.iter().fold((0.0, 0.0), |(s, a), e| {
            (s + e.area * e.direct.element_sum() / 3.0, a + e.area)
        });
        if area > 0.0 { sum / area } else { 0.0 }
    }

    /// The root node.
    pub(super) fn root(&self) -> u32 {
        (self.nodes.len() - 1) as u32
    }

    /// Number of cluster nodes (spanning several polygons).
    pub(super) fn clusters(&self) -> usize {
        self.nodes
            .iter()
            .filter(|n| n.polygon == NO_POLYGON)
            .count()
    }
}

/// True when an element faces only the inside of closed geometry: every one of a fixed set of
/// rays from its centroid (the normal and eight directions 60° from it) hits the back of a
/// surface. So the floor under a box standing on it, which no light reaches and no one sees,
/// neither receives nor reflects: it would otherwise dilute the radiosity of every coarse node
/// that contains it.
fn enclosed(scene: &Scene, vis: &Visibility, p: &[DVec3; 3], n: DVec3, polygon: usize) -> bool {
    let c = (p[0] + p[1] + p[2]) / 3.0;
    let origin = SurfacePoint::new(c, n, polygon, vis).ray_origin;
    let t = if n.x.abs() < 0.9 { DVec3::X } else { DVec3::Y };
    let u = n.cross(t).normalize();
    let v = n.cross(u);
    let (s, co) = (60f64.to_radians().sin(), 60f64.to_radians().cos());
    std::iter::once(n)
        .chain((0..8).map(|k| {
            let a = k as f64 * PI / 4.0;
            n * co + (u * a.cos() + v * a.sin()) * s
        }))
        .all(|d| {
            vis.first_hit(origin, d, f64::INFINITY)
                .is_some_and(|h| scene.triangles[h.triangle].normal.dot(d) > 0.0)
        })
}

/// Up to four sample points of a node (see the `hierarchical` module doc); `area_before[e]` is
/// the area of the elements before element `e` (one more entry than elements).
fn node_samples(
    n: &Node,
    elements: &[Element],
    area_before: &[f64],
    vis: &Visibility,
) -> Vec<Sample> {
    let at = |p: DVec3, e: &Element| {
        let sp = SurfacePoint::new(p, e.normal, e.polygon, vis);
        Sample {
            p,
            n: e.normal,
            ray: sp.ray_origin,
            polygon: e.polygon,
        }
    };
    let count = (n.hi - n.lo) as usize;
    if count == 1 {
        let e = &elements[n.lo as usize];
        let c = (e.p[0] + e.p[1] + e.p[2]) / 3.0;
        // Cowper's three-point rule, exact for quadratics (at barycentric (2/3, 1/6, 1/6)
        // and its permutations): the link's `K` is the samples' plain mean.
        return e.p.iter().map(|q| at((c + *q) * 0.5, e)).collect();
    }
    // The elements at the 1/8, 3/8, 5/8, 7/8 points of the node's area, not of its element
    // count: a discontinuity mesh's elements are smallest along its lines (a wall's foot, a
    // shadow's edge), where the light is least like the node's mean.
    let m = count.min(4);
    let range = &area_before[n.lo as usize..=n.hi as usize];
    let (first, total) = (range[0], range[count] - range[0]);
    // Each sample on an element of its own: a large element holding two of the points (a
    // node of one large and one small element) would hide the node's spread from the
    // variation test.
    let mut next = 0;
    (0..m)
        .map(|k| {
            let at_area = first + total * (2 * k + 1) as f64 / (2 * m) as f64;
            let i = range[1..]
                .partition_point(|&a| a <= at_area)
                .clamp(next, count - (m - k));
            next = i + 1;
            let e = &elements[n.lo as usize + i];
            at((e.p[0] + e.p[1] + e.p[2]) / 3.0, e)
        })
        .collect()
}
