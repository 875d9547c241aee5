//! One polygon's constrained Delaunay triangulation (spade): its outline and discontinuity
//! lines as constraints, refined to an area cap and an angle bound, then cut along the lines
//! where the light jumps.

use super::arrangement;
use super::lines::{Obstacles, keep_clear, merge_collinear};
use super::safe_frame::in_safe_frame;
use super::{Constraint, Inserted, Lines, ReceiverMesh};
use crate::discontinuity::{Kind, Segment};
use crate::scene::Polygon;
use glam::DVec2;
use spade::handles::FixedVertexHandle;
use spade::{
    AngleLimit, ConstrainedDelaunayTriangulation, Point2, RefinementParameters, Triangulation,
};

/// Minimum angle for quality refinement, degrees.
pub(crate) const ANGLE_LIMIT_DEG: f64 = 25.0;

/// The repair ([`repair`]) gives every element larger than this fraction of the area cap
/// the angle limit, in every polygon, small ones included: so that the vertices the lines and
/// their small features take never leave the open areas in slivers (the generated city's
/// ground, with five thousand lines, kept fans of slivers 10 m long from its footprint corners)
/// and a wall smaller than one element is not two triangles 20 m long. Below it, elements are
/// at the scale of the features that make them (lines a few centimetres apart, short outline
/// edges), where refining them for their angles costs without bound: at a hundredth of the
/// cap, the generated 5 000-triangle city took 18 times the elements.
pub(crate) const SHAPE_FLOOR: f64 = 0.1;

/// The bounded passes refine no element smaller than this fraction of the area cap.
const DETAIL_FLOOR: f64 = 1e-3;

/// A polygon larger than this many area caps whose refinement runs out of vertices is
/// triangulated again with a lattice in its open areas ([`open_lattice`]).
const LATTICE_FROM: f64 = 4.0;

/// The lattice's triangles, as a fraction of the area cap: under 1, so rounding leaves none
/// over the cap for refinement to split.
const LATTICE_FILL: f64 = 0.8;

/// The lattice keeps this many of its steps from the outline and the lines.
const LATTICE_CLEAR: f64 = 0.25;

/// How far from a corner or contact line its row of vertices lies ([`corner_strip`]), as a
/// fraction of the side of an element at the area cap (a square of the cap). Measured on a
/// real city (Florence, the RMSE against a path-traced reference): 0.2 and 0.45 did worse than
/// 0.3.
const STRIP_OFFSET: f64 = 0.3;

/// Only polygons at most this many element sides across (twice the area over the perimeter)
/// get strips ([`corner_strip`]): a wall a few elements high. A polygon meshed finer already
/// grades its elements towards its corners; there the rows of thin elements only take the
/// budget from the rest.
const STRIP_UP_TO: f64 = 3.0;

/// The most point-in-triangle tests [`open_lattice`] spends on one polygon.
const LATTICE_TESTS: f64 = 5e7;

