use super::transfer::{point_bound, projected_bound};
use super::tree::Node;
use super::*;
use crate::geometry::point_polygon_form_factor;
use crate::light::NO_POLYGON;
use glam::DVec2;
use std::f64::consts::PI;

/// The Cornell box's hierarchy at about 2 000 elements.
fn cornell() -> Hierarchy {
    let gltf = crate::load::from_bytes(
        crate::fixtures::cornell_box(),
        std::path::Path::new("cornell.glb"),
    )
    .expect("fixture parses");
    let options = crate::BakeOptions {
        budget: Some(2000),
        resolution: Some(128),
        ..Default::default()
    };
    let b = crate::bake(&gltf, &options, &|_, _, _| {}).expect("bake");
    let vis = Visibility::new(&b.scene);
    Hierarchy::build(&b.scene, &vis, &b.meshes, &b.solution.direct).expect("elements")
}

/// A source split's form factors from its parent's ([`Hierarchy::source_split_factors`])
/// are what each child's own contour sums give, to rounding, for every surface pair where
/// they apply (and they apply often enough that the test cannot pass empty).
#[test]
fn a_split_sources_form_factors_are_its_parents_minus_the_other_childs() {
    let h = cornell();
    let surfaces: Vec<u32> = (0..h.nodes.len() as u32)
        .filter(|&i| h.nodes[i as usize].polygon != NO_POLYGON)
        .step_by(7)
        .collect();
    let (mut derived, mut pairs) = (0, 0);
    for &r in &surfaces {
        for &s in surfaces.iter().step_by(5) {
            let Some(kids) = h.nodes[s as usize].kids else {
                continue;
            };
            if h.culled(r, s) {
                continue;
            }
            let Some(f) = h.point_factors(r, s) else {
                continue;
            };
            pairs += 1;
            for (kid, got) in kids.iter().zip(h.source_split_factors(r, s, f, kids)) {
                let Some((got, n)) = got else { continue };
                let (want, m) = h.point_factors(r, *kid).expect("a child's contour applies");
                assert_eq!(n, m);
                for i in 0..n {
                    let tol = 1e-12 * (1.0 + f.0[i]);
                    assert!(
                        (got[i] - want[i]).abs() <= tol,
                        "{r} <- {kid}: sample {i}: {} derived, {} summed",
                        got[i],
                        want[i]
                    );
                }
                derived += 1;
            }
        }
    }
    assert!(
        pairs > 1000 && derived > 2000,
        "{derived} derived of {pairs} pairs"
    );
}

/// [`point_bound`] bounds the unoccluded form factor from every receiver sample to the
/// source (summed over the source's elements, each clipped to the sample's horizon), for
/// surface and cluster nodes alike; the projected-area term is the binding one for most
/// of the pairs checked (15 456, with 65 863 samples), so a wrong one fails here (a
/// quarter of it did).
#[test]
fn the_point_bound_bounds_the_point_form_factors() {
    let h = cornell();
    let nodes: Vec<u32> = (0..h.nodes.len() as u32).step_by(13).collect();
    let (mut checked, mut tightened) = (0, 0);
    for &r in &nodes {
        for &s in nodes.iter().step_by(3) {
            let (nr, ns) = (&h.nodes[r as usize], &h.nodes[s as usize]);
            if r == s || ns.hi - ns.lo > 64 || h.culled(r, s) {
                continue;
            }
            let bound = point_bound(nr, ns);
            for a in &h.samples[r as usize] {
                let f: f64 = h.elements[ns.lo as usize..ns.hi as usize]
                    .iter()
                    .filter(|e| e.normal.dot(a.p - e.p[0]) > 0.0)
                    .map(|e| point_polygon_form_factor(a.p, a.n, &e.p))
                    .sum();
                assert!(
                    f <= bound * (1.0 + 1e-9) + 1e-12,
                    "{r} <- {s}: {f} over {bound}"
                );
                checked += 1;
            }
            let d = nr.center.distance(ns.center) - nr.radius;
            let gap = (d - ns.radius).max(0.0);
            let disk = ns.area / (PI * gap * gap + ns.area);
            let sphere = if d > ns.radius {
                (ns.radius / d).powi(2)
            } else {
                1.0
            };
            tightened += usize::from(bound < disk.min(sphere));
        }
    }
    assert!(
        checked > 10_000 && tightened > 100,
        "{checked} checked, {tightened} tightened"
    );
}

/// Links are the solver's memory: keep them at 48 bytes.
#[test]
fn a_link_is_48_bytes() {
    assert_eq!(std::mem::size_of::<Link>(), 48);
}

