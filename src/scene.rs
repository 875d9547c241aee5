//! The scene as the baker sees it: world-space triangles grouped into planar receiver polygons,
//! Lambertian materials, area emitters and punctual lights.
//!
//! Built by [`crate::load`]; everything downstream reads it. Lengths are in scene units (glTF:
//! metres), colours are linear RGB triples (`DVec3`).

use glam::{DVec2, DVec3};
use std::collections::BTreeMap;
use std::sync::Arc;

pub(crate) mod cut;
pub(crate) mod emission;
pub mod mixed;
pub(crate) mod surface;
pub(crate) mod texture;

pub(crate) use surface::{AlbedoOver, Base, Passes};

/// The geometric tolerances of every stage, as fractions of [`Scene::extent`] (times it: scene
/// units), so a scene bakes alike at any size. Three levels, by the rounding each must absorb:
pub(crate) mod tolerance {
    /// Points computed along different paths that stand for the same point (a texel corner
    /// found again, a box flat in one axis): f64 rounds each operation to about 1e-16 of the
    /// magnitudes involved, so 1e-9 leaves room for millions of operations and is still far
    /// below any modelled feature.
    pub(crate) const COINCIDENT: f64 = 1e-9;
    /// Input geometry that stands for the same point or plane (the triangles of one planar
    /// polygon, a point set in from an edge): glTF stores coordinates as f32, rounded to about
    /// 6e-8 of their magnitude, so 1e-6 is above that with a margin of about 16. A typical
    /// triangle is larger than this ([`crate::load::MAX_EXTENT_RATIO`]).
    pub(crate) const INPUT: f64 = 1e-6;
    /// How far rays start off their surfaces and stop short of their targets
    /// ([`crate::visibility::Visibility::epsilon`]): the BVH intersects in f32, about 1e-7 of
    /// the extent, and 1e-5 is a hundred times that.
    pub(crate) const RAY: f64 = 1e-5;
}

/// The largest albedo a surface is given: an albedo of 1 reflects everything it receives, so
/// the bounces in a closed room never converge.
pub(crate) const MAX_ALBEDO: f64 = 0.99;

/// A Lambertian surface material.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// Name from the glTF file (for messages).
    pub name: String,
    /// Diffuse reflectance `rho` in 0..1 per channel: baseColorFactor x mean of baseColorTexture.
    pub rho: DVec3,
    /// Emitted radiance `L_e` in W/(m² sr) per channel (front face only); exitance is `pi L_e`.
    pub radiance: DVec3,
    /// Where the colour varies over the surface (a base-colour texture, an alpha test): how.
    /// `None`: `rho` everywhere.
    pub(crate) base: Option<Base>,
}

impl Material {
    /// True when the material emits light.
    pub(crate) fn is_emitter(&self) -> bool {
        self.radiance.max_element() > 0.0
    }
}

/// One world-space triangle of a static mesh instance.
#[derive(Clone, Debug)]
pub struct Triangle {
    /// Corners in world space, counter-clockwise seen from the front.
    pub p: [DVec3; 3],
    /// Unit geometric normal (front side).
    pub normal: DVec3,
    /// Index into [`Scene::materials`].
    pub(crate) material: usize,
    /// Index into [`Scene::instances`].
    pub(crate) instance: usize,
    /// Index of the triangle within its instance's index list (`indices[3k..3k+3]`).
    pub(crate) local_index: usize,
    /// Index into [`Scene::polygons`], or `None` for degenerate triangles, which receive nothing.
    pub polygon: Option<usize>,
}

impl Triangle {
    /// Area in square scene units.
    pub(crate) fn area(&self) -> f64 {
        crate::geometry::triangle_area(&self.p)
    }
}

/// An orthonormal frame of a plane: `p_world = origin + x u + y v`, normal `n = u x v`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    pub origin: DVec3,
    pub(crate) u: DVec3,
    pub(crate) v: DVec3,
    pub n: DVec3,
}

