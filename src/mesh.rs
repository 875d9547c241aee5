//! Receiver meshes: per polygon, a constrained Delaunay triangulation (spade) of its outline,
//! refined to a maximum element area.
//!
//! Every mesher produces the same [`ReceiverMesh`], so the solve, atlas and lightmap stages are
//! shared and comparisons between meshers are fair by construction. Refinement is Ruppert/Chew
//! Delaunay refinement as implemented by spade (Shewchuk, "Delaunay refinement algorithms for
//! triangular mesh generation", 2002).

use crate::scene::{Polygon, Scene};
use glam::DVec2;
use rayon::prelude::*;
use spade::{
    AngleLimit, ConstrainedDelaunayTriangulation, Point2, RefinementParameters, Triangulation,
};

/// Which mesher builds the receiver meshes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Mesher {
    /// Quality Delaunay refinement of each polygon's outline to an area cap from the budget.
    #[default]
    Uniform,
    /// Discontinuity meshing (not built yet).
    Discontinuity,
    /// A-posteriori adaptive meshing (not built yet).
    Adaptive,
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
}

impl ReceiverMesh {
    /// Total area of the triangles (scene units²).
    pub fn area(&self) -> f64 {
        self.triangles.iter().map(|t| tri_area(self, t)).sum()
    }
}

fn tri_area(m: &ReceiverMesh, t: &[u32; 3]) -> f64 {
    let [a, b, c] = t.map(|i| m.vertices[i as usize]);
    0.5 * (b - a).perp_dot(c - a)
}

/// Minimum angle for quality refinement, degrees.
pub const ANGLE_LIMIT_DEG: f64 = 25.0;

/// Triangulates one polygon: its boundary as constraints, refined so that no triangle is larger
/// than `max_area` (scene units²) and, where the outline allows, none has an angle under
/// [`ANGLE_LIMIT_DEG`]. At most `vertex_cap` vertices are added by refinement. Faces outside
/// the polygon (holes, concavities) are dropped by testing each face's centroid against the
/// polygon's own triangles.
pub fn triangulate(id: usize, polygon: &Polygon, max_area: f64, vertex_cap: usize) -> ReceiverMesh {
    let mut cdt = ConstrainedDelaunayTriangulation::<Point2<f64>>::new();
    for [a, b] in &polygon.boundary {
        let (Ok(va), Ok(vb)) = (
            cdt.insert(Point2::new(a.x, a.y)),
            cdt.insert(Point2::new(b.x, b.y)),
        ) else {
            continue;
        };
        if va != vb {
            // Never panics; an edge that would cross an existing constraint is left out and the
            // inside test below still decides which faces belong to the polygon.
            cdt.try_add_constraint(va, vb);
        }
    }
    if cdt.num_vertices() >= 3 && !cdt.all_vertices_on_line() {
        let params = RefinementParameters::<f64>::new()
            .with_angle_limit(AngleLimit::from_deg(ANGLE_LIMIT_DEG))
            .with_max_allowed_area(max_area.max(polygon.area * 1e-9))
            .with_min_required_area(max_area * 1e-3)
            .with_max_additional_vertices(vertex_cap)
            .exclude_outer_faces(true);
        cdt.refine(params);
    }
    let mut mesh = ReceiverMesh {
        polygon: id,
        ..Default::default()
    };
    let mut remap = vec![u32::MAX; cdt.num_vertices()];
    for face in cdt.inner_faces() {
        let pos = face.positions().map(|p| DVec2::new(p.x, p.y));
        let centroid = (pos[0] + pos[1] + pos[2]) / 3.0;
        if !polygon.contains(centroid) {
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
    mesh
}

/// The uniform mesher: every polygon refined to one area cap, chosen so that the whole scene
/// has about `budget` triangles (never fewer than each polygon's own outline needs).
pub fn uniform(scene: &Scene, budget: usize) -> Vec<ReceiverMesh> {
    let total_area: f64 = scene.polygons.iter().map(|p| p.area).sum();
    let budget = budget.max(1) as f64;
    let mesh_all = |max_area: f64| -> Vec<ReceiverMesh> {
        scene
            .polygons
            .par_iter()
            .enumerate()
            .map(|(i, p)| {
                let expected = (p.area / max_area).ceil() as usize;
                let cap = 4 * expected + 4 * p.boundary.len() + 64;
                triangulate(i, p, max_area, cap)
            })
            .collect()
    };
    // Refinement leaves triangles between a quarter and all of the cap, so measure once at
    // area/budget and rescale.
    let first_area = total_area / budget;
    let first = mesh_all(first_area);
    let count: usize = first.iter().map(|m| m.triangles.len()).sum();
    let scaled = first_area * count as f64 / budget;
    if (count as f64 - budget).abs() / budget < 0.1 {
        first
    } else {
        mesh_all(scaled)
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
        scene.add_instance(
            Instance {
                node: 0,
                mesh: 0,
                primitive: 0,
                gltf_material: None,
                positions_world: corners,
                indices,
                mirrored: false,
                first_triangle: 0,
            },
            0,
        );
        scene
    }

    #[test]
    fn uniform_mesh_covers_the_polygon_and_meets_the_budget() {
        let scene = floor_scene(
            vec![
                DVec3::new(0.0, 0.0, 0.0),
                DVec3::new(2.0, 0.0, 0.0),
                DVec3::new(2.0, 0.0, -1.0),
                DVec3::new(0.0, 0.0, -1.0),
            ],
            vec![0, 1, 2, 0, 2, 3],
        );
        let meshes = uniform(&scene, 500);
        assert_eq!(meshes.len(), 1);
        let m = &meshes[0];
        assert!((m.area() - 2.0).abs() < 1e-9, "area {}", m.area());
        let n = m.triangles.len();
        assert!(
            (300..=700).contains(&n),
            "{n} triangles for a budget of 500"
        );
        assert!(m.triangles.iter().all(|t| tri_area(m, t) > 0.0));
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