/// A node of the six unit faces of a cube: projected area 1 along each axis direction.
fn cube() -> Node {
    Node {
        lo: 0,
        hi: 6,
        kids: None,
        polygon: NO_POLYGON,
        area: 6.0,
        rho: DVec3::splat(0.5),
        direct: 0.0,
        min: DVec3::ZERO,
        max: DVec3::ONE,
        center: DVec3::splat(0.5),
        radius: 0.75f64.sqrt(),
        normal: DVec3::ZERO,
        proj: [DVec3::ONE, DVec3::ONE],
    }
}

/// The cube's exact projected area towards `w` (unit): the faces facing it, each by its
/// cosine.
fn cube_projected(w: DVec3) -> f64 {
    w.abs().element_sum()
}

/// `projected_bound` is exact for a cone of zero width, and bounds the projected area
/// towards every direction of a wider cone.
#[test]
fn projected_bound_bounds_every_direction_in_the_cone() {
    let n = cube();
    let diagonal = DVec3::new(1.0, 1.0, 0.0).normalize();
    for u in [DVec3::X, diagonal, DVec3::ONE.normalize()] {
        let exact = projected_bound(&n, u, (0.0, 1.0));
        assert!((exact - cube_projected(u)).abs() < 1e-12, "{u}: {exact}");
    }
    for alpha in [0.1f64, 0.5, 1.0, 1.5] {
        let cone = (alpha.sin(), alpha.cos());
        for u in [DVec3::X, diagonal, DVec3::new(0.3, -0.8, 0.52).normalize()] {
            let bound = projected_bound(&n, u, cone);
            let (a, b) = u.any_orthonormal_pair();
            for i in 0..16 {
                for j in 0..=8 {
                    let phi = std::f64::consts::TAU * f64::from(i) / 16.0;
                    let theta = alpha * f64::from(j) / 8.0;
                    let w = u * theta.cos() + (a * phi.cos() + b * phi.sin()) * theta.sin();
                    assert!(
                        cube_projected(w) <= bound + 1e-12,
                        "alpha {alpha}, axis {u}: {} > {bound}",
                        cube_projected(w)
                    );
                }
            }
            assert!(bound <= 6.0 + 1e-12);
        }
    }
    // A hemisphere about +x: every face but the one facing -x may face along it.
    assert!((projected_bound(&n, DVec3::X, (1.0, 0.0)) - 5.0).abs() < 1e-12);
}

/// A 1 x 0.5 rectangle in 4 x 2 squares, two triangles each, and its elements' means of
/// `field` (by the centroid rule: exact for a linear field).
fn grid_mesh(field: impl Fn(DVec2) -> DVec3) -> (ReceiverMesh, Vec<(u32, f64, DVec3)>) {
    let (nx, ny) = (4u32, 2u32);
    let vertices: Vec<DVec2> = (0..=ny)
        .flat_map(|j| (0..=nx).map(move |i| DVec2::new(i as f64 * 0.25, j as f64 * 0.25)))
        .collect();
    let id = |i: u32, j: u32| j * (nx + 1) + i;
    let triangles: Vec<[u32; 3]> = (0..ny)
        .flat_map(|j| (0..nx).map(move |i| (i, j)))
        .flat_map(|(i, j)| {
            let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            [[a, b, c], [a, c, d]]
        })
        .collect();
    let mesh = ReceiverMesh {
        polygon: 0,
        vertices,
        triangles,
        constraints: Vec::new(),
    };
    let items = mesh
        .triangles
        .iter()
        .enumerate()
        .map(|(t, tri)| {
            let [a, b, c] = tri.map(|v| mesh.vertices[v as usize]);
            (t as u32, 0.03125, field((a + b + c) / 3.0))
        })
        .collect();
    (mesh, items)
}

/// A mesh's vertex values reproduce a linear irradiance from its elements' means at every
/// vertex, at the mesh's edges and corners too, where the mean of the elements around a
/// vertex stands for a point inside them (a third of an element in).
#[test]
fn vertex_values_reproduce_a_linear_irradiance_up_to_the_edges() {
    let field = |p: DVec2| DVec3::new(1.0 + 2.0 * p.x, 3.0 - p.y, 0.5 + p.x + p.y);
    let (mesh, items) = grid_mesh(field);
    let got = vertex_indirect(&mesh, &items);
    for (v, h) in got.iter().enumerate() {
        let want = field(mesh.vertices[v]);
        let h = h.expect("every vertex is used");
        // The Tikhonov term shrinks the gradient by about 0.1%.
        assert!(
            (h - want).abs().max_element() < 2e-3,
            "vertex {v}: {h} {want}"
        );
    }
    assert_eq!(got.len(), 15);
}