/// Triangulates one polygon: its boundary and the discontinuity `lines.segments` (plane
/// coordinates) as constraints, the `lines.points` as vertices (and with `lines.strips`, rows
/// of vertices beside corner and contact lines: [`corner_strip`]), refined so that no triangle is larger than `max_area` (scene units²) and,
/// where the constraints allow, none has an angle under [`ANGLE_LIMIT_DEG`]. The area and angle
/// passes add at most `vertex_cap` vertices, which can leave both short where the lines' small
/// features take them; the repair ([`repair`]) then completes both above [`SHAPE_FLOOR`] of the
/// cap.
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
        strips,
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
    let mut order: Vec<&Segment> = segments.iter().filter(|s| s.kind != Kind::Corner).collect();
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
    let strip = if strips {
        corner_strip(polygon, segments, max_area, &obstacles)
    } else {
        Vec::new()
    };
    let arr = arrangement::build(&input, tol);
    // A polygon no larger than one element, with nothing inside, gets only the repair: refining
    // its small slivers for their angles (a tessellated sphere's poles) would spend the budget
    // where the light is smooth at the element's scale anyway.
    let detail = polygon.area > max_area
        || !arr.edges.iter().all(|e| e.2.is_none())
        || !points.is_empty()
        || !strip.is_empty();
    // The triangulation, refined; with `lattice`, seeded first with a lattice in the open
    // areas. Also whether the area pass ran out of vertices.
    let build = |lattice: bool, vertex_cap: usize| {
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
        // The strip's points are inside already (`corner_strip` tests them).
        for p in points.iter().filter(|p| polygon.contains(**p)).chain(&strip) {
            let _ = cdt.insert(Point2::new(p.x, p.y));
        }
        if lattice {
            for q in open_lattice(polygon, lo, hi, max_area, &obstacles) {
                let _ = cdt.insert(Point2::new(q.x, q.y));
            }
        }
        let mut starved = false;
        if cdt.num_vertices() >= 3 && !cdt.all_vertices_on_line() {
            let params = |angle: f64, floor: f64, vertices: usize| {
                RefinementParameters::<f64>::new()
                    .with_angle_limit(AngleLimit::from_deg(angle))
                    .with_max_allowed_area(max_area.max(polygon.area * 1e-9))
                    .with_min_required_area(max_area * floor)
                    .with_max_additional_vertices(vertices)
                    .exclude_outer_faces(segments.is_empty())
            };
            // The area cap first, bounded: in one pass with the angles, constraints that meet
            // at small angles or run close together (a thin slab's contact and penumbra lines)
            // can take every vertex the cap allows in fans around them.
            let before = cdt.num_vertices();
            if detail {
                cdt.refine(params(0.0, DETAIL_FLOOR, vertex_cap));
            }
            let added = cdt.num_vertices() - before;
            starved = added >= vertex_cap;
            // Then the smaller elements' angles, with at most half as many vertices again as
            // the area pass took.
            if detail {
                let angle_cap = (added / 2).max(vertex_cap / 4);
                cdt.refine(params(ANGLE_LIMIT_DEG, DETAIL_FLOOR, angle_cap));
            }
        }
        (cdt, handles, refused, starved)
    };
    // When the area pass runs out of vertices, it has spent them around the lines (on a city's
    // ground, thousands of footprints and shadow lines) and left open ground in elements up to
    // forty times the cap: the polygon is triangulated again with its open areas seeded first.
    let (mut cdt, mut handles, mut refused, starved) = build(false, vertex_cap);
    if starved && polygon.area > LATTICE_FROM * max_area {
        (cdt, handles, refused, _) = build(true, vertex_cap);
    }
    // The bounded passes leave elements over the cap where they ran out of vertices (or a
    // Delaunay cavity made one), and skinny ones where the lines' small features took the
    // vertices: the repair finishes both above SHAPE_FLOOR of the cap.
    if cdt.num_vertices() >= 3 && !cdt.all_vertices_on_line() {
        let limit = (4.0 * polygon.area / (SHAPE_FLOOR * max_area)).min(1e8) as usize
            + 16 * (polygon.boundary.len() + arr.edges.len() + points.len())
            + 64;
        let cap = max_area.max(polygon.area * 1e-9);
        repair(&mut cdt, polygon, cap, SHAPE_FLOOR * cap, limit);
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

/// Vertices in a row beside each corner line ([`Kind::Corner`], inside the polygon) and on
/// both sides of each contact line ([`Kind::D0`]), [`STRIP_OFFSET`] times the side of an
/// element away, so that the elements along them are thin. The light another surface
/// reflects onto a receiver changes fastest where that surface meets it (a wall's foot beside
/// the sunlit street, the street beside the wall), and an element's mean over the whole band
/// misses that rise; the strip is inside the budget, since the budget search meshes with it.
/// None in a polygon no larger than one element or more than [`STRIP_UP_TO`] elements across.
fn corner_strip(
    polygon: &Polygon,
    segments: &[Segment],
    max_area: f64,
    obstacles: &Obstacles,
) -> Vec<DVec2> {
    let perimeter: f64 = polygon.boundary.iter().map(|[a, b]| a.distance(*b)).sum();
    let across = 2.0 * polygon.area / perimeter.max(1e-300);
    if polygon.area <= max_area || across > STRIP_UP_TO * max_area.sqrt() {
        return Vec::new();
    }
    let offset = STRIP_OFFSET * max_area.sqrt();
    let mut out = Vec::new();
    for s in segments.iter().filter(|s| !s.kind.is_wedge()) {
        let along = s.b - s.a;
        let len = along.length();
        if len < 2.0 * offset {
            continue;
        }
        let u = along / len;
        // About twice the offset apart along the line, from one offset inside its ends.
        let steps = (len / (2.0 * offset)).round().max(1.0) as usize;
        for k in 0..=steps {
            let base = s.a + u * (offset + (len - 2.0 * offset) * k as f64 / steps as f64);
            for side in [u.perp(), -u.perp()] {
                let q = base + side * offset;
                if polygon.contains(q) && !obstacles.near(q, 0.5 * offset) {
                    out.push(q);
                }
            }
        }
    }
    out
}

/// Points of a lattice of equilateral triangles of [`LATTICE_FILL`] times `max_area` (scene
/// units²) over the box `lo..hi`, inside `polygon` and at least [`LATTICE_CLEAR`] lattice steps
/// from every segment of `obstacles` (the outline and the lines): refinement grades the band
/// beside them.
fn open_lattice(
    polygon: &Polygon,
    lo: DVec2,
    hi: DVec2,
    max_area: f64,
    obstacles: &Obstacles,
) -> Vec<DVec2> {
    let step = (4.0 * LATTICE_FILL * max_area / 3f64.sqrt()).sqrt();
    let row = step * 3f64.sqrt() / 2.0;
    let sites = (hi - lo).x / step * (hi - lo).y / row;
    // Every site is tested against the polygon's triangles: left out where that would cost more
    // than the refinement it saves (a long diagonal strip, a finely tessellated polygon).
    if step.is_nan() || step <= 0.0 || sites > 16.0 * polygon.area / (step * row) + 1024.0 {
        return Vec::new();
    }
    if sites * polygon.triangles_plane.len() as f64 > LATTICE_TESTS {
        return Vec::new();
    }
    let rows = ((hi.y - lo.y) / row).ceil() as usize;
    let columns = ((hi.x - lo.x) / step).ceil() as usize + 1;
    let mut out = Vec::new();
    for j in 1..rows {
        let y = lo.y + j as f64 * row;
        let shift = if j % 2 == 1 { 0.5 * step } else { 0.0 };
        for i in 0..columns {
            let q = DVec2::new(lo.x + shift + i as f64 * step, y);
            if q.x < hi.x && polygon.contains(q) && !obstacles.near(q, LATTICE_CLEAR * step) {
                out.push(q);
            }
        }
    }
    out
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

/// Most rounds of [`repair`].
const REPAIR_ROUNDS: usize = 24;

/// Repairs the faces of `cdt` inside `polygon` that are larger than `max_area`, or larger
/// than `floor` (scene units²) with an angle under [`ANGLE_LIMIT_DEG`] outside a corner where
/// constraints meet at less: each round, every such face gets its circumcentre inserted where
/// it lies in the polygon with no constraint between it and the face, and otherwise splits the
/// first constraint edge in the way at its midpoint (Ruppert's rule, "A Delaunay refinement
/// algorithm for quality 2-dimensional mesh generation", 1995, applied to these faces only).
/// Unlike spade's refinement it never splits a constraint edge only because a vertex
/// encroaches it: among a real city's thousands of close lines those splits cascade (in the
/// repair's place, spade's refinement gave Munich's ground 4 times its elements, half of them
/// under 1e-4 of the cap). At most `limit` vertices.
fn repair(
    cdt: &mut ConstrainedDelaunayTriangulation<Point2<f64>>,
    polygon: &Polygon,
    max_area: f64,
    floor: f64,
    limit: usize,
) {
    let angle_limit = ANGLE_LIMIT_DEG.to_radians();
    let start = cdt.num_vertices();
    for _ in 0..REPAIR_ROUNDS {
        let mut centres: Vec<Point2<f64>> = Vec::new();
        let mut splits: Vec<[FixedVertexHandle; 2]> = Vec::new();
        for f in cdt.inner_faces() {
            let p = f.positions().map(|p| DVec2::new(p.x, p.y));
            let area = crate::geometry::signed_area(&p);
            if area < floor {
                continue;
            }
            let centroid = (p[0] + p[1] + p[2]) / 3.0;
            if !polygon.contains(centroid) {
                continue;
            }
            let vertices = f.vertices();
            // The constraints at a corner, as directions (radians).
            let forced = |k: usize, a, b| {
                let dirs: Vec<f64> = vertices[k]
                    .out_edges()
                    .filter(|e| e.is_constraint_edge())
                    .map(|e| {
                        let d = e.to().position();
                        let d = DVec2::new(d.x, d.y) - p[k];
                        d.y.atan2(d.x)
                    })
                    .collect();
                crate::geometry::inside_narrow_corner(&dirs, a, b, angle_limit)
            };
            let bad = area > max_area
                || crate::geometry::small_angles_of(&p, angle_limit, forced)
                    .0
                    .is_some();
            if !bad {
                continue;
            }
            let c = f.circumcenter();
            let from = Point2::new(centroid.x, centroid.y);
            match cdt.get_conflicting_edges_between_points(from, c).next() {
                Some(e) => splits.push(e.vertices().map(|v| v.fix())),
                None if polygon.contains(DVec2::new(c.x, c.y)) => centres.push(c),
                None => {}
            }
        }
        if centres.is_empty() && splits.is_empty() {
            break;
        }
        for [a, b] in splits {
            if cdt.num_vertices() - start >= limit {
                return;
            }
            split_constraint(cdt, a, b);
        }
        for c in centres {
            if cdt.num_vertices() - start >= limit {
                return;
            }
            let _ = cdt.insert(c);
        }
    }
}

/// Splits the constraint edge from `a` to `b`, if there still is one, at its midpoint: the
/// midpoint is inserted and the two halves are constraints (rounding puts it a hair off the
/// line, where spade would not split the edge itself).
fn split_constraint(
    cdt: &mut ConstrainedDelaunayTriangulation<Point2<f64>>,
    a: FixedVertexHandle,
    b: FixedVertexHandle,
) {
    let Some(edge) = cdt.get_edge_from_neighbors(a, b) else {
        return;
    };
    if !edge.is_constraint_edge() {
        return;
    }
    let edge = edge.fix().as_undirected();
    let [pa, pb] = [a, b].map(|v| cdt.vertex(v).position());
    let m = Point2::new(0.5 * (pa.x + pb.x), 0.5 * (pa.y + pb.y));
    cdt.remove_constraint_edge(edge);
    let split = match cdt.insert(m) {
        Ok(v) if v != a && v != b => {
            !cdt.try_add_constraint(a, v).is_empty() && !cdt.try_add_constraint(v, b).is_empty()
        }
        _ => false,
    };
    if !split {
        cdt.try_add_constraint(a, b);
    }
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