impl Frame {
    /// A frame through `origin` with normal `n` and first axis along `u_hint` projected into the
    /// plane (any perpendicular axis when `u_hint` is parallel to `n`).
    pub(crate) fn new(origin: DVec3, n: DVec3, u_hint: DVec3) -> Frame {
        let n = n.normalize();
        let mut u = u_hint - n * n.dot(u_hint);
        if u.length_squared() < 1e-20 {
            u = n.any_orthonormal_vector();
        }
        let u = u.normalize();
        let v = n.cross(u);
        Frame { origin, u, v, n }
    }

    /// World point to plane coordinates (orthogonal projection).
    pub fn plane_from_world(&self, p_world: DVec3) -> DVec2 {
        let d = p_world - self.origin;
        DVec2::new(d.dot(self.u), d.dot(self.v))
    }

    /// Plane coordinates to the world point on the plane.
    pub fn world_from_plane(&self, q_plane: DVec2) -> DVec3 {
        self.origin + self.u * q_plane.x + self.v * q_plane.y
    }
}

/// A planar receiver: coplanar, edge-connected triangles of one material and one instance.
#[derive(Clone, Debug)]
pub struct Polygon {
    /// Index into [`Scene::materials`].
    pub material: usize,
    /// Index into [`Scene::instances`].
    pub instance: usize,
    /// Indices into [`Scene::triangles`].
    pub triangles: Vec<usize>,
    /// The plane's frame: `world_from_plane` maps 2D outline coordinates to the world.
    pub frame: Frame,
    /// The triangles in plane coordinates (same order as `triangles`).
    pub triangles_plane: Vec<[DVec2; 3]>,
    /// Boundary edges (edges used by one triangle only) in plane coordinates, oriented with the
    /// polygon on their left.
    pub(crate) boundary: Vec<[DVec2; 2]>,
    /// Area in square scene units.
    pub area: f64,
}

impl Polygon {
    /// True when the plane point lies inside one of the polygon's triangles (edges included,
    /// with a tolerance relative to the triangle size).
    pub fn contains(&self, q: DVec2) -> bool {
        self.triangles_plane.iter().any(|t| point_in_triangle(q, t))
    }
}

/// Inside-or-on test of a 2D point against a triangle, with a small relative tolerance.
pub(crate) fn point_in_triangle(q: DVec2, t: &[DVec2; 3]) -> bool {
    let area2 = (t[1] - t[0]).perp_dot(t[2] - t[0]);
    if area2 == 0.0 {
        return false;
    }
    let s = area2.signum();
    let tol = -1e-9 * area2.abs();
    (0..3).all(|i| s * (t[(i + 1) % 3] - t[i]).perp_dot(q - t[i]) >= tol)
}

/// The kind of a punctual light (KHR_lights_punctual).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum LightKind {
    /// Omnidirectional point light; intensity in W/sr (glTF: candela).
    Point,
    /// Spot light with cone angles in radians (glTF defaults: inner 0, outer pi/4).
    Spot { inner_cone: f64, outer_cone: f64 },
    /// Directional light; intensity is irradiance in W/m² (glTF: lux) on a surface facing it.
    Directional,
}

/// A punctual light in world space.
#[derive(Clone, Debug, PartialEq)]
pub struct PunctualLight {
    pub(crate) kind: LightKind,
    /// Name (or `light N`), for messages.
    pub(crate) name: String,
    /// Position in world space (unused for directional lights).
    pub position: DVec3,
    /// Unit direction the light points to (spot and directional; the node's -z axis).
    pub direction: DVec3,
    /// colour x intensity: W/sr per channel for point and spot, W/m² for directional.
    pub intensity: DVec3,
    /// Range in scene units beyond which the light has no effect (glTF `range`), if any.
    pub(crate) range: Option<f64>,
    /// The glTF node that places it, and its index in `KHR_lights_punctual.lights`.
    pub(crate) node: usize,
    pub(crate) index: usize,
}

