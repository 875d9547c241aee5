//! The solved light as a ray sees it: the reflected radiosity `rho H` (W/m²) where a ray first
//! meets a receiver, read from the solved irradiance at the mesh vertices (interpolated in the
//! mesh) and the albedo at the hit. The final gathers of the light probes
//! ([`crate::probes`]) and of the directional lightmap's bounce directions
//! ([`super::light_vector`]) both read the solution this way.

use crate::geometry::barycentric_3d;
use crate::lightmap::Locator;
use crate::mesh::ReceiverMesh;
use crate::scene::Scene;
use crate::visibility::Visibility;
use glam::DVec3;

/// The receivers' solved irradiance, located by the rays that meet them.
pub(crate) struct Reflected<'a> {
    scene: &'a Scene,
    locators: Vec<Locator<'a>>,
    mesh_of_polygon: Vec<usize>,
}

/// What a ray meets first.
pub(crate) enum Seen {
    /// Nothing, or a surface without a receiver mesh.
    Nothing,
    /// The back of a one-sided surface.
    Back,
    /// A receiver's front, reflecting `rho H` (W/m², per channel) at the hit.
    Radiosity(DVec3),
}

impl<'a> Reflected<'a> {
    /// The solved `irradiance` at the vertices of `meshes`.
    pub(crate) fn new(
        scene: &'a Scene,
        meshes: &'a [ReceiverMesh],
        irradiance: &'a [Vec<DVec3>],
    ) -> Reflected<'a> {
        Reflected {
            scene,
            locators: meshes
                .iter()
                .zip(irradiance)
                .map(|(m, v)| Locator::new(m, v))
                .collect(),
            mesh_of_polygon: crate::mesh::mesh_of_polygon(scene, meshes),
        }
    }

    /// What the ray from `origin` along unit `d` meets first.
    pub(crate) fn along(&self, vis: &Visibility, origin: DVec3, d: DVec3) -> Seen {
        let Some(hit) = vis.first_hit(origin, d, f64::MAX) else {
            return Seen::Nothing;
        };
        let scene = self.scene;
        let tri = &scene.triangles[hit.triangle];
        if tri.normal.dot(d) >= 0.0 {
            return Seen::Back;
        }
        let Some(poly) = tri.polygon else {
            return Seen::Nothing;
        };
        let Some(locator) = self
            .mesh_of_polygon
            .get(poly)
            .and_then(|&k| self.locators.get(k))
        else {
            return Seen::Nothing;
        };
        let x = origin + d * hit.t;
        let bary = barycentric_3d(&tri.p, x);
        let q = scene.polygons[poly].frame.plane_from_world(x);
        Seen::Radiosity(scene.albedo_at(hit.triangle, bary) * locator.value(q))
    }
}