/// Interpolated linearly between the vertices (as the lightmap shows them), the vertex
/// values keep each element's mean irradiance better than the mean of the elements around
/// each vertex, which flattens a peak and lifts the edges (RMS of the elements' interpolated
/// means against theirs, measured: 0.043 against 0.120 of the peak).
#[test]
fn vertex_values_keep_the_elements_mean_irradiance_under_a_peak() {
    let field = |p: DVec2| {
        DVec3::splat((1.0 - 4.0 * (p - DVec2::new(0.5, 0.25)).length_squared()).max(0.0))
    };
    let (mesh, items) = grid_mesh(field);
    let rms = |values: &[DVec3]| {
        let sq: f64 = items
            .iter()
            .map(|&(t, _, h)| {
                let c = mesh.triangles[t as usize].map(|v| values[v as usize].x);
                ((c[0] + c[1] + c[2]) / 3.0 - h.x).powi(2)
            })
            .sum();
        (sq / items.len() as f64).sqrt()
    };
    let fitted: Vec<DVec3> = vertex_indirect(&mesh, &items)
        .into_iter()
        .flatten()
        .collect();
    let mut sum = vec![(DVec3::ZERO, 0.0); mesh.vertices.len()];
    for &(t, a, h) in &items {
        for v in mesh.triangles[t as usize] {
            sum[v as usize].0 += h * a;
            sum[v as usize].1 += a;
        }
    }
    let averaged: Vec<DVec3> = sum.iter().map(|(s, w)| *s / *w).collect();
    let (fitted, averaged) = (rms(&fitted), rms(&averaged));
    assert!(
        fitted < 0.5 * averaged,
        "fitted {fitted}, averaged {averaged}"
    );
}

/// A surface node's sample points stand for its area: the mean of the exact point form
/// factors from its samples to a source is the area-weighted mean over its elements' centroids,
/// on a discontinuity mesh whose elements are smallest along its lines (the Cornell box's,
/// graded towards the boxes' contacts and shadows). Samples taken at quantiles of the element
/// count instead sit mostly along those lines, where a node's light is least like its mean:
/// there the error is measured too, and must be larger.
#[test]
fn a_nodes_samples_give_its_area_mean_form_factor() {
    let h = cornell();
    let ff = |p: DVec3, n: DVec3, s: &Node| {
        h.elements[s.lo as usize..s.hi as usize]
            .iter()
            .map(|e| point_polygon_form_factor(p, n, &e.p))
            .sum::<f64>()
    };
    let centroid = |e: &Element| (e.p[0] + e.p[1] + e.p[2]) / 3.0;
    let nodes = &h.nodes;
    let surfaces = |least: u32| {
        (0..nodes.len())
            .filter(move |&i| {
                let n = &nodes[i];
                n.polygon != NO_POLYGON && n.hi - n.lo >= least
            })
            .collect::<Vec<_>>()
    };
    let sources: Vec<usize> = surfaces(64).into_iter().step_by(3).collect();
    let (mut by_area, mut by_count, mut pairs) = (0.0, 0.0, 0);
    let (mut signed_area, mut signed_count) = (0.0, 0.0);
    for r in surfaces(16) {
        let nr = &h.nodes[r];
        let els = &h.elements[nr.lo as usize..nr.hi as usize];
        for &s in &sources {
            let ns = &h.nodes[s];
            if ns.polygon == nr.polygon {
                continue;
            }
            let exact = els
                .iter()
                .map(|e| e.area * ff(centroid(e), e.normal, ns))
                .sum::<f64>()
                / nr.area;
            if exact < 1e-3 {
                continue;
            }
            let samples = &h.samples[r];
            let area_mean =
                samples.iter().map(|q| ff(q.p, q.n, ns)).sum::<f64>() / samples.len() as f64;
            let count = els.len();
            let count_mean = (0..4)
                .map(|k| {
                    let e = &els[(2 * k + 1) * count / 8];
                    ff(centroid(e), e.normal, ns)
                })
                .sum::<f64>()
                / 4.0;
            by_area += (area_mean / exact - 1.0).abs();
            by_count += (count_mean / exact - 1.0).abs();
            signed_area += area_mean / exact - 1.0;
            signed_count += count_mean / exact - 1.0;
            pairs += 1;
        }
    }
    let (by_area, by_count) = (by_area / pairs as f64, by_count / pairs as f64);
    let (signed_area, signed_count) = (signed_area / pairs as f64, signed_count / pairs as f64);
    eprintln!(
        "{pairs} links: mean error {by_area:.4} by area, {by_count:.4} by count; \
         bias {signed_area:.4} by area, {signed_count:.4} by count"
    );
    assert!(pairs > 100, "{pairs} pairs");
    // Four points are a coarse quadrature (6.5% per link here): the errors must not add up to
    // a bias, and must be well under the count quantiles' (12.6%).
    assert!(
        by_area < 0.08,
        "mean error of the samples' form factor {by_area}"
    );
    assert!(
        signed_area.abs() < 0.01,
        "bias of the samples' form factor {signed_area}"
    );
    assert!(
        by_area < 0.6 * by_count,
        "{by_area} by area, {by_count} by count"
    );
}