/// Which side of a glTF primitive an [`Instance`] is.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Side {
    /// The primitive as written: its front faces are counter-clockwise.
    #[default]
    Front,
    /// The back of a primitive whose material is `doubleSided`: the same positions with every
    /// triangle's winding reversed, added right after its front instance. Its triangles are
    /// ordinary one-sided receivers facing the other way, so every stage treats them like any
    /// other surface.
    Back,
}

/// A static mesh primitive placed by one node: the unit that gets its own lightmap space.
#[derive(Clone, Debug)]
pub struct Instance {
    /// glTF node index.
    pub node: usize,
    /// Which of the node's `EXT_mesh_gpu_instancing` instances this is, if the node has them.
    pub gpu_instance: Option<u32>,
    /// glTF mesh index.
    pub mesh: usize,
    /// Primitive index within the mesh.
    pub primitive: usize,
    /// glTF material index, if the primitive has one.
    pub(crate) gltf_material: Option<usize>,
    /// Vertex positions in world space (the primitive's vertices, one per glTF vertex).
    pub positions_world: Vec<DVec3>,
    /// Triangle list over `positions_world` (strips and fans expanded, winding fixed for mirrors).
    pub indices: Vec<u32>,
    /// True when the node's transform mirrors (negative determinant): `indices` then has the
    /// second and third corner of every glTF triangle swapped so fronts face the right way.
    pub mirrored: bool,
    /// Front, or the back side of a double-sided primitive (its `indices` reversed).
    pub side: Side,
    /// Index of this instance's first triangle in [`Scene::triangles`]; its triangles are
    /// consecutive, one per `indices` triple.
    pub first_triangle: usize,
    /// Vertices added by [`cut::cut_long_edges`], in order: vertex `positions_world.len() -
    /// derived.len() + i` is `derived[i]`. Empty when nothing was cut.
    pub derived: Vec<Derived>,
    /// Linear RGB per glTF vertex from `COLOR_0`, which multiplies the material's base colour:
    /// per mesh element ([`AlbedoOver`]); a polygon's material takes its area-weighted mean
    /// where one colour stands for the polygon ([`Scene::add_instance`]).
    pub(crate) colours: Option<Vec<DVec3>>,
    /// The material [`Scene::add_instance`] was given (before any `colours` tint).
    pub(crate) material: usize,
    /// Per `TEXCOORD_n` set that the material's textures read: its coordinates per glTF
    /// vertex (without a texture's transform).
    pub(crate) uvs: BTreeMap<u32, Vec<DVec2>>,
    /// Per triangle, its own emitted radiance, when the material's emission comes from a
    /// texture and the triangles were split where it changes ([`emission`]).
    pub(crate) emission: Option<Vec<DVec3>>,
}

/// A vertex that is not in the glTF primitive: a weighted mean of up to three of its vertices
/// (the corners of the glTF triangle it lies in), with weights summing to 1.
#[derive(Clone, Debug, PartialEq)]
pub struct Derived {
    /// (glTF vertex index, weight) pairs, ascending by vertex.
    pub(crate) weights: Vec<(u32, f64)>,
}

impl Instance {
    /// The front side of node 0's mesh 0 primitive 0, nothing mirrored or cut: a triangle list
    /// over world positions, for scenes built in code.
    #[cfg(test)]
    pub(crate) fn new(positions_world: Vec<DVec3>, indices: Vec<u32>) -> Instance {
        Instance {
            node: 0,
            gpu_instance: None,
            mesh: 0,
            primitive: 0,
            gltf_material: None,
            positions_world,
            indices,
            mirrored: false,
            side: Side::Front,
            first_triangle: 0,
            derived: Vec::new(),
            colours: None,
            material: 0,
            uvs: BTreeMap::new(),
            emission: None,
        }
    }

