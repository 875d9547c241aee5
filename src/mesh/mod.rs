//! Receiver meshes: per polygon, a constrained Delaunay triangulation (spade) of its outline,
//! refined to a maximum element area.
//!
//! Every mesher produces the same [`ReceiverMesh`], so the solve, atlas and lightmap stages are
//! shared and comparisons between meshers are fair by construction. Refinement is Ruppert/Chew
//! Delaunay refinement as implemented by spade (Shewchuk, "Delaunay refinement algorithms for
//! triangular mesh generation", 2002).

pub mod arrangement;
mod lines;
mod safe_frame;

use lines::{Obstacles, keep_clear, merge_collinear};
use safe_frame::in_safe_frame;
pub use safe_frame::{MeshFailure, SAFE_EXTENT};

use crate::discontinuity::{Kind, Segment};
use crate::scene::{Polygon, Scene};
use glam::DVec2;
use rayon::prelude::*;
use spade::handles::FixedVertexHandle;
use spade::{
    AngleLimit, ConstrainedDelaunayTriangulation, Point2, RefinementParameters, Triangulation,
};

/// Which mesher builds the receiver meshes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Mesher {
    /// Quality Delaunay refinement of each polygon's outline to an area cap from the budget.
    Uniform,
    /// Discontinuity meshing: umbra, penumbra and contact lines as constraints, then the same
    /// refinement as uniform.
    #[default]
    Discontinuity,
    /// A-posteriori adaptive meshing: uniform start, split where the solved direct light varies
    /// most across an element or is missed most between its vertices, repeat to the budget.
    Adaptive,
}

/// What goes into a polygon's triangulation besides its outline (see [`triangulate_with`]).
#[derive(Clone, Copy, Debug, Default)]
pub struct Lines<'a> {
    /// Discontinuity segments in plane coordinates, inserted as constraints.
    pub segments: &'a [Segment],
    /// Merge tolerance, scene units.
    pub snap: f64,
    /// Wedge segments along a stronger line closer than this (scene units) are left out.
    pub clearance: f64,
    /// Extra vertices (plane coordinates) inserted before refinement: the light-driven splits.
    pub points: &'a [DVec2],
}

/// What [`triangulate_with`] did with its segments besides inserting them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Inserted {
    /// Constraint pieces spade refused (they would have crossed another; should be 0).
    pub refused: usize,
    /// Wedge segments left out because they run along a stronger line within the clearance
    /// (or, all of them, along the other boundary of their own penumbra).
    pub crowded: usize,
}

/// A triangulated receiver polygon. Coordinates are in the polygon's plane frame
/// ([`crate::scene::Polygon::frame`]); values are solved at its vertices.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ReceiverMesh {
    /// Index into [`Scene::polygons`].
    pub polygon: usize,
    /// Vertex positions in plane coordinates (scene units).
    pub vertices: Vec<DVec2>,
    /// Triangles, counter-clockwise in the plane (front side up).
    pub triangles: Vec<[u32; 3]>,
    /// The mesh edges that lie on discontinuity segments, with the kind and event id of the
    /// segment that made each (for debugging and the significance ranking). Vertex ids are those
    /// of the side kept by the first copy when a D0 line splits its vertices.
    pub constraints: Vec<Constraint>,
}

/// A mesh edge on a discontinuity segment.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Constraint {
    pub a: u32,
    pub b: u32,
    pub kind: Kind,
    /// [`Segment::event`] of the segment.
    pub event: u32,
}

impl ReceiverMesh {
    /// Total area of the triangles (scene units²).
    pub fn area(&self) -> f64 {
        self.triangles.iter().map(|t| self.triangle_area(t)).sum()
    }

    /// Area of the triangle `t` of this mesh (scene units²; its triangles wind
    /// counter-clockwise, so it is positive).
    pub fn triangle_area(&self, t: &[u32; 3]) -> f64 {
        crate::geometry::signed_area(&t.map(|i| self.vertices[i as usize]))
    }
}

/// Minimum angle for quality refinement, degrees.
pub(crate) const ANGLE_LIMIT_DEG: f64 = 25.0;

/// Triangulates one polygon without extra constraints; see [`triangulate_with`].
pub(crate) fn triangulate(
    id: usize,
    polygon: &Polygon,
    max_area: f64,
    vertex_cap: usize,
) -> ReceiverMesh {
    triangulate_with(id, polygon, Lines::default(), max_area, vertex_cap).0
}

/// Triangulates one polygon: its boundary and the discontinuity `lines.segments` (plane
/// coordinates) as constraints, the `lines.points` as vertices, refined so that no triangle is larger than `max_area` (scene units²) and,
/// where the constraints allow, none has an angle under [`ANGLE_LIMIT_DEG`]. At most
/// `vertex_cap` vertices are added by refinement.
///
/// Points closer than `lines.snap` (scene units; at least 1e-9 of the polygon's size) are merged,
/// and segments within `snap` of each other (or of the outline) become one: use the tolerance the
/// segments were computed to, so near-coincident events do not force slivers.
///
/// A wedge segment (any kind but D0) that runs along the outline, a D0 line or a stronger wedge
/// segment (higher [`Segment::significance`]), both its ends within `lines.clearance`
/// of it, is left out: two constraints closer than an element cannot both be resolved, and
/// Delaunay refinement splits such a pair against each other until its triangles have good
/// angles (a thin slab's penumbra line 1 cm from its contact line took three times the budget).
/// Use about half an element's side; segments that only meet or cross stay, except along the
/// other boundary of their own penumbra (`Obstacles::apart_from_its_pair`).
///
/// The constraints go through [`arrangement::build`] first, so they never cross when inserted
/// with spade's `try_add_constraint`. Faces outside the polygon (holes, concavities) are dropped
/// by testing each face's centroid against the polygon's own triangles (spade's
/// `exclude_outer_faces` is wrong once interior constraints exist). Vertices on D0 (contact)
/// segments are split, one copy per side, so values never interpolate across a contact.
/// Returns the mesh and what became of the segments ([`Inserted`]).
///
/// A polygon whose extent is outside [`SAFE_EXTENT`] is triangulated in a frame scaled into it
/// (`safe_frame::in_safe_frame`). A panic of the triangulation (spade's refinement panics on a loss of
/// precision) unwinds as a [`MeshFailure`] that names the polygon.
pub fn triangulate_with(
    id: usize,
    polygon: &Polygon,
    lines: Lines<'_>,
    max_area: f64,
    vertex_cap: usize,
) -> (ReceiverMesh, Inserted) {
    in_safe_frame(
        id,
        polygon,
        lines,
        max_area,
        vertex_cap,
        triangulate_in_frame,
    )
}

