//! The shared types of the patch solvers (progressive refinement, classic radiosity): the
//! coarse patches, and the linear system over them.
//!
//! Irradiance `H` and radiosity `B` in W/m² per linear RGB channel.

use crate::geometry::triangle_area;
use crate::scene::Scene;
use glam::DVec3;

/// A coarse patch of the indirect solve: one triangle.
#[derive(Clone, Debug)]
pub struct Patch {
    /// Index into [`Scene::polygons`].
    pub polygon: usize,
    pub(crate) p: [DVec3; 3],
    pub normal: DVec3,
    pub centroid: DVec3,
    pub(crate) area: f64,
    pub(crate) rho: DVec3,
    /// Bounding radius around the centroid.
    pub(crate) radius: f64,
}

impl Patch {
    fn new(polygon: usize, p: [DVec3; 3], normal: DVec3, rho: DVec3) -> Patch {
        let centroid = (p[0] + p[1] + p[2]) / 3.0;
        let area = triangle_area(&p);
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
        let albedo = crate::scene::AlbedoOver::new(scene, m.polygon);
        for t in &m.triangles {
            let p = t.map(|i| poly.frame.world_from_plane(m.vertices[i as usize]));
            let rho = albedo.mean(&t.map(|i| m.vertices[i as usize]));
            out.push(Patch::new(m.polygon, p, poly.frame.n, rho));
        }
    }
    out
}

/// The linear system of the patch solvers: `B_i = M_i + rho_i H_i`, `H_i = D_i + sum_j F_ij B_j`
/// (Goral, Torrance, Greenberg, Battaile 1984), with `F_ij` the form factor from patch `i`'s
/// centroid to patch `j`. W/m² per linear RGB channel.
pub(crate) struct PatchSystem<'a> {
    pub(crate) patches: &'a [Patch],
    /// `D`: the irradiance the form factors do not carry (the direct light computed apart: all
    /// of it, or with hemicube form factors only the punctual lights').
    pub(crate) direct: Vec<DVec3>,
    /// `M`: the emitted radiosity carried by the form factors (with hemicube form factors the
    /// area emitters', `pi L`; otherwise 0).
    pub(crate) emission: Vec<DVec3>,
}

impl<'a> PatchSystem<'a> {
    pub(crate) fn new(patches: &'a [Patch], direct: Vec<DVec3>, emission: Vec<DVec3>) -> Self {
        PatchSystem {
            patches,
            direct,
            emission,
        }
    }

    /// The source of the system, `S_i = M_i + rho_i D_i`: `B = S + rho F B`.
    pub(crate) fn source(&self) -> Vec<DVec3> {
        self.patches
            .iter()
            .zip(&self.direct)
            .zip(&self.emission)
            .map(|((p, d), m)| *m + p.rho * *d)
            .collect()
    }

    /// True when the form factors carry emitted light, whose first transfer is then the direct
    /// light rather than a bounce.
    pub(crate) fn emits(&self) -> bool {
        self.emission.iter().any(|m| m.max_element() > 0.0)
    }

    /// Power of a radiosity (or irradiance) per patch, W (mean over RGB).
    pub(crate) fn power(&self, b: &[DVec3]) -> f64 {
        self.patches
            .iter()
            .zip(b)
            .map(|(p, b)| b.element_sum() / 3.0 * p.area)
            .sum()
    }
}