    /// Number of the primitive's own glTF vertices (the first ones of `positions_world`).
    pub(crate) fn source_vertices(&self) -> usize {
        self.positions_world.len() - self.derived.len()
    }

    /// True when the triangles, welded by exact position, close a volume: every edge is used
    /// by exactly two triangles, once in each direction (a consistently wound closed
    /// surface, such as a box exported with all six faces). The back of such a surface lies
    /// inside the volume, where no ray from outside reaches: a double-sided material on it
    /// gives it no back side. Degenerate triangles (two corners at one position) are ignored.
    pub fn is_closed(&self) -> bool {
        let mut weld: BTreeMap<[u64; 3], u32> = BTreeMap::new();
        let id: Vec<u32> = self
            .positions_world
            .iter()
            .map(|p| {
                let n = weld.len() as u32;
                *weld
                    .entry([p.x.to_bits(), p.y.to_bits(), p.z.to_bits()])
                    .or_insert(n)
            })
            .collect();
        let mut directed: BTreeMap<(u32, u32), u32> = BTreeMap::new();
        for t in self.indices.chunks_exact(3) {
            let v = [id[t[0] as usize], id[t[1] as usize], id[t[2] as usize]];
            if v[0] == v[1] || v[1] == v[2] || v[2] == v[0] {
                continue;
            }
            for e in 0..3 {
                *directed.entry((v[e], v[(e + 1) % 3])).or_default() += 1;
            }
        }
        !directed.is_empty()
            && directed
                .iter()
                .all(|(&(a, b), &n)| n == 1 && directed.get(&(b, a)) == Some(&1))
    }

    /// The back side of this (front) instance: the same vertices, every triangle's second and
    /// third corner swapped.
    pub(crate) fn back_side(&self) -> Instance {
        let mut indices = self.indices.clone();
        for t in indices.chunks_exact_mut(3) {
            t.swap(1, 2);
        }
        Instance {
            indices,
            side: Side::Back,
            ..self.clone()
        }
    }
}

/// A warning that does not stop the bake (skipped items, degenerate triangles).
pub(crate) type Warning = String;

/// A tinted material's key: the material, the vertex-colour mean's bits, the radiance's bits.
type Tint = (usize, [u64; 3], Option<[u64; 3]>);

/// The whole scene.
#[derive(Clone, Debug)]
pub struct Scene {
    pub materials: Vec<Material>,
    pub triangles: Vec<Triangle>,
    pub polygons: Vec<Polygon>,
    pub instances: Vec<Instance>,
    pub lights: Vec<PunctualLight>,
    /// Axis-aligned bounds of all triangles, world space.
    pub bounds_min: DVec3,
    pub bounds_max: DVec3,
    /// What the loader skipped or repaired.
    pub warnings: Vec<Warning>,
    /// The decoded base-colour images that materials' [`Base::texture`] index (shared with
    /// the ray queries' alpha test).
    pub(crate) images: Arc<Vec<texture::Image>>,
    /// The material of each (material, vertex-colour tint) made so far ([`Scene::add_instance`]).
    tints: BTreeMap<Tint, usize>,
    /// How each light is baked and into which layer ([`mixed`]): all lights fully into the
    /// one lightmap unless the bake's rules say otherwise.
    pub(crate) mixed: mixed::Mixed,
}

impl Default for Scene {
    fn default() -> Scene {
        Scene {
            materials: Vec::new(),
            triangles: Vec::new(),
            polygons: Vec::new(),
            instances: Vec::new(),
            lights: Vec::new(),
            bounds_min: DVec3::INFINITY,
            bounds_max: DVec3::NEG_INFINITY,
            warnings: Vec::new(),
            images: Arc::default(),
            tints: BTreeMap::new(),
            mixed: mixed::Mixed::default(),
        }
    }
}

impl Scene {
    /// Length of the bounding box diagonal: the scale for every geometric tolerance.
    pub fn extent(&self) -> f64 {
        let d = (self.bounds_max - self.bounds_min).length();
        if d.is_finite() { d.max(1e-30) } else { 1.0 }
    }