/// [`triangulate_with`] in the polygon's own frame.
fn triangulate_in_frame(
    id: usize,
    polygon: &Polygon,
    lines: Lines<'_>,
    max_area: f64,
    vertex_cap: usize,
) -> (ReceiverMesh, Inserted) {
    let Lines {
        segments,
        snap,
        clearance,
        points,
    } = lines;
    let (lo, hi) = polygon.triangles_plane.iter().flatten().fold(
        (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    let diameter = (hi - lo).length().max(1e-300);
    let tol = (1e-9 * diameter).max(snap);
    // The outline with collinear runs merged, and the segments kept clear of it by `gap`: a
    // point of the outline between two collinear outline edges is, after rounding, a hair
    // inside or outside their line; spade's convex hull then bridges it with a zero-area face
    // outside the polygon, which refinement splits without end.
    let outline = merge_collinear(&polygon.boundary);
    let gap = (0.05 * max_area.max(0.0).sqrt()).max(tol * 10.0);
    // A hard shadow line keeps to twice the snapping distance from the outline: a strip of
    // shadow a few centimetres wide at a wall's foot still gets its line (at ten times, a real
    // city's 7 cm strips were left out and their walls baked dark in fans from the foot).
    let jump_gap = gap.min(tol * 2.0);
    // Tags: `None` for the outline, the segment's kind and event otherwise.
    type Tagged = (DVec2, DVec2, Option<(Kind, u32)>);
    let mut input: Vec<Tagged> = outline.iter().map(|[a, b]| (*a, *b, None)).collect();
    // The jumps in the light first (D0 contacts, punctual lights' hard shadows: never left
    // out, they cannot be interpolated), then the wedges strongest first, each kept clear of
    // what went before.
    let jumps = Kind::is_jump;
    let mut order: Vec<&Segment> = segments.iter().collect();
    order.sort_by(|s, t| {
        jumps(t.kind)
            .cmp(&jumps(s.kind))
            .then(t.significance.total_cmp(&s.significance))
    });
    let mut obstacles = Obstacles::new(lo, hi, clearance, order.len() + outline.len());
    for &[p, q] in &outline {
        obstacles.push(p, q, 0);
    }
    let mut crowded = 0;
    for s in order {
        let pieces = if jumps(s.kind) {
            vec![(s.a, s.b)]
        } else if obstacles.along(s.a, s.b) {
            Vec::new()
        } else {
            obstacles.apart_from_its_pair(s.a, s.b, s.feature)
        };
        if pieces.is_empty() {
            crowded += 1;
        }
        for (a, b) in pieces {
            // A hard shadow line kept beside the outline costs a row of thin elements; one left
            // out, or pulled away from it, lets the outline's vertices carry the other side's
            // light over whole elements (a roof's strip of shadow along its parapet darkened
            // it all). A contact line there mostly bounds a buried strip (a wall's foot on a
            // floor that runs under it), where the thin row would buy nothing.
            let punctual = s.kind == Kind::Punctual;
            let gap = if punctual { jump_gap } else { gap };
            if let Some((a, b)) = keep_clear(a, b, &outline, gap, punctual) {
                input.push((a, b, Some((s.kind, s.event))));
                obstacles.push(a, b, s.feature);
            }
        }
    }
    let arr = arrangement::build(&input, tol);
    let mut cdt = ConstrainedDelaunayTriangulation::<Point2<f64>>::new();
    let handles: Vec<Option<FixedVertexHandle>> = arr
        .points
        .iter()
        .map(|p| cdt.insert(Point2::new(p.x, p.y)).ok())
        .collect();
    let mut refused = 0;
    for &(a, b, _) in &arr.edges {
        if let (Some(va), Some(vb)) = (handles[a as usize], handles[b as usize])
            && va != vb
            && cdt.try_add_constraint(va, vb).is_empty()
            && !cdt.exists_constraint(va, vb)
        {
            refused += 1;
        }
    }
    for p in points {
        if polygon.contains(*p) {
            let _ = cdt.insert(Point2::new(p.x, p.y));
        }
    }
    // A polygon no larger than one element, with nothing inside, stays its outline's
    // triangulation: refining its slivers for their angles (a tessellated sphere's poles) would
    // spend the budget where the light is smooth at the element's scale anyway.
    let refine =
        polygon.area > max_area || !arr.edges.iter().all(|e| e.2.is_none()) || !points.is_empty();
    if refine && cdt.num_vertices() >= 3 && !cdt.all_vertices_on_line() {
        // Two passes: the area cap first, then the angles with at most half as many vertices
        // again. In one pass, constraints that meet at small angles or run close together (a
        // thin slab's contact and penumbra lines) can take every vertex the cap allows in
        // fans around them and leave the rest of the polygon coarse.
        let params = |angle: AngleLimit, vertices: usize| {
            RefinementParameters::<f64>::new()
                .with_angle_limit(angle)
                .with_max_allowed_area(max_area.max(polygon.area * 1e-9))
                .with_min_required_area(max_area * 1e-3)
                .with_max_additional_vertices(vertices)
                .exclude_outer_faces(segments.is_empty())
        };
        let before = cdt.num_vertices();
        cdt.refine(params(AngleLimit::from_deg(0.0), vertex_cap));
        let added = cdt.num_vertices() - before;
        let angle_cap = (added / 2).max(vertex_cap / 4);
        cdt.refine(params(AngleLimit::from_deg(ANGLE_LIMIT_DEG), angle_cap));
    }
    let (mut mesh, remap) = inside_faces(id, polygon, &cdt);
    let mut constraint_edges: Vec<(u32, u32)> = cdt
        .undirected_edges()
        .filter(|e| e.is_constraint_edge())
        .filter_map(|e| {
            let [a, b] = e.vertices().map(|v| remap[v.fix().index()]);
            (a != u32::MAX && b != u32::MAX).then_some((a.min(b), a.max(b)))
        })
        .collect();
    // Follow each segment's arrangement edge along the final constraint edges (refinement may
    // have split it) to tag them with the segment's kind and event.
    constraint_edges.sort_unstable();
    constraint_edges.dedup();
    let mut along: Vec<Vec<u32>> = vec![Vec::new(); mesh.vertices.len()];
    for &(a, b) in &constraint_edges {
        along[a as usize].push(b);
        along[b as usize].push(a);
    }
    for &(pa, pb, tag) in &arr.edges {
        let Some((kind, event)) = tag else { continue };
        let final_id = |p: u32| {
            handles[p as usize]
                .map(|h| remap[h.index()])
                .filter(|&i| i != u32::MAX)
        };
        let (Some(mut cur), Some(end)) = (final_id(pa), final_id(pb)) else {
            continue;
        };
        let target = mesh.vertices[end as usize];
        for _ in 0..along.len() {
            if cur == end {
                break;
            }
            let here = mesh.vertices[cur as usize];
            let dir = (target - here).normalize_or_zero();
            let next = along[cur as usize].iter().copied().find(|&n| {
                let step = mesh.vertices[n as usize] - here;
                step.length() > 0.0
                    && step.normalize().dot(dir) > 1.0 - 1e-6
                    && mesh.vertices[n as usize].distance(target) < here.distance(target)
            });
            let Some(next) = next else { break };
            mesh.constraints.push(Constraint {
                a: cur,
                b: next,
                kind,
                event,
            });
            cur = next;
        }
    }
    // Cut along the lines where the light jumps (D0 contacts, punctual lights' hard shadows),
    // and at their vertices also along every other discontinuity line that leaves them: where
    // an occluder's edge touches the receiver (a box corner on the floor) the umbra and
    // penumbra lines start at the contact, the penumbra there is zero wide, and one vertex
    // value cannot be both the lit and the shadowed limit.
    let mut on_jump = vec![false; mesh.vertices.len()];
    for c in mesh.constraints.iter().filter(|c| jumps(c.kind)) {
        on_jump[c.a as usize] = true;
        on_jump[c.b as usize] = true;
    }
    let mut cuts: Vec<(u32, u32)> = mesh
        .constraints
        .iter()
        .filter(|c| jumps(c.kind) || on_jump[c.a as usize] || on_jump[c.b as usize])
        .map(|c| (c.a.min(c.b), c.a.max(c.b)))
        .collect();
    if !cuts.is_empty() {
        cuts.sort_unstable();
        cuts.dedup();
        split_along(&mut mesh, &cuts);
    }
    (mesh, Inserted { refused, crowded })
}

/// Duplicates the vertices on the `cuts` edges so that the triangles on either side of a cut
/// have their own copy: the fan around each such vertex is split into the groups connected
/// through uncut edges, and every group but the first gets a new vertex at the same place.
fn split_along(mesh: &mut ReceiverMesh, cuts: &[(u32, u32)]) {
    let cut = |a: u32, b: u32| cuts.binary_search(&(a.min(b), a.max(b))).is_ok();
    let mut on_cut = vec![false; mesh.vertices.len()];
    for &(a, b) in cuts {
        on_cut[a as usize] = true;
        on_cut[b as usize] = true;
    }
    let mut incident: Vec<Vec<usize>> = vec![Vec::new(); mesh.vertices.len()];
    for (t, tri) in mesh.triangles.iter().enumerate() {
        for &v in tri {
            if on_cut[v as usize] {
                incident[v as usize].push(t);
            }
        }
    }
    // Per vertex: its triangles, grouped through the uncut edges they share at it. Each group
    // is named by its first triangle (in `tris` order), so the copies do not depend on the
    // order the unions run in.
    let mut group: Vec<usize> = Vec::new();
    let mut by_neighbour: Vec<(u32, usize)> = Vec::new();
    let mut copy_of: Vec<u32> = Vec::new();
    for (v, tris) in incident.iter().enumerate() {
        if tris.len() < 2 {
            continue;
        }
        fn root(g: &mut [usize], mut i: usize) -> usize {
            while g[i] != i {
                g[i] = g[g[i]];
                i = g[i];
            }
            i
        }
        group.clear();
        group.extend(0..tris.len());
        // Two triangles at v share an edge (v, u) when both have u: sorted by u, they are
        // neighbours in this list (linear in the fan, however many triangles meet at v).
        by_neighbour.clear();
        for (i, &t) in tris.iter().enumerate() {
            for &u in &mesh.triangles[t] {
                if u != v as u32 {
                    by_neighbour.push((u, i));
                }
            }
        }
        by_neighbour.sort_unstable();
        for pair in by_neighbour.windows(2) {
            let [(u, i), (w, j)] = [pair[0], pair[1]];
            if u == w && i != j && !cut(v as u32, u) {
                let (ri, rj) = (root(&mut group, i), root(&mut group, j));
                group[ri.max(rj)] = ri.min(rj);
            }
        }
        let first = root(&mut group, 0);
        copy_of.clear();
        copy_of.resize(tris.len(), u32::MAX);
        for (i, &t) in tris.iter().enumerate() {
            let r = root(&mut group, i);
            if r == first {
                continue;
            }
            if copy_of[r] == u32::MAX {
                mesh.vertices.push(mesh.vertices[v]);
                copy_of[r] = (mesh.vertices.len() - 1) as u32;
            }
            let id = copy_of[r];
            for c in mesh.triangles[t].iter_mut() {
                if *c == v as u32 {
                    *c = id;
                }
            }
        }
    }
}

/// The element count may exceed the budget by this fraction.
pub(crate) const BUDGET_SLACK: f64 = 0.05;

/// When not every discontinuity fits, the wedge pieces kept may take at most this share of what
/// the coarsest meshing without them leaves of the budget; the rest refines between the lines
/// (at 0.75 the Cornell box's walls got 8 elements at a budget of 250: 20% error where lit).
pub(crate) const DM_SHARE: f64 = 0.5;

/// The coarsest area cap the budget search uses, as a multiple of the average element area
/// (elements 8x the side of a uniform mesh's): coarser meshes cost no fewer elements on
/// real scenes, only quality (at 16x, box-grid-40's 9 600 polygons alone overran its budget).
const COARSEST: f64 = 64.0;

/// The share of the budget above the coarsest meshing that the discontinuity mesher leaves to
/// refinement where the light varies most.
pub(crate) const LIGHT_SHARE: f64 = 0.2;

/// Rounds of light-driven refinement after discontinuity meshing (each evaluates the direct
/// light on the whole mesh).
pub(crate) const LIGHT_ROUNDS: usize = 3;

/// Elements split by [`adaptive`] and by the discontinuity mesher's refinement when their
/// error (the light's spread over their vertices, or the light they miss between them: see
/// `refine_by_light`) is more than this fraction of the brightest vertex.
pub(crate) const LIGHT_TOLERANCE: f64 = 0.01;

/// The light-driven refinement looks for light missed between an element's vertices in the
/// elements larger than this fraction of the average element: in smaller ones the vertices
/// sample the light finely enough. On interior-20 and a two-room house this found the same
/// meshes as looking in every element, and the extra direct light costs 0.12 s of mesh stage on
/// bevy_DepthOfFieldExample (2048 emitters) instead of 0.95 s; above the average element
/// (1.0), the two-room house at 2 000 elements showed 92% of its lamps' light instead of 96%.
pub(crate) const MISSED_AREA: f64 = 0.5;

/// The direct light (W/m², linear RGB) at every vertex of a set of meshes.
pub(crate) type Evaluate<'a> = dyn Fn(&[ReceiverMesh]) -> Vec<Vec<glam::DVec3>> + 'a;

/// Most meshings of the whole scene [`to_budget`] tries while looking for its area cap.
const BUDGET_PASSES: usize = 10;

/// The elements of a set of meshes.
pub(crate) fn element_count(meshes: &[ReceiverMesh]) -> usize {
    meshes.iter().map(|m| m.triangles.len()).sum()
}

/// Meshes every polygon with `mesh_one(polygon, max_area, vertex_cap)` at one area cap (scene
/// units²), chosen so that the whole scene has at most `most` triangles (usually
/// [`with_slack`]`(budget)`) and not many fewer than `budget`.
///
/// The count falls with the cap, but not as `1/cap`: constraints and the angle bound grade the
/// mesh, so part of it does not scale. The search starts at area/budget and brackets the
/// budget between a cap that gives too many and one that gives too few, then interpolates in
/// log(cap), log(count) within the bracket (bisecting when that stalls). The cap stays within
/// [`COARSEST`] times area/budget; when even that gives too many, that meshing is returned and
/// the caller decides what to drop.
fn to_budget<F>(scene: &Scene, budget: usize, most: usize, mesh_one: F) -> (Vec<ReceiverMesh>, f64)
where
    F: Fn(usize, f64, usize) -> ReceiverMesh + Sync,
{
    let budget = budget.max(1) as f64;
    let most = most as f64;
    let mesh_all = |max_area: f64| -> (Vec<ReceiverMesh>, f64) {
        let meshes = mesh_at(scene, max_area, &mesh_one);
        let count = element_count(&meshes) as f64;
        (meshes, count)
    };
    let first = element_area(scene, budget as usize);
    // Past COARSEST only when even that is over the budget: then as coarse as it gets.
    let total_area: f64 = scene.polygons.iter().map(|p| p.area).sum();
    let (lowest, highest) = (first * 1e-3, total_area.max(first * COARSEST));
    let mut cap = first;
    let (mut best, mut best_count) = mesh_all(cap);
    let mut best_cap = cap;
    // Bracket: (cap, count) with too many elements, and with too few.
    let mut over: Option<(f64, f64)> = None;
    let mut under: Option<(f64, f64)> = None;
    let mut last = (cap, best_count);
    let mut previous: Option<(f64, f64)> = None;
    for _ in 1..BUDGET_PASSES {
        let (c, n) = last;
        if n == 0.0 || (n <= most && n >= budget * 0.9) {
            break;
        }
        if n > most {
            over = Some(last);
        } else {
            under = Some(last);
        }
        // Aim a little under the budget (and under `most`, when that is the tighter bound):
        // the interpolation is not exact.
        let target = (budget * (1.0 - BUDGET_SLACK / 2.0)).min(most * (1.0 - BUDGET_SLACK / 4.0));
        let next = match (over, under) {
            (Some((c0, n0)), Some((c1, n1))) => {
                let slope = (n1.max(1.0) / n0).ln() / (c1 / c0).ln();
                let t = (target / n0).ln() / slope;
                let guess = c0 * t.exp();
                // Stay well inside the bracket, else bisect.
                let (a, b) = (c0.ln(), c1.ln());
                let g = guess.ln();
                if slope < 0.0
                    && g.is_finite()
                    && (g - a) / (b - a) > 0.1
                    && (g - a) / (b - a) < 0.9
                {
                    guess
                } else {
                    ((a + b) / 2.0).exp()
                }
            }
            // Not bracketed yet: extrapolate the last step in log-log (at first assume count
            // ∝ 1/cap), stepping 2x to 64x.
            _ => {
                let slope = match previous {
                    Some((c0, n0)) if c0 != c && n0 > 0.0 && n > 0.0 => {
                        ((n / n0).ln() / (c / c0).ln()).min(-1.0 / 64.0)
                    }
                    _ => -1.0,
                };
                let step = ((target / n).ln() / slope).exp();
                if n > most {
                    c * step.clamp(2.0, 64.0)
                } else {
                    c * step.clamp(1.0 / 64.0, 0.5)
                }
            }
        }
        .clamp(lowest, highest);
        if next == c {
            break;
        }
        cap = next;
        let (meshes, count) = mesh_all(cap);
        previous = Some(last);
        last = (cap, count);
        // Keep the fullest meshing within the budget, else the smallest.
        let better = if count <= most {
            best_count > most || count > best_count
        } else {
            best_count > most && count < best_count
        };
        if better {
            best = meshes;
            best_count = count;
            best_cap = cap;
        }
    }
    (best, best_cap)
}

/// The element count at which the light-driven rounds stop (95% of `budget`): a round adds
/// what the budget has room for, and the last few percent are not worth evaluating the light
/// on the whole scene again.
fn rounds_stop(budget: usize) -> usize {
    budget.saturating_mul(19).div_ceil(20)
}

/// The most elements a meshing for `budget` may have: `budget` (1 + [`BUDGET_SLACK`]).
fn with_slack(budget: usize) -> usize {
    (budget as f64 * (1.0 + BUDGET_SLACK)) as usize
}

/// The average element area (scene units²) at `budget` elements over the whole scene; the budget
/// search's cap stays within [`COARSEST`] times it.
fn element_area(scene: &Scene, budget: usize) -> f64 {
    let total_area: f64 = scene.polygons.iter().map(|p| p.area).sum();
    total_area / budget.max(1) as f64
}

/// Meshes every polygon at one area cap, with a refinement vertex cap from the polygon's
/// expected element count and its outline.
fn mesh_at<F>(scene: &Scene, max_area: f64, mesh_one: &F) -> Vec<ReceiverMesh>
where
    F: Fn(usize, f64, usize) -> ReceiverMesh + Sync,
{
    (0..scene.polygons.len())
        .into_par_iter()
        .map(|i| mesh_one(i, max_area, vertex_cap(&scene.polygons[i], max_area)))
        .collect()
}

/// Most vertices refinement may add to polygon `p` at area cap `max_area`: four times the
/// elements the cap asks for, plus room for the outline's grading.
fn vertex_cap(p: &Polygon, max_area: f64) -> usize {
    let expected = (p.area / max_area).ceil().min(1e9) as usize;
    4 * expected + 4 * p.boundary.len() + 64
}

/// The uniform mesher: every polygon refined to one area cap, about `budget` triangles in all.
pub fn uniform(scene: &Scene, budget: usize) -> Vec<ReceiverMesh> {
    to_budget(scene, budget, with_slack(budget), |i, area, cap| {
        triangulate(i, &scene.polygons[i], area, cap)
    })
    .0
}

/// The discontinuity mesher: each polygon's discontinuity `segments` as constraints, then the
/// same refinement as [`uniform`], at most `budget` (1 + [`BUDGET_SLACK`]) triangles in all.
///
/// Discontinuities take the budget first: when every wedge piece does not fit even with the
/// coarsest refinement, the weakest pieces (lowest significance; D0 lines are always kept)
/// are dropped until the coarsest meshing costs at most [`DM_SHARE`] of what the meshing
/// without them ([`geometry_floor`]) leaves of the budget, so that the rest still refines the surfaces between the lines.
///
/// With `refine` (the direct light at the vertices of a set of meshes), [`LIGHT_SHARE`] of what
/// the coarsest meshing with the lines leaves of the budget is kept back, and goes where the light
/// varies most across an element or is missed most between its vertices ([`LIGHT_ROUNDS`]
/// rounds of the adaptive mesher's rule,
/// splitting at the centroid so that no split lands on a line). The uniform step before them
/// stays under where the rounds stop ([`rounds_stop`]) whenever the lines leave room there.
/// Returns the meshes, what became of the segments passed to the triangulation and the wedge
/// pieces dropped for the budget.
pub fn discontinuity(
    scene: &Scene,
    segments: &[Vec<Segment>],
    budget: usize,
    refine: Option<&Evaluate<'_>>,
) -> (Vec<ReceiverMesh>, Inserted, usize) {
    // Wedge pieces, strongest first (ties by polygon and position: a total, fixed order).
    let mut ranked: Vec<(usize, usize)> = segments
        .iter()
        .enumerate()
        .flat_map(|(p, segs)| {
            segs.iter()
                .enumerate()
                .filter(|(_, s)| s.kind != Kind::D0)
                .map(move |(i, _)| (p, i))
        })
        .collect();
    ranked.sort_by(|&(p, i), &(q, j)| {
        segments[q][j]
            .significance
            .total_cmp(&segments[p][i].significance)
            .then((p, i).cmp(&(q, j)))
    });
    let (snap, clearance) = line_spacing(scene, budget);
    // The strongest `keep` wedge pieces and every D0 line, per polygon.
    let select = |keep: usize| -> Vec<Vec<Segment>> {
        let mut kept: Vec<Vec<bool>> = segments
            .iter()
            .map(|segs| segs.iter().map(|s| s.kind == Kind::D0).collect())
            .collect();
        for &(p, i) in &ranked[..keep] {
            kept[p][i] = true;
        }
        segments
            .iter()
            .zip(&kept)
            .map(|(segs, k)| {
                segs.iter()
                    .zip(k)
                    .filter(|(_, k)| **k)
                    .map(|(s, _)| s.clone())
                    .collect()
            })
            .collect()
    };
    // What became of each polygon's segments: decided before refinement, so the same at every
    // cap; the last meshing (the final selection) writes last.
    let inserted = std::sync::Mutex::new(vec![Inserted::default(); scene.polygons.len()]);
    let mesh_one =
        |selected: &[Vec<Segment>], i: usize, points: &[DVec2], area: f64, cap: usize| {
            let lines = Lines {
                segments: &selected[i],
                snap,
                clearance,
                points,
            };
            let (m, ins) = triangulate_with(i, &scene.polygons[i], lines, area, cap);
            inserted.lock().unwrap_or_else(|e| e.into_inner())[i] = ins;
            m
        };
    // The count at the coarsest cap with the strongest `keep` pieces.
    let coarsest = element_area(scene, budget) * COARSEST;
    let floor = |keep: usize| -> usize {
        let selected = select(keep);
        element_count(&mesh_at(scene, coarsest, &|i, area, cap| {
            mesh_one(&selected, i, &[], area, cap)
        }))
    };
    let mut keep = ranked.len();
    let most = (budget as f64 * (1.0 + BUDGET_SLACK)) as usize;
    let all = floor(keep);
    // The coarsest meshing's count with the pieces kept.
    let mut least = all;
    if all > most {
        // The wedges may take DM_SHARE of what the meshing without them leaves of the budget:
        // search for the most pieces that fit, interpolating (the count grows about linearly
        // in the pieces kept) or bisecting between the most known to fit and the fewest known
        // not to.
        let none = geometry_floor(scene, segments, budget);
        let share = none + ((budget.saturating_sub(none)) as f64 * DM_SHARE) as usize;
        let (mut fits, mut fails) = ((0, none), (ranked.len(), all));
        for _ in 0..BUDGET_PASSES {
            if none > share || fails.0 - fits.0 <= (ranked.len() / 100).max(1) {
                break;
            }
            let span = (fails.0 - fits.0) as f64;
            let t = (share - fits.1) as f64 / (fails.1 - fits.1).max(1) as f64;
            let t = if (0.1..=0.9).contains(&t) { t } else { 0.5 };
            let guess = fits.0 + ((span * t) as usize).clamp(1, fails.0 - fits.0 - 1);
            let n = floor(guess);
            if n <= share {
                fits = (guess, n);
            } else {
                fails = (guess, n);
            }
        }
        (keep, least) = if none <= share { fits } else { (0, none) };
    }
    let selected = select(keep);
    // With light-driven refinement, the lines and the uniform refinement leave it LIGHT_SHARE
    // of what the coarsest meshing with the lines leaves of the budget.
    let first = match refine {
        Some(_) => least + (budget.saturating_sub(least) as f64 * (1.0 - LIGHT_SHARE)) as usize,
        None => budget,
    };
    let uniform_step = |most: usize| {
        to_budget(scene, first, most, |i, area, vertices| {
            mesh_one(&selected, i, &[], area, vertices)
        })
    };
    let (mut meshes, mut cap) = uniform_step(with_slack(first));
    // The light rounds stop at `rounds_stop`: where the lines leave room under it but the
    // uniform step's slack carried it past, the step is redone under it, so that the rounds
    // still run (interior-20 at 100 000 elements: the lines' coarsest meshing is 92 840, the
    // step landed at 101 285, and the bake showed less light than at 70 000).
    let stop = rounds_stop(budget);
    if refine.is_some() && least < stop && element_count(&meshes) >= stop {
        (meshes, cap) = uniform_step(stop - 1);
    }
    if let Some(evaluate) = refine {
        let start = meshes;
        let added;
        (meshes, added) = refine_by_light(
            &start,
            budget,
            LIGHT_ROUNDS,
            evaluate,
            |t| (t[0] + t[1] + t[2]) / 3.0,
            |mi, points| {
                let i = start[mi].polygon;
                let vertices = vertex_cap(&scene.polygons[i], cap) + 4 * points.len();
                mesh_one(&selected, i, points, cap, vertices)
            },
        );
        // Where the light varies little, the rounds stop short of the budget: the rest refines
        // uniformly, keeping the points added.
        if element_count(&meshes) * 10 < budget * 9 {
            (meshes, _) = to_budget(scene, budget, with_slack(budget), |i, area, vertices| {
                mesh_one(&selected, i, &added[i], area, vertices + 4 * added[i].len())
            });
        }
    }
    let total = inserted
        .into_inner()
        .unwrap_or_else(|e| e.into_inner())
        .iter()
        .fold(Inserted::default(), |t, i| Inserted {
            refused: t.refused + i.refused,
            crowded: t.crowded + i.crowded,
        });
    (meshes, total, ranked.len() - keep)
}

/// The snapping distance and the clearance between lines ([`Lines`]) of the discontinuity
/// mesher at `budget` (scene units): the discontinuity stage's tolerance, and half the side of
/// an average element.
fn line_spacing(scene: &Scene, budget: usize) -> (f64, f64) {
    let snap = 10.0 * crate::discontinuity::TOLERANCE * scene.extent();
    (snap, 0.5 * element_area(scene, budget).sqrt())
}

/// The elements the geometry itself takes at `budget`: the count of the coarsest meshing the
/// budget search uses (area cap [`COARSEST`] times area/budget), with the D0 (contact) lines of
/// `segments` and no wedge piece (pass no segments for the uniform and adaptive meshers). It is
/// usually below the input's triangle count (a box's faces are one polygon each), but not where
/// the angle bound refines thin or notched polygons (boards, walls with doors): the default
/// element budget leaves room above it (`bake::element_budget`), and the discontinuity mesher
/// gives its wedges a share of what is left above it ([`DM_SHARE`]).
pub(crate) fn geometry_floor(scene: &Scene, segments: &[Vec<Segment>], budget: usize) -> usize {
    let d0: Vec<Vec<Segment>> = segments
        .iter()
        .map(|segs| {
            segs.iter()
                .filter(|s| s.kind == Kind::D0)
                .cloned()
                .collect()
        })
        .collect();
    lines_floor(scene, &d0, budget)
}

/// The elements the geometry and every one of `segments` take at `budget`: as
/// [`geometry_floor`], with the wedge pieces too. The default element budget stays above it
/// (`bake::element_budget`), so that no line the discontinuity stage kept is dropped for the
/// budget and the open areas between the lines are refined all the same.
pub(crate) fn lines_floor(scene: &Scene, segments: &[Vec<Segment>], budget: usize) -> usize {
    let (snap, clearance) = line_spacing(scene, budget);
    let d0 = segments;
    let coarsest = element_area(scene, budget) * COARSEST;
    element_count(&mesh_at(scene, coarsest, &|i, area, cap| {
        // As the mesher that asks meshes: the uniform mesher with no lines at all.
        let lines = match d0.get(i) {
            Some(segments) => Lines {
                segments,
                snap,
                clearance,
                points: &[],
            },
            None => Lines::default(),
        };
        triangulate_with(i, &scene.polygons[i], lines, area, cap).0
    }))
}

/// Triangulates a polygon's outline plus the given interior points, with no refinement (the
/// caller chose the points). Faces outside the polygon are dropped.
pub(crate) fn triangulate_points(id: usize, polygon: &Polygon, points: &[DVec2]) -> ReceiverMesh {
    let outline = merge_collinear(&polygon.boundary);
    let mut cdt = ConstrainedDelaunayTriangulation::<Point2<f64>>::new();
    for [a, b] in &outline {
        if let (Ok(va), Ok(vb)) = (
            cdt.insert(Point2::new(a.x, a.y)),
            cdt.insert(Point2::new(b.x, b.y)),
        ) && va != vb
        {
            cdt.try_add_constraint(va, vb);
        }
    }
    for p in points {
        let _ = cdt.insert(Point2::new(p.x, p.y));
    }
    inside_faces(id, polygon, &cdt).0
}

/// The faces of `cdt` inside the polygon (centroid test against its own triangles, nonzero
/// area) as a mesh, and the map from spade vertex index to mesh vertex (`u32::MAX`: unused).
fn inside_faces(
    id: usize,
    polygon: &Polygon,
    cdt: &ConstrainedDelaunayTriangulation<Point2<f64>>,
) -> (ReceiverMesh, Vec<u32>) {
    let mut mesh = ReceiverMesh {
        polygon: id,
        ..Default::default()
    };
    let mut remap = vec![u32::MAX; cdt.num_vertices()];
    for face in cdt.inner_faces() {
        let pos = face.positions().map(|p| DVec2::new(p.x, p.y));
        if (pos[1] - pos[0]).perp_dot(pos[2] - pos[0]) <= 0.0
            || !polygon.contains((pos[0] + pos[1] + pos[2]) / 3.0)
        {
            continue;
        }
        let ids = face.vertices().map(|v| {
            let i = v.fix().index();
            if remap[i] == u32::MAX {
                remap[i] = mesh.vertices.len() as u32;
                mesh.vertices
                    .push(DVec2::new(v.position().x, v.position().y));
            }
            remap[i]
        });
        mesh.triangles.push(ids);
    }
    (mesh, remap)
}

/// The a-posteriori adaptive mesher, the classic alternative to discontinuity meshing (e.g.
/// Cohen, Greenberg, Immel, Brock, "An efficient radiosity approach for realistic image
/// synthesis", 1986): start from a uniform mesh of a quarter of the budget, solve, and split the
/// elements across which the solution varies most, or whose centroid it misses most (the
/// longest edge at its midpoint; the error of `refine_by_light`), then solve and split again,
/// until the budget is reached or no element's error is over [`LIGHT_TOLERANCE`] of the
/// brightest vertex. `evaluate` gives the values (irradiance) at every mesh's vertices.
pub fn adaptive(scene: &Scene, budget: usize, evaluate: &Evaluate<'_>) -> Vec<ReceiverMesh> {
    let start = uniform(scene, (budget / 4).max(1));
    refine_by_light(
        &start,
        budget,
        8,
        evaluate,
        |t| {
            // The midpoint of the longest edge.
            let e = (0..3)
                .max_by(|&i, &j| {
                    let li = t[i].distance_squared(t[(i + 1) % 3]);
                    let lj = t[j].distance_squared(t[(j + 1) % 3]);
                    li.total_cmp(&lj).then(j.cmp(&i))
                })
                .unwrap_or(0);
            (t[e] + t[(e + 1) % 3]) * 0.5
        },
        |mi, points| {
            let m = &start[mi];
            let mut all = m.vertices.clone();
            all.extend(points);
            triangulate_points(m.polygon, &scene.polygons[m.polygon], &all)
        },
    )
    .0
}

/// The adaptive rule on top of `start`: up to `rounds` times, evaluate the light, rank the
/// elements whose error exceeds [`LIGHT_TOLERANCE`] of the brightest vertex, and add a vertex
/// (`split` of the triangle's corners) to the worst ones, as many as the budget allows;
/// `rebuild(mesh, points)` remeshes `start[mesh]` with all the points added to it so far.
/// Stops at [`rounds_stop`] (95% of the budget); a round that would overshoot it by more than
/// [`BUDGET_SLACK`] is undone. Returns the meshes and the points added to each.
///
/// An element's error is the larger of
///
/// * the *variation*: the spread of the light over its three vertices (the classic rule, Cohen
///   et al. 1986), which finds shadow edges and steep falloff, and
/// * the *missed* light: the exact light at its centroid minus the mean of its vertices (what
///   linear interpolation shows there), times its area in average elements (at least one);
///   looked for in the elements larger than [`MISSED_AREA`] of the average one.
///
/// The first alone cannot see a peak between an element's vertices: a house's wall under a
/// ceiling light is dark at the ceiling and at the floor and brightest in between, and with
/// every vertex of its few large elements on those edges the wall read a third of its light.
/// On a 20-room house (`interior-20`) the bake's direct light over all surfaces was 82% of what
/// the lamps emit, and against the Monte Carlo reference the RMSE over all texels was 18.8% of
/// the lit mean; with the missed light, 94% and 11.6%; at night under 256 street lamps
/// (`night-town-25k`) 17.1% and 14.4% (the ground's lit pools: their bias from -16% to 0.1%).
/// The missed light is weighted by area because a large element that misses a peak misplaces
/// that light over all its area, as much as that many average elements would; unweighted
/// it changed nothing. The variation stays unweighted: weighted too, the Cornell box's
/// penumbra error went from 0.69% to 1.13% of the lit mean, the budget taken from the small
/// elements along the shadow edges (the missed light alone leaves the Cornell box's mesh as
/// it was).
fn refine_by_light<S, R>(
    start: &[ReceiverMesh],
    budget: usize,
    rounds: usize,
    evaluate: &Evaluate<'_>,
    split: S,
    rebuild: R,
) -> (Vec<ReceiverMesh>, Vec<Vec<DVec2>>)
where
    S: Fn([DVec2; 3]) -> DVec2,
    R: Fn(usize, &[DVec2]) -> ReceiverMesh + Sync,
{
    let lum = |c: &glam::DVec3| crate::light::luminance(*c);
    let most = (budget as f64 * (1.0 + BUDGET_SLACK)) as usize;
    let mut meshes = start.to_vec();
    let mut added: Vec<Vec<DVec2>> = vec![Vec::new(); start.len()];
    // Elements one split adds, measured after each round.
    let mut per_split = 2.0;
    // The light at each mesh's vertices (after a round, only the rebuilt meshes are evaluated
    // again) and at the centroids of its elements larger than MISSED_AREA of the round's
    // average element (evaluated once per element: `None` until then).
    let mut values: Vec<Vec<glam::DVec3>> = vec![Vec::new(); meshes.len()];
    let mut centroids: Vec<Vec<Option<glam::DVec3>>> = vec![Vec::new(); meshes.len()];
    let mut stale: Vec<usize> = (0..meshes.len()).collect();
    for _ in 0..rounds {
        let total = element_count(&meshes);
        if total >= rounds_stop(budget) {
            break;
        }
        let mean_area = meshes.iter().map(ReceiverMesh::area).sum::<f64>() / total.max(1) as f64;
        for &mi in &stale {
            centroids[mi] = vec![None; meshes[mi].triangles.len()];
        }
        // Per mesh, the large elements whose centroid has no value yet.
        let wanted: Vec<(usize, Vec<usize>)> = meshes
            .iter()
            .enumerate()
            .filter_map(|(mi, m)| {
                let ts: Vec<usize> = (0..m.triangles.len())
                    .filter(|&ti| {
                        centroids[mi][ti].is_none()
                            && m.triangle_area(&m.triangles[ti]) > MISSED_AREA * mean_area
                    })
                    .collect();
                (!ts.is_empty()).then_some((mi, ts))
            })
            .collect();
        // One evaluation for both: the stale meshes' vertices, then per mesh a mesh of the
        // wanted centroids alone (no triangles: the points are inside the polygon).
        let mut subset: Vec<ReceiverMesh> = stale.iter().map(|&mi| meshes[mi].clone()).collect();
        subset.extend(
            wanted
                .iter()
                .map(|(mi, ts)| centroid_points(&meshes[*mi], ts)),
        );
        let mut out = evaluate(&subset).into_iter();
        for &mi in &stale {
            values[mi] = out.next().unwrap_or_default();
        }
        for (mi, ts) in &wanted {
            for (&ti, h) in ts.iter().zip(out.next().unwrap_or_default()) {
                centroids[*mi][ti] = Some(h);
            }
        }
        // The brightest point seen, vertex or centroid: a pool of light may lie between dark
        // vertices only.
        let peak = values
            .iter()
            .flatten()
            .chain(centroids.iter().flatten().flatten())
            .map(lum)
            .fold(0.0, f64::max);
        if peak <= 0.0 {
            break;
        }
        // (error, mesh, triangle), largest first; ties in a fixed order.
        let mut ranked: Vec<(f64, usize, usize)> = Vec::new();
        for (mi, (m, v)) in meshes.iter().zip(&values).enumerate() {
            for (ti, t) in m.triangles.iter().enumerate() {
                let l = t.map(|i| lum(&v[i as usize]));
                let variation = l.iter().fold(f64::MIN, |a, &b| a.max(b))
                    - l.iter().fold(f64::MAX, |a, &b| a.min(b));
                let missed = match centroids[mi].get(ti) {
                    Some(Some(c)) => {
                        let weight = (m.triangle_area(t) / mean_area).max(1.0);
                        (lum(c) - (l[0] + l[1] + l[2]) / 3.0).abs() * weight
                    }
                    _ => 0.0,
                };
                let error = variation.max(missed);
                if error > LIGHT_TOLERANCE * peak {
                    ranked.push((error, mi, ti));
                }
            }
        }
        if ranked.is_empty() {
            break;
        }
        ranked.sort_by(|a, b| b.0.total_cmp(&a.0).then((a.1, a.2).cmp(&(b.1, b.2))));
        let room = (budget - total) as f64 / per_split;
        ranked.truncate((room as usize).clamp(1, total.div_ceil(2)));
        // A round that overshoots is retried once with fewer splits, scaled by the overshoot.
        let mut accepted = None;
        for _ in 0..2 {
            let mut touched = vec![false; meshes.len()];
            let mut next_added = added.clone();
            for &(_, mi, ti) in &ranked {
                let m = &meshes[mi];
                next_added[mi].push(split(m.triangles[ti].map(|i| m.vertices[i as usize])));
                touched[mi] = true;
            }
            let next: Vec<ReceiverMesh> = (0..meshes.len())
                .into_par_iter()
                .map(|mi| {
                    if touched[mi] {
                        rebuild(mi, &next_added[mi])
                    } else {
                        meshes[mi].clone()
                    }
                })
                .collect();
            let count = element_count(&next);
            per_split = ((count as f64 - total as f64) / ranked.len() as f64).max(1.0);
            if count <= most {
                accepted = Some((next, next_added));
                break;
            }
            let fewer = ((budget - total) as f64 / per_split * 0.95) as usize;
            if fewer == 0 {
                break;
            }
            ranked.truncate(fewer);
        }
        let Some((next, next_added)) = accepted else {
            break;
        };
        stale = (0..meshes.len())
            .filter(|&mi| next_added[mi].len() != added[mi].len())
            .collect();
        meshes = next;
        added = next_added;
    }
    (meshes, added)
}

/// A mesh of the centroids of `m`'s `triangles` as vertices, with no triangles (for
/// evaluating the light there).
fn centroid_points(m: &ReceiverMesh, triangles: &[usize]) -> ReceiverMesh {
    ReceiverMesh {
        polygon: m.polygon,
        vertices: triangles
            .iter()
            .map(|&ti| {
                m.triangles[ti]
                    .iter()
                    .map(|&i| m.vertices[i as usize])
                    .sum::<DVec2>()
                    / 3.0
            })
            .collect(),
        triangles: Vec::new(),
        constraints: Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Instance, Material};
    use glam::DVec3;

    fn floor_scene(corners: Vec<DVec3>, indices: Vec<u32>) -> Scene {
        let mut scene = Scene::default();
        scene.materials.push(Material {
            name: "m".into(),
            rho: DVec3::splat(0.5),
            radiance: DVec3::ZERO,
        });
        scene.add_instance(Instance::new(corners, indices), 0);
        scene
    }

    /// A `w` x `d` floor at y = 0 (two triangles).
    fn rectangle(w: f64, d: f64) -> Scene {
        floor_scene(
            vec![
                DVec3::new(0.0, 0.0, 0.0),
                DVec3::new(w, 0.0, 0.0),
                DVec3::new(w, 0.0, -d),
                DVec3::new(0.0, 0.0, -d),
            ],
            vec![0, 1, 2, 0, 2, 3],
        )
    }

    /// The unit square's outline, counter-clockwise (inside on the left).
    fn unit_square() -> Vec<[DVec2; 2]> {
        let c = [
            DVec2::new(0.0, 0.0),
            DVec2::new(1.0, 0.0),
            DVec2::new(1.0, 1.0),
            DVec2::new(0.0, 1.0),
        ];
        (0..4).map(|i| [c[i], c[(i + 1) % 4]]).collect()
    }

    #[test]
    fn segment_ends_near_the_outline_go_onto_it() {
        let outline = unit_square();
        let gap = 0.05;
        // Ends 1e-12 and 0.03 from the bottom and top edges, crossing at 60 degrees: both go
        // onto the edges along the segment's line, a hair outside.
        let (a, b) = (
            DVec2::new(0.3, 1e-12),
            DVec2::new(0.3 + 0.97 / 3f64.sqrt(), 0.97),
        );
        let (a2, b2) = keep_clear(a, b, &outline, gap, true).expect("kept");
        assert!(a2.y <= 0.0 && a2.y > -1e-8, "{a2}");
        assert!(b2.y >= 1.0 && b2.y < 1.0 + 1e-8, "{b2}");
        let dir = (b - a).normalize();
        assert!((a2 - a).perp_dot(dir).abs() < 1e-8 && (b2 - a).perp_dot(dir).abs() < 1e-8);
        // An end 0.01 from a corner goes onto the corner.
        let (_, c) = keep_clear(
            DVec2::new(0.5, 0.5),
            DVec2::new(0.99, 0.992),
            &outline,
            gap,
            true,
        )
        .expect("kept");
        assert_eq!(c, DVec2::new(1.0, 1.0));
        // An end far from the outline stays; a segment along an edge is left out.
        let (p, _) = keep_clear(DVec2::new(0.5, 0.5), b, &outline, gap, true).expect("kept");
        assert_eq!(p, DVec2::new(0.5, 0.5));
        assert!(
            keep_clear(
                DVec2::new(0.1, 0.02),
                DVec2::new(0.9, 0.03),
                &outline,
                gap,
                true
            )
            .is_none()
        );
    }

    #[test]
    fn uniform_mesh_covers_the_polygon_and_meets_the_budget() {
        let scene = rectangle(2.0, 1.0);
        let meshes = uniform(&scene, 500);
        assert_eq!(meshes.len(), 1);
        let m = &meshes[0];
        assert!((m.area() - 2.0).abs() < 1e-9, "area {}", m.area());
        let n = m.triangles.len();
        assert!(
            (450..=525).contains(&n),
            "{n} triangles for a budget of 500"
        );
        assert!(m.triangles.iter().all(|t| m.triangle_area(t) > 0.0));
    }

    /// A pool of light (a paraboloid cap of radius 1.2, zero outside) in the middle of a 4 x 4
    /// floor whose two triangles' corners are all dark: the spread over the vertices sees
    /// nothing, the light missed at the centroids finds the pool, and the refined mesh shows
    /// its light (`pi r² / 2` exactly) to within 5% (measured 1.6% at 400 elements).
    #[test]
    fn light_between_dark_vertices_is_found_and_refined() {
        let scene = rectangle(4.0, 4.0);
        let polygon = &scene.polygons[0];
        let start = vec![triangulate_points(0, polygon, &[])];
        assert_eq!(start[0].triangles.len(), 2);
        let centre = polygon.frame.plane_from_world(DVec3::new(2.0, 0.0, -2.0));
        let (r, peak) = (1.2, 1.0);
        let light = |v: DVec2| peak * (1.0 - (v - centre).length_squared() / (r * r)).max(0.0);
        let evaluate = |meshes: &[ReceiverMesh]| -> Vec<Vec<DVec3>> {
            meshes
                .iter()
                .map(|m| m.vertices.iter().map(|&v| DVec3::splat(light(v))).collect())
                .collect()
        };
        let (meshes, added) = refine_by_light(
            &start,
            400,
            8,
            &evaluate,
            |t| (t[0] + t[1] + t[2]) / 3.0,
            |mi, points| {
                let mut all = start[mi].vertices.clone();
                all.extend(points);
                triangulate_points(0, polygon, &all)
            },
        );
        assert!(!added[0].is_empty(), "no split");
        let m = &meshes[0];
        let shown: f64 = m
            .triangles
            .iter()
            .map(|t| {
                m.triangle_area(t)
                    * t.iter()
                        .map(|&i| light(m.vertices[i as usize]))
                        .sum::<f64>()
                    / 3.0
            })
            .sum();
        let exact = std::f64::consts::PI * r * r / 2.0 * peak;
        assert!(
            (shown / exact - 1.0).abs() < 0.05,
            "shown {shown:.4} of {exact:.4} with {} elements",
            m.triangles.len()
        );
    }

    /// A 40 x 1 board on a 100 x 100 ground: the board is larger than the coarsest element (64
    /// times 10 040 / 20 000 = 32) and far too thin for good angles, so its coarsest meshing
    /// takes many more elements than its two triangles, which the floor counts.
    #[test]
    fn a_penumbra_boundary_leaves_out_where_it_runs_along_its_pair() {
        // A placed boundary from the origin along +x, and a second one leaving the same point
        // 3 degrees apart: within the clearance 0.1 of the first for its first 0.1 / sin 3° =
        // 1.91 units.
        let mut obstacles = Obstacles::new(DVec2::splat(-10.0), DVec2::splat(10.0), 0.1, 16);
        obstacles.push(DVec2::ZERO, DVec2::new(8.0, 0.0), 7);
        let angle = 3f64.to_radians();
        let end = DVec2::new(angle.cos(), angle.sin()) * 8.0;
        let pieces = obstacles.apart_from_its_pair(DVec2::ZERO, end, 7);
        assert_eq!(pieces.len(), 1, "{pieces:?}");
        // It starts where it is the clearance away from the first (its height above the x
        // axis), and runs on to its end.
        let (a, b) = pieces[0];
        assert!(
            (a.length() - 0.1 / angle.sin()).abs() < 1e-6,
            "starts at {a}"
        );
        assert!((a.y - 0.1).abs() < 1e-6 && b == end, "{a} {b}");
        // The boundary of another penumbra, or one opening wider than the angle limit, stays.
        assert_eq!(
            obstacles.apart_from_its_pair(DVec2::ZERO, end, 8),
            vec![(DVec2::ZERO, end)]
        );
        let wide = DVec2::new(30f64.to_radians().cos(), 30f64.to_radians().sin()) * 8.0;
        assert_eq!(
            obstacles.apart_from_its_pair(DVec2::ZERO, wide, 7),
            vec![(DVec2::ZERO, wide)]
        );
        // A line with no feature (D0, punctual) is never cut.
        assert_eq!(
            obstacles.apart_from_its_pair(DVec2::ZERO, end, 0),
            vec![(DVec2::ZERO, end)]
        );
    }

    #[test]
    fn the_geometry_floor_counts_the_angle_refinement_of_a_thin_board() {
        let p = |x: f64, z: f64| DVec3::new(x, 0.0, -z);
        let q = |x: f64, y: f64| DVec3::new(x, y, -50.0);
        let mut scene = floor_scene(
            vec![p(-50., -50.), p(50., -50.), p(50., 50.), p(-50., 50.)],
            vec![0, 1, 2, 0, 2, 3],
        );
        scene.add_instance(
            Instance::new(
                vec![q(0., 0.), q(40., 0.), q(40., 1.), q(0., 1.)],
                vec![0, 1, 2, 0, 2, 3],
            ),
            0,
        );
        let floor = geometry_floor(&scene, &[], 20_000);
        let coarsest = mesh_at(
            &scene,
            element_area(&scene, 20_000) * COARSEST,
            &|i, a, c| triangulate(i, &scene.polygons[i], a, c),
        );
        assert_eq!(floor, element_count(&coarsest));
        let board = coarsest.iter().find(|m| m.polygon == 1).expect("board");
        assert!(board.triangles.len() >= 10, "{}", board.triangles.len());
        // The discontinuity mesher's floor keeps the ground's contact lines (a line across
        // it, in its plane coordinates) and leaves out every wedge piece.
        let segment = |kind, y: f64| Segment {
            a: DVec2::new(-40.0, y),
            b: DVec2::new(40.0, y),
            kind,
            event: 0,
            significance: 1.0,
            feature: 0,
        };
        let count = |segs: Vec<Segment>| geometry_floor(&scene, &[segs, Vec::new()], 20_000);
        let d0 = count(vec![segment(Kind::D0, 0.5)]);
        assert!(d0 > count(Vec::new()), "{d0}");
        assert_eq!(
            count(vec![segment(Kind::D0, 0.5), segment(Kind::Ve, 10.0)]),
            d0
        );
    }

    #[test]
    fn concave_polygon_keeps_its_notch() {
        // An L shape: the notch [1,2]x[1,2] must stay empty.
        let p = |x: f64, y: f64| DVec3::new(x, 0.0, -y);
        let scene = floor_scene(
            vec![
                p(0., 0.),
                p(2., 0.),
                p(2., 1.),
                p(1., 1.),
                p(1., 2.),
                p(0., 2.),
            ],
            vec![0, 1, 2, 0, 2, 3, 0, 3, 4, 0, 4, 5],
        );
        let meshes = uniform(&scene, 300);
        let m = &meshes[0];
        assert!((m.area() - 3.0).abs() < 1e-9, "area {}", m.area());
    }
}