    /// Indices of the polygons whose material emits light (area emitters).
    pub fn emitters(&self) -> impl Iterator<Item = usize> + '_ {
        self.polygons
            .iter()
            .enumerate()
            .filter(|(_, p)| self.materials[p.material].is_emitter())
            .map(|(i, _)| i)
    }

    /// True when the scene has at least one area emitter or punctual light.
    pub(crate) fn has_light(&self) -> bool {
        !self.lights.is_empty() || self.emitters().next().is_some()
    }

    /// The same triangle on the other side of a double-sided surface (the back copy of a front
    /// triangle, or the front of a back one); `None` for one-sided surfaces.
    pub fn twin_triangle(&self, t: usize) -> Option<usize> {
        let tri = &self.triangles[t];
        let inst = &self.instances[tri.instance];
        let other = match inst.side {
            Side::Back => tri.instance.checked_sub(1)?,
            Side::Front => tri.instance + 1,
        };
        let o = self.instances.get(other)?;
        let twin = match inst.side {
            Side::Back => o.side == Side::Front,
            Side::Front => o.side == Side::Back,
        } && o.node == inst.node
            && o.mesh == inst.mesh
            && o.primitive == inst.primitive;
        twin.then(|| o.first_triangle + tri.local_index)
    }

    /// True when triangle `t` is on the back side of a double-sided primitive.
    pub(crate) fn is_back(&self, t: usize) -> bool {
        self.instances[self.triangles[t].instance].side == Side::Back
    }

    /// True when polygon `p` is on the back side of a double-sided primitive.
    pub fn is_back_polygon(&self, p: usize) -> bool {
        self.instances[self.polygons[p].instance].side == Side::Back
    }

    /// The polygon on the other side of polygon `p` of a double-sided surface (the polygon of
    /// its first triangle's twin), if any.
    pub(crate) fn twin_polygon(&self, p: usize) -> Option<usize> {
        self.twin_triangle(*self.polygons[p].triangles.first()?)
            .and_then(|t| self.triangles[t].polygon)
    }

    /// Appends an instance's triangles and groups them into polygons. `positions_world` and
    /// `indices` describe a triangle list; `material` indexes [`Scene::materials`].
    pub(crate) fn add_instance(&mut self, mut instance: Instance, material: usize) {
        let id = self.instances.len();
        instance.first_triangle = self.triangles.len();
        instance.material = material;
        let first = self.triangles.len();
        for (k, tri) in instance.indices.chunks_exact(3).enumerate() {
            let p = [
                instance.positions_world[tri[0] as usize],
                instance.positions_world[tri[1] as usize],
                instance.positions_world[tri[2] as usize],
            ];
            let cross = (p[1] - p[0]).cross(p[2] - p[0]);
            let len = cross.length();
            let normal = if len > 0.0 { cross / len } else { DVec3::ZERO };
            for q in p {
                self.bounds_min = self.bounds_min.min(q);
                self.bounds_max = self.bounds_max.max(q);
            }
            self.triangles.push(Triangle {
                p,
                normal,
                material,
                instance: id,
                local_index: k,
                polygon: None,
            });
        }
        self.instances.push(instance);
        let last = self.triangles.len();
        let polygons = self.polygons.len();
        self.merge_polygons(first..last, material, id);
        self.tint_polygons(polygons, id);
    }

    /// Gives each polygon from `first` on (all of instance `id`'s) the material it was made
    /// with, tinted: times the area-weighted mean of the instance's vertex colours over it (the
    /// mean of the linear interpolation over each triangle is its corners' mean), and emitting
    /// its triangles' own radiance where the instance has one per triangle ([`emission`]).
    /// Polygons of one tint share one material.
    fn tint_polygons(&mut self, first: usize, id: usize) {
        let inst = &self.instances[id];
        if inst.colours.is_none() && inst.emission.is_none() {
            return;
        }
        let has_colours = inst.colours.is_some();
        let tints: Vec<(DVec3, Option<DVec3>)> = self.polygons[first..]
            .iter()
            .map(|poly| {
                let mean = inst.colours.as_ref().map_or(DVec3::ONE, |colours| {
                    let (mut sum, mut area) = (DVec3::ZERO, 0.0);
                    for &t in &poly.triangles {
                        let tri = &self.triangles[t];
                        let k = tri.local_index;
                        let c = (0..3)
                            .map(|e| inst.attribute(colours, inst.indices[3 * k + e]))
                            .sum::<DVec3>()
                            / 3.0;
                        sum += c * tri.area();
                        area += tri.area();
                    }
                    if area > 0.0 { sum / area } else { DVec3::ONE }
                });
                // Every triangle of a polygon emits alike (they merge only then).
                let radiance = inst
                    .emission
                    .as_ref()
                    .map(|e| e[self.triangles[poly.triangles[0]].local_index]);
                (mean, radiance)
            })
            .collect();
        for (i, (mean, radiance)) in tints.into_iter().enumerate() {
            let base = self.polygons[first + i].material;
            let bits = |v: DVec3| v.to_array().map(f64::to_bits);
            let key = (base, bits(mean), radiance.map(bits));
            let m = match self.tints.get(&key) {
                Some(&m) => m,
                None => {
                    let b = &self.materials[base];
                    let mut name = b.name.clone();
                    if has_colours {
                        name.push_str(" x COLOR_0");
                    }
                    if radiance.is_some() {
                        name.push_str(" (part of its emissive texture)");
                    }
                    let tinted = Material {
                        name,
                        rho: (b.rho * mean)
                            .clamp(DVec3::ZERO, DVec3::splat(MAX_ALBEDO)),
                        radiance: radiance.unwrap_or(b.radiance),
                        base: b.base.clone(),
                    };
                    self.materials.push(tinted);
                    self.tints.insert(key, self.materials.len() - 1);
                    self.materials.len() - 1
                }
            };
            self.polygons[first + i].material = m;
            for t in self.polygons[first + i].triangles.clone() {
                self.triangles[t].material = m;
            }
        }
    }

    /// Groups the triangles in `range` into planar polygons: flood fill over shared edges
    /// (vertices welded by position) between triangles whose planes agree.
    fn merge_polygons(&mut self, range: std::ops::Range<usize>, material: usize, instance: usize) {
        // Weld vertices by exact world position so split vertices (different normals or UVs) still
        // connect their triangles.
        let mut weld: BTreeMap<[u64; 3], u32> = BTreeMap::new();
        let welded: Vec<u32> = self.instances[instance]
            .positions_world
            .iter()
            .map(|p| {
                let key = [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()];
                let n = weld.len() as u32;
                *weld.entry(key).or_insert(n)
            })
            .collect();
        let tri_vertices = tri_vertices_of(self, &welded, instance);
        let mut edges: BTreeMap<(u32, u32), Vec<usize>> = BTreeMap::new();
        for t in range.clone() {
            if self.triangles[t].normal == DVec3::ZERO {
                continue;
            }
            let v = tri_vertices(t);
            for e in 0..3 {
                let (a, b) = (v[e], v[(e + 1) % 3]);
                edges.entry((a.min(b), a.max(b))).or_default().push(t);
            }
        }
        let tol = tolerance::INPUT * self.extent().max(1e-12);
        // Triangles that emit differently (parts of an emissive texture) stay apart.
        let emission = self.instances[instance].emission.as_ref();
        let emits = |t: usize| emission.map(|e| e[self.triangles[t].local_index]);
        let mut assigned = vec![false; range.len()];
        let mut new_polygons = Vec::new();
        for seed in range.clone() {
            if assigned[seed - range.start] || self.triangles[seed].normal == DVec3::ZERO {
                continue;
            }
            assigned[seed - range.start] = true;
            let n0 = self.triangles[seed].normal;
            let o0 = self.triangles[seed].p[0];
            let mut members = vec![seed];
            let mut stack = vec![seed];
            while let Some(t) = stack.pop() {
                let v = tri_vertices(t);
                for e in 0..3 {
                    let (a, b) = (v[e], v[(e + 1) % 3]);
                    for &nb in &edges[&(a.min(b), a.max(b))] {
                        let i = nb - range.start;
                        if assigned[i] {
                            continue;
                        }
                        let tn = &self.triangles[nb];
                        let coplanar = tn.normal.dot(n0) > 1.0 - 1e-9
                            && tn.p.iter().all(|q| (q - o0).dot(n0).abs() <= tol)
                            && emits(nb) == emits(seed);
                        if coplanar {
                            assigned[i] = true;
                            members.push(nb);
                            stack.push(nb);
                        }
                    }
                }
            }
            members.sort_unstable();
            new_polygons.push(members);
        }
        let polygons: Vec<Polygon> = new_polygons
            .iter()
            .map(|members| self.make_polygon(members, material, instance, &tri_vertices))
            .collect();
        drop(tri_vertices);
        for polygon in polygons {
            let id = self.polygons.len();
            for &t in &polygon.triangles {
                self.triangles[t].polygon = Some(id);
            }
            self.polygons.push(polygon);
        }
    }

    fn make_polygon(
        &self,
        members: &[usize],
        material: usize,
        instance: usize,
        welded_tris: &dyn Fn(usize) -> [u32; 3],
    ) -> Polygon {
        // Area-weighted normal, origin at the first vertex, u along the longest edge of the
        // largest triangle (a stable, deterministic choice).
        let mut normal = DVec3::ZERO;
        let mut area = 0.0;
        let mut largest = members[0];
        for &t in members {
            let tri = &self.triangles[t];
            let a = tri.area();
            normal += tri.normal * a;
            area += a;
            if a > self.triangles[largest].area() {
                largest = t;
            }
        }
        let lt = &self.triangles[largest];
        let mut u_hint = lt.p[1] - lt.p[0];
        for e in 1..3 {
            let d = lt.p[(e + 1) % 3] - lt.p[e];
            if d.length_squared() > u_hint.length_squared() {
                u_hint = d;
            }
        }
        let frame = Frame::new(self.triangles[members[0]].p[0], normal, u_hint);
        let triangles_plane: Vec<[DVec2; 3]> = members
            .iter()
            .map(|&t| self.triangles[t].p.map(|q| frame.plane_from_world(q)))
            .collect();
        // Boundary edges: welded edges used by exactly one member triangle.
        let mut count: BTreeMap<(u32, u32), (usize, usize)> = BTreeMap::new();
        for (m, &t) in members.iter().enumerate() {
            let v = welded_tris(t);
            for e in 0..3 {
                let (a, b) = (v[e], v[(e + 1) % 3]);
                let entry = count.entry((a.min(b), a.max(b))).or_insert((0, 0));
                entry.0 += 1;
                entry.1 = m * 3 + e;
            }
        }
        let mut boundary = Vec::new();
        for (_, (c, me)) in count {
            if c == 1 {
                let t = &triangles_plane[me / 3];
                let e = me % 3;
                boundary.push([t[e], t[(e + 1) % 3]]);
            }
        }
        Polygon {
            material,
            instance,
            triangles: members.to_vec(),
            frame,
            triangles_plane,
            boundary,
            area,
        }
    }
}

fn tri_vertices_of<'a>(
    scene: &'a Scene,
    welded: &'a [u32],
    instance: usize,
) -> impl Fn(usize) -> [u32; 3] + 'a {
    move |t: usize| {
        let inst = &scene.instances[instance];
        let k = scene.triangles[t].local_index;
        let i = &inst.indices[3 * k..3 * k + 3];
        [
            welded[i[0] as usize],
            welded[i[1] as usize],
            welded[i[2] as usize],
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A unit cube's six faces (two triangles each, outward), as one instance; `drop` faces
    /// left out from the end.
    fn cube(drop: usize) -> Instance {
        let c = crate::geometry::box_corners(DVec3::ZERO, DVec3::ONE);
        let mut positions = Vec::new();
        let mut indices = Vec::new();
        for f in &crate::geometry::BOX_FACES[..6 - drop] {
            // Every face its own four vertices (split normals), as exporters write boxes.
            let base = positions.len() as u32;
            positions.extend(f.iter().map(|&i| c[i as usize]));
            indices.extend([base, base + 1, base + 2, base, base + 2, base + 3]);
        }
        Instance::new(positions, indices)
    }

    #[test]
    fn a_box_with_all_faces_is_closed_and_an_open_one_is_not() {
        let closed = cube(0);
        assert!(closed.is_closed());
        assert!(!cube(1).is_closed(), "no bottom");
        assert!(
            closed.back_side().is_closed(),
            "turned inside out, still closed"
        );
        // The same faces twice (front and back in one primitive) use each edge four times.
        let mut both = closed.clone();
        let back = closed.back_side();
        let n = both.positions_world.len() as u32;
        both.positions_world
            .extend(back.positions_world.iter().copied());
        both.indices.extend(back.indices.iter().map(|i| i + n));
        assert!(!both.is_closed());
        // One quad is open.
        assert!(!quad_instance([DVec3::ZERO, DVec3::X, DVec3::ONE, DVec3::Y]).is_closed());
    }

    fn quad_instance(corners: [DVec3; 4]) -> Instance {
        Instance::new(corners.to_vec(), vec![0, 1, 2, 0, 2, 3])
    }

    fn grey() -> Material {
        Material {
            name: "grey".into(),
            rho: DVec3::splat(0.5),
            radiance: DVec3::ZERO,
            base: None,
        }
    }

    #[test]
    fn coplanar_quad_merges_into_one_polygon_with_four_boundary_edges() {
        let mut scene = Scene::default();
        scene.materials.push(grey());
        let inst = quad_instance([
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(1.0, 0.0, 0.0),
            DVec3::new(1.0, 0.0, -1.0),
            DVec3::new(0.0, 0.0, -1.0),
        ]);
        scene.add_instance(inst, 0);
        assert_eq!(scene.polygons.len(), 1);
        let poly = &scene.polygons[0];
        assert_eq!(poly.boundary.len(), 4);
        assert!((poly.area - 1.0).abs() < 1e-12);
        assert!((poly.frame.n - DVec3::Y).length() < 1e-12);
        assert!(poly.contains(poly.frame.plane_from_world(DVec3::new(0.5, 0.0, -0.5))));
        assert!(!poly.contains(poly.frame.plane_from_world(DVec3::new(1.5, 0.0, -0.5))));
    }

    #[test]
    fn folded_quad_gives_two_polygons() {
        let mut scene = Scene::default();
        scene.materials.push(grey());
        let inst = quad_instance([
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(1.0, 0.0, 0.0),
            DVec3::new(1.0, 0.5, -1.0),
            DVec3::new(0.0, 0.0, -1.0),
        ]);
        scene.add_instance(inst, 0);
        assert_eq!(scene.polygons.len(), 2);
    }

    #[test]
    fn frame_round_trips() {
        let f = Frame::new(
            DVec3::new(1.0, 2.0, 3.0),
            DVec3::new(0.3, 0.9, -0.1),
            DVec3::X,
        );
        let p = f.world_from_plane(DVec2::new(0.25, -4.0));
        assert!((f.plane_from_world(p) - DVec2::new(0.25, -4.0)).length() < 1e-12);
        assert!(f.n.dot(f.u).abs() < 1e-12 && f.n.dot(f.v).abs() < 1e-12);
    }
}
