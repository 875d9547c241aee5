//! Generated glTF 2.0 test scenes, and the small binary glTF (`.glb`) writer that makes them.
//!
//! [`GlbBuilder`] collects materials, triangle meshes, cameras, `KHR_lights_punctual` lights and
//! nodes, and [`GlbBuilder::to_glb`] writes them as one self-contained glb file. The scene
//! functions ([`cornell_box`], [`square_occluder`], [`box_on_floor`], [`furnace_box`],
//! [`point_light`], [`spot_light`], [`directional_light`], [`plane_uniform`], [`instanced`]) build
//! the project's test scenes; `cargo run --example make_fixtures` writes them to `fixtures/`.
//!
//! Conventions, the same as glTF's and the rest of penumbra's:
//!
//! * lengths in metres, y up, right-handed;
//! * front faces wind counter-clockwise (CCW) seen from the front, and vertex normals point to
//!   the front;
//! * base colour = diffuse reflectance, linear, each channel in `[0, 1]`; materials are
//!   dielectric (`metallicFactor` 0, `roughnessFactor` 1);
//! * emission is stored as emitted radiance `L_e` in W/(m² sr) (linear RGB): glTF's
//!   `emissiveFactor` (each component at most 1) times `KHR_materials_emissive_strength`'s
//!   `emissiveStrength` (written only when some component of `L_e` exceeds 1). A Lambertian
//!   emitter's exitance is `M = π L_e` in W/m²;
//! * punctual lights use `KHR_lights_punctual` units: point and spot intensity in candela
//!   (lm/sr), directional illuminance in lux (lm/m²); they shine along their node's local -z.
//!
//! Output is deterministic: the same calls give the same bytes on every run (no hash-map
//! iteration, JSON keys in insertion order, numbers printed shortest round-trip).
//!
//! Vertex positions, normals and texture coordinates are given in `f64` and stored as `f32`.
//! Every accessor has its own tightly packed buffer view, 4-byte aligned, with the right
//! `target`; indices are `u16` when the primitive has at most 65 535 vertices (so the primitive
//! restart value 65 535 is never used), `u32` otherwise.

use std::collections::BTreeSet;
use std::f64::consts::PI;

use glam::{DMat3, DMat4, DQuat, DVec3};
use serde_json::{Map, Value, json};

/// The failure sweep: scenes where each meshing method is known to break down.
pub mod failure;

/// The scale ladder: generated towns and a house interior of game-level size (about 5 000 to
/// 100 000 triangles), for measuring how the baker scales.
pub mod ladder;

/// glTF `bufferView.target` for vertex attributes.
const ARRAY_BUFFER: u32 = 34962;
/// glTF `bufferView.target` for indices.
const ELEMENT_ARRAY_BUFFER: u32 = 34963;
/// glTF `componentType` codes.
const UNSIGNED_SHORT: u32 = 5123;
const UNSIGNED_INT: u32 = 5125;
const FLOAT: u32 = 5126;

/// glb magic `glTF`, little-endian.
const GLB_MAGIC: u32 = 0x4654_6C67;
/// glb chunk type `JSON`.
const CHUNK_JSON: u32 = 0x4E4F_534A;
/// glb chunk type `BIN\0`.
const CHUNK_BIN: u32 = 0x004E_4942;

/// Name of the glTF extension for emitted radiance above 1.
pub const KHR_MATERIALS_EMISSIVE_STRENGTH: &str = "KHR_materials_emissive_strength";
/// Name of the glTF extension for point, spot and directional lights.
pub const KHR_LIGHTS_PUNCTUAL: &str = "KHR_lights_punctual";

// ---------------------------------------------------------------------------------------------
// Geometry
// ---------------------------------------------------------------------------------------------

/// Indexed triangle-list geometry: one glTF mesh primitive (mode 4, `TRIANGLES`).
///
/// Triangles wind CCW seen from their front. Positions are in metres in the mesh's local frame.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TriangleMesh {
    /// Vertex positions, metres (written as `POSITION`, `VEC3` of `f32`).
    pub positions: Vec<[f64; 3]>,
    /// Optional per-vertex unit normals, one per position (written as `NORMAL`, normalised).
    pub normals: Option<Vec<[f64; 3]>>,
    /// Optional per-vertex texture coordinates, one per position, unitless (written as
    /// `TEXCOORD_0`).
    pub texcoords: Option<Vec<[f64; 2]>>,
    /// Vertex indices, three per triangle, CCW seen from the front.
    pub indices: Vec<u32>,
}

impl TriangleMesh {
    /// Number of triangles (`indices.len() / 3`).
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }

    /// Appends `other`'s vertices and triangles (re-indexed). Both meshes must agree on
    /// whether they carry normals and texture coordinates (an empty `self` takes `other`'s).
    ///
    /// # Panics
    /// If the attribute sets differ.
    pub fn append(&mut self, other: &TriangleMesh) {
        if self.positions.is_empty() && self.indices.is_empty() {
            *self = other.clone();
            return;
        }
        assert_eq!(
            self.normals.is_some(),
            other.normals.is_some(),
            "TriangleMesh::append: both meshes must have normals, or neither"
        );
        assert_eq!(
            self.texcoords.is_some(),
            other.texcoords.is_some(),
            "TriangleMesh::append: both meshes must have texcoords, or neither"
        );
        let base = u32::try_from(self.positions.len()).expect("too many vertices");
        self.positions.extend_from_slice(&other.positions);
        if let (Some(a), Some(b)) = (self.normals.as_mut(), other.normals.as_ref()) {
            a.extend_from_slice(b);
        }
        if let (Some(a), Some(b)) = (self.texcoords.as_mut(), other.texcoords.as_ref()) {
            a.extend_from_slice(b);
        }
        self.indices.extend(other.indices.iter().map(|&i| i + base));
    }

    /// Turns every triangle around: reverses the winding and negates the normals, so the front
    /// becomes the back. Used to make inward-facing boxes from [`cuboid`].
    pub fn flip(&mut self) {
        for tri in self.indices.chunks_exact_mut(3) {
            tri.swap(1, 2);
        }
        if let Some(normals) = self.normals.as_mut() {
            for n in normals {
                *n = n.map(|c| -c);
            }
        }
    }

    /// Returns the mesh with the given per-vertex texture coordinates (`TEXCOORD_0`).
    ///
    /// # Panics
    /// If `texcoords.len() != self.positions.len()`.
    pub fn with_texcoords(mut self, texcoords: Vec<[f64; 2]>) -> Self {
        assert_eq!(
            texcoords.len(),
            self.positions.len(),
            "one texcoord per vertex"
        );
        self.texcoords = Some(texcoords);
        self
    }

    /// Geometric normal of triangle `t` (unit; from the winding, not the vertex normals).
    pub fn face_normal(&self, t: usize) -> [f64; 3] {
        let [a, b, c] =
            [0, 1, 2].map(|k| DVec3::from(self.positions[self.indices[3 * t + k] as usize]));
        (b - a).cross(c - a).normalize().into()
    }

    /// Axis-aligned bounds of the positions, metres: `(min, max)`.
    ///
    /// # Panics
    /// If the mesh has no vertices.
    pub fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        assert!(!self.positions.is_empty(), "bounds of an empty mesh");
        let mut lo = DVec3::splat(f64::INFINITY);
        let mut hi = DVec3::splat(f64::NEG_INFINITY);
        for &p in &self.positions {
            lo = lo.min(p.into());
            hi = hi.max(p.into());
        }
        (lo.into(), hi.into())
    }
}

/// A planar (or nearly planar) quadrilateral as two triangles, `(0,1,2)` and `(0,2,3)`.
///
/// `corners` in metres, in CCW order seen from the front. The four vertices share one normal,
/// the quad's area-weighted normal `(c2 - c0) × (c3 - c1)` normalised, which for a non-planar
/// quad (the Cornell box's red wall) is the average of the two triangles' orientations.
/// No texture coordinates.
///
/// # Panics
/// If the quad is degenerate (zero area).
pub fn quad(corners: [[f64; 3]; 4]) -> TriangleMesh {
    let c = corners.map(DVec3::from);
    let n = (c[2] - c[0]).cross(c[3] - c[1]);
    assert!(n.length() > 1e-12, "degenerate quad {corners:?}");
    let n: [f64; 3] = n.normalize().into();
    TriangleMesh {
        positions: corners.to_vec(),
        normals: Some(vec![n; 4]),
        texcoords: None,
        indices: vec![0, 1, 2, 0, 2, 3],
    }
}

/// A horizontal rectangle `[x0, x1] × [z0, z1]` at height `y` (metres), facing up (+y) when
/// `up` is true, down (-y) otherwise. Two triangles, one shared normal.
pub fn horizontal_rect(x: [f64; 2], z: [f64; 2], y: f64, up: bool) -> TriangleMesh {
    let [x0, x1] = x;
    let [z0, z1] = z;
    // Seen from above (+y), (x0,z0) -> (x0,z1) -> (x1,z1) -> (x1,z0) is CCW.
    let corners = [[x0, y, z0], [x0, y, z1], [x1, y, z1], [x1, y, z0]];
    let mut m = quad(corners);
    if !up {
        m.flip();
    }
    m
}

/// A prism dropped from a quad: the top face `top` (metres, CCW seen from above, so it faces
/// +y) and four vertical sides reaching down to height `base_y`, plus the bottom face (facing
/// -y) when `bottom` is true. All faces face outward; each face is its own quad (4 vertices,
/// flat normal, no vertex shared between faces): 5 or 6 faces, 10 or 12 triangles.
///
/// The top need not be horizontal-rectangular: this is how the Cornell box's rotated blocks
/// are built.
///
/// # Panics
/// If the top does not face +y or lies below `base_y`.
pub fn block(top: [[f64; 3]; 4], base_y: f64, bottom: bool) -> TriangleMesh {
    let mut m = quad(top);
    assert!(
        m.normals.as_ref().unwrap()[0][1] > 0.0,
        "block top must face +y (CCW from above)"
    );
    assert!(
        top.iter().all(|p| p[1] > base_y),
        "block top must lie above base_y"
    );
    let bot = top.map(|[x, _, z]| [x, base_y, z]);
    for i in 0..4 {
        let j = (i + 1) % 4;
        // For a CCW top with normal N and edge e = top_j - top_i, e × N points out; this
        // winding's normal is (bot_i - top_i) × (bot_j - top_i) = h (e × N).
        m.append(&quad([top[i], bot[i], bot[j], top[j]]));
    }
    if bottom {
        m.append(&quad([bot[3], bot[2], bot[1], bot[0]]));
    }
    m
}

/// An axis-aligned box from `min` to `max` (metres): 6 outward-facing quads, 12 triangles,
/// 24 vertices. [`flip`] it for a closed room seen from inside.
pub fn cuboid(min: [f64; 3], max: [f64; 3]) -> TriangleMesh {
    let [x0, y0, z0] = min;
    let [x1, y1, z1] = max;
    assert!(
        x0 < x1 && y0 < y1 && z0 < z1,
        "cuboid: min must be below max"
    );
    block(
        [[x0, y1, z0], [x0, y1, z1], [x1, y1, z1], [x1, y1, z0]],
        y0,
        true,
    )
}

/// Returns `mesh` turned inside out (see [`TriangleMesh::flip`]).
pub fn flip(mut mesh: TriangleMesh) -> TriangleMesh {
    mesh.flip();
    mesh
}

// ---------------------------------------------------------------------------------------------
// Materials, cameras, lights, nodes
// ---------------------------------------------------------------------------------------------

/// A diffuse, optionally emissive glTF material.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// Material name (written as `name`).
    pub name: String,
    /// Diffuse reflectance, linear RGB, each in `[0, 1]` (`pbrMetallicRoughness.baseColorFactor`,
    /// alpha 1).
    pub base_color: [f64; 3],
    /// Emitted radiance `L_e`, linear RGB, W/(m² sr), each `>= 0`; all zero for a non-emitter.
    /// Written as `emissiveFactor` times `KHR_materials_emissive_strength` (see
    /// [`Material::emissive_factor_and_strength`]).
    pub emission: [f64; 3],
    /// Whether both sides of the surface are front faces (`doubleSided`).
    pub double_sided: bool,
}

impl Material {
    /// A one-sided, non-emissive diffuse material with reflectance `base_color` (linear RGB,
    /// each in `[0, 1]`).
    pub fn diffuse(name: &str, base_color: [f64; 3]) -> Self {
        Material {
            name: name.to_owned(),
            base_color,
            emission: [0.0; 3],
            double_sided: false,
        }
    }

    /// Returns the material emitting radiance `radiance` (linear RGB, W/(m² sr)).
    pub fn emitting(mut self, radiance: [f64; 3]) -> Self {
        self.emission = radiance;
        self
    }

    /// Returns the material made double-sided.
    pub fn double_sided(mut self) -> Self {
        self.double_sided = true;
        self
    }

    /// Splits the emitted radiance `L_e` into glTF's `emissiveFactor` (each component in
    /// `[0, 1]`) and `emissiveStrength` (`>= 1`, unitless multiplier) with
    /// `factor * strength = L_e`: strength is `max(L_e)` when that exceeds 1, else 1.
    pub fn emissive_factor_and_strength(&self) -> ([f64; 3], f64) {
        let m = self.emission.iter().copied().fold(0.0, f64::max);
        if m > 1.0 {
            (self.emission.map(|c| c / m), m)
        } else {
            (self.emission, 1.0)
        }
    }

    fn uses_emissive_strength(&self) -> bool {
        self.emissive_factor_and_strength().1 != 1.0
    }

    fn validate(&self) {
        assert!(
            self.base_color.iter().all(|c| (0.0..=1.0).contains(c)),
            "material {:?}: base colour must be in [0, 1]",
            self.name
        );
        assert!(
            self.emission.iter().all(|c| c.is_finite() && *c >= 0.0),
            "material {:?}: emission must be finite and >= 0",
            self.name
        );
    }

    fn to_json(&self) -> Value {
        let [r, g, b] = self.base_color;
        let mut m = Map::new();
        m.insert("name".into(), json!(self.name));
        m.insert(
            "pbrMetallicRoughness".into(),
            json!({ "baseColorFactor": [num(r), num(g), num(b), 1.0], "metallicFactor": 0.0 }),
        );
        let (factor, strength) = self.emissive_factor_and_strength();
        if factor.iter().any(|&c| c > 0.0) {
            m.insert("emissiveFactor".into(), json!(factor.map(num)));
        }
        if strength != 1.0 {
            m.insert(
                "extensions".into(),
                json!({ KHR_MATERIALS_EMISSIVE_STRENGTH: { "emissiveStrength": num(strength) } }),
            );
        }
        if self.double_sided {
            m.insert("doubleSided".into(), json!(true));
        }
        Value::Object(m)
    }
}

/// A perspective camera (glTF `camera.perspective`). It looks along its node's local -z with
/// local +y up.
#[derive(Clone, Debug, PartialEq)]
pub struct PerspectiveCamera {
    /// Camera name.
    pub name: String,
    /// Vertical field of view, radians, in `(0, π)`.
    pub yfov: f64,
    /// Width / height of the view; `None` leaves it to the viewport.
    pub aspect_ratio: Option<f64>,
    /// Near clipping distance, metres, `> 0`.
    pub znear: f64,
    /// Far clipping distance, metres, `> znear`; `None` for an infinite projection.
    pub zfar: Option<f64>,
}

impl PerspectiveCamera {
    fn to_json(&self) -> Value {
        assert!(
            self.yfov > 0.0 && self.yfov < PI,
            "camera yfov must be in (0, pi)"
        );
        assert!(self.znear > 0.0, "camera znear must be > 0");
        let mut p = Map::new();
        if let Some(a) = self.aspect_ratio {
            assert!(a > 0.0, "camera aspect ratio must be > 0");
            p.insert("aspectRatio".into(), num(a));
        }
        p.insert("yfov".into(), num(self.yfov));
        if let Some(f) = self.zfar {
            assert!(f > self.znear, "camera zfar must exceed znear");
            p.insert("zfar".into(), num(f));
        }
        p.insert("znear".into(), num(self.znear));
        json!({ "name": self.name, "type": "perspective", "perspective": p })
    }
}

/// The kind of a `KHR_lights_punctual` light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LightKind {
    /// Emits in all directions from the node's origin; intensity in candela.
    Point,
    /// A cone along the node's local -z; intensity in candela. Angles in radians from the
    /// axis, `0 <= inner_cone_angle < outer_cone_angle <= π/2`; full intensity inside the
    /// inner cone, falling to zero at the outer.
    Spot {
        /// Angle (radians) where the falloff starts.
        inner_cone_angle: f64,
        /// Angle (radians) where the light reaches zero.
        outer_cone_angle: f64,
    },
    /// Parallel light travelling along the node's local -z; intensity is illuminance in lux
    /// on a surface facing the light.
    Directional,
}

/// A `KHR_lights_punctual` light, placed in the scene by a node (see [`Node::light`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Light {
    /// Light name.
    pub name: String,
    /// Point, spot or directional.
    pub kind: LightKind,
    /// Linear RGB colour, each in `[0, 1]`, multiplying `intensity`.
    pub color: [f64; 3],
    /// Candela (lm/sr) for point and spot lights, lux (lm/m²) for directional ones; `>= 0`.
    pub intensity: f64,
    /// Distance (metres) beyond which a point or spot light has no effect; `None` for
    /// unlimited. Must be `None` for directional lights.
    pub range: Option<f64>,
}

impl Light {
    /// A white point light of `intensity` candela, unlimited range.
    pub fn point(name: &str, intensity: f64) -> Self {
        Light {
            name: name.to_owned(),
            kind: LightKind::Point,
            color: [1.0; 3],
            intensity,
            range: None,
        }
    }

    /// A white spot light of `intensity` candela with cone angles in radians, unlimited range.
    pub fn spot(name: &str, intensity: f64, inner_cone_angle: f64, outer_cone_angle: f64) -> Self {
        Light {
            name: name.to_owned(),
            kind: LightKind::Spot {
                inner_cone_angle,
                outer_cone_angle,
            },
            color: [1.0; 3],
            intensity,
            range: None,
        }
    }

    /// A white directional light of `illuminance` lux.
    pub fn directional(name: &str, illuminance: f64) -> Self {
        Light {
            name: name.to_owned(),
            kind: LightKind::Directional,
            color: [1.0; 3],
            intensity: illuminance,
            range: None,
        }
    }

    fn to_json(&self) -> Value {
        assert!(
            self.intensity >= 0.0 && self.intensity.is_finite(),
            "light intensity must be >= 0"
        );
        assert!(
            self.color.iter().all(|c| (0.0..=1.0).contains(c)),
            "light colour must be in [0, 1]"
        );
        let mut m = Map::new();
        m.insert("name".into(), json!(self.name));
        m.insert("color".into(), json!(self.color.map(num)));
        m.insert("intensity".into(), num(self.intensity));
        let kind = match self.kind {
            LightKind::Point => "point",
            LightKind::Spot { .. } => "spot",
            LightKind::Directional => "directional",
        };
        if let LightKind::Spot {
            inner_cone_angle,
            outer_cone_angle,
        } = self.kind
        {
            assert!(
                0.0 <= inner_cone_angle
                    && inner_cone_angle < outer_cone_angle
                    && outer_cone_angle <= PI / 2.0,
                "spot light needs 0 <= inner < outer <= pi/2"
            );
            m.insert(
                "spot".into(),
                json!({ "innerConeAngle": num(inner_cone_angle), "outerConeAngle": num(outer_cone_angle) }),
            );
        }
        m.insert("type".into(), json!(kind));
        if let Some(r) = self.range {
            assert!(
                self.kind != LightKind::Directional,
                "directional lights have no range"
            );
            assert!(r > 0.0, "light range must be > 0");
            m.insert("range".into(), num(r));
        }
        Value::Object(m)
    }
}

/// A node's local transform: parent-from-local, applied as `T * R * S`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Transform {
    /// Translation (metres), rotation (unit quaternion) and scale (unitless). Written as
    /// `translation`, `rotation`, `scale`, each omitted when it is the identity.
    Trs {
        /// Translation, metres.
        translation: DVec3,
        /// Rotation (normalised on write).
        rotation: DQuat,
        /// Scale factors.
        scale: DVec3,
    },
    /// A general affine matrix (column-major when written as `matrix`); it must be
    /// decomposable into TRS, as glTF requires.
    Matrix(DMat4),
}

impl Default for Transform {
    fn default() -> Self {
        Transform::IDENTITY
    }
}

impl Transform {
    /// The identity (written as no transform at all).
    pub const IDENTITY: Transform = Transform::Trs {
        translation: DVec3::ZERO,
        rotation: DQuat::IDENTITY,
        scale: DVec3::ONE,
    };

    /// A pure translation (metres).
    pub fn translation(t: [f64; 3]) -> Self {
        Transform::Trs {
            translation: t.into(),
            rotation: DQuat::IDENTITY,
            scale: DVec3::ONE,
        }
    }

    /// Translation (metres) and rotation, unit scale.
    pub fn translation_rotation(t: [f64; 3], rotation: DQuat) -> Self {
        Transform::Trs {
            translation: t.into(),
            rotation,
            scale: DVec3::ONE,
        }
    }

    /// Places a camera or light at `eye` (metres) looking along `direction` (so local -z maps
    /// to `direction`), with local +y as close to `up` as possible.
    ///
    /// # Panics
    /// If `direction` is zero or parallel to `up`.
    pub fn look_to(eye: [f64; 3], direction: [f64; 3], up: [f64; 3]) -> Self {
        let f = DVec3::from(direction).normalize();
        let r = f.cross(DVec3::from(up));
        assert!(r.length() > 1e-9, "look_to: direction parallel to up");
        let r = r.normalize();
        let u = r.cross(f);
        let rotation = DQuat::from_mat3(&DMat3::from_cols(r, u, -f)).normalize();
        // q and -q are the same rotation: write the one with w >= 0.
        let rotation = if rotation.w < 0.0 {
            -rotation
        } else {
            rotation
        };
        Transform::translation_rotation(eye, rotation)
    }

    /// The transform as a parent-from-local matrix.
    pub fn matrix(&self) -> DMat4 {
        match *self {
            Transform::Trs {
                translation,
                rotation,
                scale,
            } => DMat4::from_scale_rotation_translation(scale, rotation.normalize(), translation),
            Transform::Matrix(m) => m,
        }
    }

    fn write(&self, node: &mut Map<String, Value>) {
        match *self {
            Transform::Trs {
                translation,
                rotation,
                scale,
            } => {
                if translation != DVec3::ZERO {
                    node.insert("translation".into(), json!(translation.to_array().map(num)));
                }
                let rotation = rotation.normalize();
                if rotation != DQuat::IDENTITY {
                    node.insert("rotation".into(), json!(rotation.to_array().map(num)));
                }
                if scale != DVec3::ONE {
                    node.insert("scale".into(), json!(scale.to_array().map(num)));
                }
            }
            Transform::Matrix(m) => {
                if m != DMat4::IDENTITY {
                    node.insert("matrix".into(), json!(m.to_cols_array().map(num)));
                }
            }
        }
    }
}

/// A scene node. Build with [`Node::new`] and the `with_*` methods; add with
/// [`GlbBuilder::add_node`] after its children.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Node {
    /// Node name.
    pub name: String,
    /// Local transform (parent-from-local).
    pub transform: Transform,
    /// Indices of child nodes (each added earlier, each with only this parent).
    pub children: Vec<usize>,
    /// Index of the mesh drawn at this node, from [`GlbBuilder::add_mesh`].
    pub mesh: Option<usize>,
    /// Index of the camera at this node, from [`GlbBuilder::add_camera`].
    pub camera: Option<usize>,
    /// Index of the `KHR_lights_punctual` light at this node, from [`GlbBuilder::add_light`].
    pub light: Option<usize>,
}

impl Node {
    /// An empty node with an identity transform.
    pub fn new(name: &str) -> Self {
        Node {
            name: name.to_owned(),
            ..Node::default()
        }
    }

    /// Returns the node with the given local transform.
    pub fn with_transform(mut self, transform: Transform) -> Self {
        self.transform = transform;
        self
    }

    /// Returns the node with the given children (node indices).
    pub fn with_children(mut self, children: &[usize]) -> Self {
        self.children = children.to_vec();
        self
    }

    /// Returns the node drawing mesh `mesh`.
    pub fn with_mesh(mut self, mesh: usize) -> Self {
        self.mesh = Some(mesh);
        self
    }

    /// Returns the node carrying camera `camera`.
    pub fn with_camera(mut self, camera: usize) -> Self {
        self.camera = Some(camera);
        self
    }

    /// Returns the node carrying light `light`.
    pub fn with_light(mut self, light: usize) -> Self {
        self.light = Some(light);
        self
    }
}

// ---------------------------------------------------------------------------------------------
// The builder
// ---------------------------------------------------------------------------------------------

/// Collects a glTF 2.0 scene and writes it as a binary glTF (glb) with [`GlbBuilder::to_glb`].
///
/// Objects are referenced by the indices the `add_*` methods return. The single default scene
/// (`scene` 0) holds every node that is nobody's child, in the order added. `extensionsUsed`
/// lists exactly the extensions written (none are required).
#[derive(Clone, Debug, Default)]
pub struct GlbBuilder {
    materials: Vec<Material>,
    meshes: Vec<Value>,
    accessors: Vec<Value>,
    buffer_views: Vec<Value>,
    bin: Vec<u8>,
    cameras: Vec<PerspectiveCamera>,
    lights: Vec<Light>,
    nodes: Vec<Node>,
    has_parent: Vec<bool>,
}

impl GlbBuilder {
    /// An empty scene.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds a material; returns its index.
    ///
    /// # Panics
    /// If a base-colour component is outside `[0, 1]` or an emission component is negative.
    pub fn add_material(&mut self, material: Material) -> usize {
        material.validate();
        self.materials.push(material);
        self.materials.len() - 1
    }

    /// Adds a mesh with one triangle-list primitive per `(geometry, material index)` pair;
    /// returns the mesh index. The geometry goes into the binary buffer at once.
    ///
    /// # Panics
    /// If a primitive is empty, has an index out of range or an index count not a multiple of
    /// 3, has attribute arrays of the wrong length, or names an unknown material.
    pub fn add_mesh(&mut self, name: &str, primitives: &[(&TriangleMesh, usize)]) -> usize {
        assert!(!primitives.is_empty(), "mesh {name:?} has no primitives");
        let mut prims = Vec::new();
        for &(geometry, material) in primitives {
            assert!(
                material < self.materials.len(),
                "mesh {name:?}: unknown material {material}"
            );
            prims.push(self.add_primitive(name, geometry, material));
        }
        self.meshes
            .push(json!({ "name": name, "primitives": prims }));
        self.meshes.len() - 1
    }

    /// Adds a mesh of one primitive and a node drawing it with an identity transform (the
    /// geometry is already in world coordinates); returns the node index. Mesh and node are
    /// both named `name`.
    pub fn add_mesh_node(&mut self, name: &str, geometry: &TriangleMesh, material: usize) -> usize {
        let mesh = self.add_mesh(name, &[(geometry, material)]);
        self.add_node(Node::new(name).with_mesh(mesh))
    }

    /// Adds a perspective camera; returns its index. Place it with a node.
    pub fn add_camera(&mut self, camera: PerspectiveCamera) -> usize {
        self.cameras.push(camera);
        self.cameras.len() - 1
    }

    /// Adds a `KHR_lights_punctual` light; returns its index. Place it with a node.
    pub fn add_light(&mut self, light: Light) -> usize {
        self.lights.push(light);
        self.lights.len() - 1
    }

    /// Adds a node; returns its index. Children must have been added already and may have only
    /// one parent (this keeps the hierarchy a forest).
    ///
    /// # Panics
    /// If a child, mesh, camera or light index is unknown, or a child already has a parent.
    pub fn add_node(&mut self, node: Node) -> usize {
        for &c in &node.children {
            assert!(
                c < self.nodes.len(),
                "node {:?}: unknown child {c}",
                node.name
            );
            assert!(
                !self.has_parent[c],
                "node {:?}: child {c} already has a parent",
                node.name
            );
            self.has_parent[c] = true;
        }
        assert!(
            node.mesh.is_none_or(|m| m < self.meshes.len()),
            "node {:?}: unknown mesh",
            node.name
        );
        assert!(
            node.camera.is_none_or(|c| c < self.cameras.len()),
            "node {:?}: unknown camera",
            node.name
        );
        assert!(
            node.light.is_none_or(|l| l < self.lights.len()),
            "node {:?}: unknown light",
            node.name
        );
        self.nodes.push(node);
        self.has_parent.push(false);
        self.nodes.len() - 1
    }

    /// The extensions this scene uses, sorted (what `extensionsUsed` will list).
    pub fn extensions_used(&self) -> Vec<&'static str> {
        let mut used = BTreeSet::new();
        if !self.lights.is_empty() {
            used.insert(KHR_LIGHTS_PUNCTUAL);
        }
        if self.materials.iter().any(Material::uses_emissive_strength) {
            used.insert(KHR_MATERIALS_EMISSIVE_STRENGTH);
        }
        used.into_iter().collect()
    }

    /// The glTF JSON document (what [`GlbBuilder::to_glb`] writes in its JSON chunk). Empty
    /// top-level arrays are omitted, as glTF requires.
    pub fn to_json(&self) -> Value {
        let mut root = Map::new();
        root.insert(
            "asset".into(),
            json!({ "generator": "penumbra fixtures", "version": "2.0" }),
        );
        let used = self.extensions_used();
        if !used.is_empty() {
            root.insert("extensionsUsed".into(), json!(used));
        }
        if !self.lights.is_empty() {
            let lights: Vec<Value> = self.lights.iter().map(Light::to_json).collect();
            root.insert(
                "extensions".into(),
                json!({ KHR_LIGHTS_PUNCTUAL: { "lights": lights } }),
            );
        }
        let roots: Vec<usize> = (0..self.nodes.len())
            .filter(|&i| !self.has_parent[i])
            .collect();
        root.insert("scene".into(), json!(0));
        let mut scene = Map::new();
        scene.insert("name".into(), json!("Scene"));
        if !roots.is_empty() {
            scene.insert("nodes".into(), json!(roots));
        }
        root.insert("scenes".into(), json!([scene]));
        let mut put = |key: &str, items: Vec<Value>| {
            if !items.is_empty() {
                root.insert(key.into(), Value::Array(items));
            }
        };
        put("nodes", self.nodes.iter().map(node_json).collect());
        put("meshes", self.meshes.clone());
        put(
            "materials",
            self.materials.iter().map(Material::to_json).collect(),
        );
        put(
            "cameras",
            self.cameras
                .iter()
                .map(PerspectiveCamera::to_json)
                .collect(),
        );
        put("accessors", self.accessors.clone());
        put("bufferViews", self.buffer_views.clone());
        if !self.bin.is_empty() {
            put("buffers", vec![json!({ "byteLength": self.bin.len() })]);
        }
        Value::Object(root)
    }

    /// Writes the scene as a glb: the 12-byte header (`glTF`, version 2, total length), the
    /// JSON chunk padded with spaces to a multiple of 4 bytes, then (when there is any
    /// geometry) the BIN chunk padded with zeros to a multiple of 4 bytes.
    pub fn to_glb(&self) -> Vec<u8> {
        let mut json = serde_json::to_vec(&self.to_json()).expect("JSON serialisation cannot fail");
        while !json.len().is_multiple_of(4) {
            json.push(b' ');
        }
        let mut bin = self.bin.clone();
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
        let mut total = 12 + 8 + json.len();
        if !bin.is_empty() {
            total += 8 + bin.len();
        }
        let total = u32::try_from(total).expect("glb larger than 4 GiB");
        let mut out = Vec::with_capacity(total as usize);
        for word in [GLB_MAGIC, 2, total, json.len() as u32, CHUNK_JSON] {
            out.extend_from_slice(&word.to_le_bytes());
        }
        out.extend_from_slice(&json);
        if !bin.is_empty() {
            out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
            out.extend_from_slice(&CHUNK_BIN.to_le_bytes());
            out.extend_from_slice(&bin);
        }
        out
    }

    /// Writes one primitive's accessors; returns the primitive's JSON.
    fn add_primitive(&mut self, name: &str, g: &TriangleMesh, material: usize) -> Value {
        let n = g.positions.len();
        assert!(n > 0, "mesh {name:?}: primitive without vertices");
        assert!(
            !g.indices.is_empty() && g.indices.len().is_multiple_of(3),
            "mesh {name:?}: index count must be a positive multiple of 3"
        );
        assert!(
            g.indices.iter().all(|&i| (i as usize) < n),
            "mesh {name:?}: index out of range"
        );
        let mut attributes = Map::new();
        let pos: Vec<[f32; 3]> = g.positions.iter().map(|p| p.map(|c| c as f32)).collect();
        attributes.insert(
            "POSITION".into(),
            json!(self.push_floats(&pos, "VEC3", true)),
        );
        if let Some(normals) = &g.normals {
            assert_eq!(normals.len(), n, "mesh {name:?}: one normal per vertex");
            let nor: Vec<[f32; 3]> = normals
                .iter()
                .map(|&v| {
                    let v = DVec3::from(v);
                    assert!(v.length() > 1e-12, "mesh {name:?}: zero normal");
                    v.normalize().to_array().map(|c| c as f32)
                })
                .collect();
            attributes.insert(
                "NORMAL".into(),
                json!(self.push_floats(&nor, "VEC3", false)),
            );
        }
        if let Some(texcoords) = &g.texcoords {
            assert_eq!(texcoords.len(), n, "mesh {name:?}: one texcoord per vertex");
            let uv: Vec<[f32; 2]> = texcoords.iter().map(|t| t.map(|c| c as f32)).collect();
            attributes.insert(
                "TEXCOORD_0".into(),
                json!(self.push_floats(&uv, "VEC2", false)),
            );
        }
        // u16 unless a vertex index would reach the primitive-restart value 65535.
        let (bytes, component) = if n <= 65535 {
            (
                g.indices
                    .iter()
                    .flat_map(|&i| (i as u16).to_le_bytes())
                    .collect::<Vec<u8>>(),
                UNSIGNED_SHORT,
            )
        } else {
            (
                g.indices.iter().flat_map(|&i| i.to_le_bytes()).collect(),
                UNSIGNED_INT,
            )
        };
        let view = self.push_view(&bytes, ELEMENT_ARRAY_BUFFER);
        let indices = self.push_accessor(json!({
            "bufferView": view,
            "componentType": component,
            "count": g.indices.len(),
            "type": "SCALAR",
        }));
        json!({ "attributes": attributes, "indices": indices, "material": material, "mode": 4 })
    }

    /// Writes a float vertex attribute; POSITION gets exact `min`/`max` (the stored `f32`s).
    fn push_floats<const N: usize>(
        &mut self,
        data: &[[f32; N]],
        kind: &str,
        min_max: bool,
    ) -> usize {
        let bytes: Vec<u8> = data
            .iter()
            .flatten()
            .flat_map(|c| c.to_le_bytes())
            .collect();
        let view = self.push_view(&bytes, ARRAY_BUFFER);
        let mut acc = Map::new();
        acc.insert("bufferView".into(), json!(view));
        acc.insert("componentType".into(), json!(FLOAT));
        acc.insert("count".into(), json!(data.len()));
        acc.insert("type".into(), json!(kind));
        if min_max {
            let mut lo = [f32::INFINITY; N];
            let mut hi = [f32::NEG_INFINITY; N];
            for v in data {
                for k in 0..N {
                    lo[k] = lo[k].min(v[k]);
                    hi[k] = hi[k].max(v[k]);
                }
            }
            // f32 -> f64 is exact, so the validator's comparison with the data is too.
            acc.insert(
                "max".into(),
                Value::Array(hi.iter().map(|&c| num(f64::from(c))).collect()),
            );
            acc.insert(
                "min".into(),
                Value::Array(lo.iter().map(|&c| num(f64::from(c))).collect()),
            );
        }
        self.push_accessor(Value::Object(acc))
    }

    fn push_accessor(&mut self, accessor: Value) -> usize {
        self.accessors.push(accessor);
        self.accessors.len() - 1
    }

    /// Appends `bytes` at the next 4-byte boundary of the buffer; returns the view index.
    fn push_view(&mut self, bytes: &[u8], target: u32) -> usize {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let offset = self.bin.len();
        self.bin.extend_from_slice(bytes);
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        self.buffer_views.push(json!({
            "buffer": 0,
            "byteLength": bytes.len(),
            "byteOffset": offset,
            "target": target,
        }));
        self.buffer_views.len() - 1
    }
}

fn node_json(node: &Node) -> Value {
    let mut m = Map::new();
    m.insert("name".into(), json!(node.name));
    node.transform.write(&mut m);
    if !node.children.is_empty() {
        m.insert("children".into(), json!(node.children));
    }
    if let Some(mesh) = node.mesh {
        m.insert("mesh".into(), json!(mesh));
    }
    if let Some(camera) = node.camera {
        m.insert("camera".into(), json!(camera));
    }
    if let Some(light) = node.light {
        m.insert(
            "extensions".into(),
            json!({ KHR_LIGHTS_PUNCTUAL: { "light": light } }),
        );
    }
    Value::Object(m)
}

/// A JSON number, with -0 written as 0.
///
/// # Panics
/// If `x` is not finite (JSON has no NaN or infinity).
fn num(x: f64) -> Value {
    assert!(x.is_finite(), "non-finite number {x} in glTF output");
    json!(if x == 0.0 { 0.0 } else { x })
}

// ---------------------------------------------------------------------------------------------
// Scenes
// ---------------------------------------------------------------------------------------------

/// Cornell box white reflectance (linear RGB).
pub const CORNELL_WHITE: [f64; 3] = [0.725, 0.71, 0.68];
/// Cornell box red-wall reflectance (linear RGB).
pub const CORNELL_RED: [f64; 3] = [0.63, 0.065, 0.05];
/// Cornell box green-wall reflectance (linear RGB).
pub const CORNELL_GREEN: [f64; 3] = [0.14, 0.45, 0.091];
/// Cornell box light's emitted radiance, W/(m² sr) (linear RGB).
pub const CORNELL_LIGHT_RADIANCE: [f64; 3] = [17.0, 12.0, 4.0];
/// Number of triangles in [`cornell_box`]: 5 walls and the light at 2 each, two 5-faced blocks
/// at 10 each.
pub const CORNELL_TRIANGLES: usize = 32;

/// The Cornell box, after the Cornell Program of Computer Graphics measurements (given there in
/// millimetres, here scaled to metres).
///
/// Nodes, each drawing its own mesh with an identity transform: `floor`, `ceiling`,
/// `back wall` (white), `green wall` (x = 0, facing +x), `red wall` (x ≈ 0.55, facing -x),
/// `short block`, `tall block` (white), `light`, and `camera`. The walls are single quads facing
/// into the box (the data's quads are not all exactly planar: the red wall; every quad is split
/// `(0,1,2)`, `(0,2,3)`). The blocks are the data's top quads with four sides dropped to y = 0;
/// they have no bottom face (it would lie on the floor, facing it, and never be seen): 5 faces,
/// 10 triangles each, so [`CORNELL_TRIANGLES`] = 32 in all.
///
/// The light is a 130 mm × 105 mm quad at y = 548.7 mm, 0.1 mm below the ceiling so the two
/// are not coplanar, facing -y, with its own material `light`: emitted radiance
/// [`CORNELL_LIGHT_RADIANCE`] = (17, 12, 4) W/(m² sr) written as `emissiveFactor`
/// (1, 12/17, 4/17) and `emissiveStrength` 17, and reflectance 0.78 (the Cornell data's
/// value for the light). Wall reflectances: [`CORNELL_WHITE`], [`CORNELL_RED`],
/// [`CORNELL_GREEN`].
///
/// The camera sits at (0.278, 0.273, -0.8) m looking +z with +y up: a 35 mm lens on 25 mm
/// film, `yfov = 2 atan(12.5 / 35)` ≈ 0.6860 rad (39.3°), aspect 1, znear 0.01 m, zfar 10 m.
pub fn cornell_box() -> Vec<u8> {
    const MM: f64 = 0.001;
    let q = |c: [[f64; 3]; 4]| quad(c.map(|p| p.map(|v| v * MM)));
    let top = |c: [[f64; 3]; 4]| c.map(|p| p.map(|v| v * MM));

    let mut b = GlbBuilder::new();
    let white = b.add_material(Material::diffuse("white", CORNELL_WHITE));
    let red = b.add_material(Material::diffuse("red", CORNELL_RED));
    let green = b.add_material(Material::diffuse("green", CORNELL_GREEN));
    let light =
        b.add_material(Material::diffuse("light", [0.78; 3]).emitting(CORNELL_LIGHT_RADIANCE));

    let floor = q([
        [552.8, 0.0, 0.0],
        [0.0, 0.0, 0.0],
        [0.0, 0.0, 559.2],
        [549.6, 0.0, 559.2],
    ]);
    let ceiling = q([
        [556.0, 548.8, 0.0],
        [556.0, 548.8, 559.2],
        [0.0, 548.8, 559.2],
        [0.0, 548.8, 0.0],
    ]);
    let back = q([
        [549.6, 0.0, 559.2],
        [0.0, 0.0, 559.2],
        [0.0, 548.8, 559.2],
        [556.0, 548.8, 559.2],
    ]);
    let green_wall = q([
        [0.0, 0.0, 559.2],
        [0.0, 0.0, 0.0],
        [0.0, 548.8, 0.0],
        [0.0, 548.8, 559.2],
    ]);
    let red_wall = q([
        [552.8, 0.0, 0.0],
        [549.6, 0.0, 559.2],
        [556.0, 548.8, 559.2],
        [556.0, 548.8, 0.0],
    ]);
    let lamp = q([
        [343.0, 548.7, 227.0],
        [343.0, 548.7, 332.0],
        [213.0, 548.7, 332.0],
        [213.0, 548.7, 227.0],
    ]);
    let short_block = block(
        top([
            [130.0, 165.0, 65.0],
            [82.0, 165.0, 225.0],
            [240.0, 165.0, 272.0],
            [290.0, 165.0, 114.0],
        ]),
        0.0,
        false,
    );
    let tall_block = block(
        top([
            [423.0, 330.0, 247.0],
            [265.0, 330.0, 296.0],
            [314.0, 330.0, 456.0],
            [472.0, 330.0, 406.0],
        ]),
        0.0,
        false,
    );

    b.add_mesh_node("floor", &floor, white);
    b.add_mesh_node("ceiling", &ceiling, white);
    b.add_mesh_node("back wall", &back, white);
    b.add_mesh_node("green wall", &green_wall, green);
    b.add_mesh_node("red wall", &red_wall, red);
    b.add_mesh_node("short block", &short_block, white);
    b.add_mesh_node("tall block", &tall_block, white);
    b.add_mesh_node("light", &lamp, light);

    let camera = b.add_camera(PerspectiveCamera {
        name: "camera".into(),
        yfov: 2.0 * (12.5f64 / 35.0).atan(),
        aspect_ratio: Some(1.0),
        znear: 0.01,
        zfar: Some(10.0),
    });
    b.add_node(
        Node::new("camera")
            .with_transform(Transform::look_to(
                [0.278, 0.273, -0.8],
                [0.0, 0.0, 1.0],
                [0.0, 1.0, 0.0],
            ))
            .with_camera(camera),
    );
    b.to_glb()
}

/// Emitted radiance of the area sources in [`square_occluder`], W/(m² sr) (exitance π W/m²).
pub const SQUARE_OCCLUDER_RADIANCE: f64 = 1.0;

/// The square source / square occluder / floor configuration with a closed-form reference,
/// turned to glTF's y-up: a reference with z up maps (x, y, z) to glTF (x, z, ·) with height
/// along glTF y.
///
/// * `source`: S = [-0.5, 0.5]² (in x, z) at y = 2, facing down (-y); material `source`
///   emitting [`SQUARE_OCCLUDER_RADIANCE`] = 1 W/(m² sr) white, reflectance 0 (black, so it
///   only emits).
/// * `occluder`: O = [-0.5, 0.5]² at y = 1, parallel to S, a thin plate modelled as a single
///   quad (normal +y, towards the source) with a **double-sided** material `occluder`,
///   reflectance 0.5 grey.
/// * `floor`: the receiver [-4, 4]² at y = 0 facing up, reflectance 0.5 grey.
pub fn square_occluder() -> Vec<u8> {
    let mut b = GlbBuilder::new();
    let grey = b.add_material(Material::diffuse("floor", [0.5; 3]));
    let plate = b.add_material(Material::diffuse("occluder", [0.5; 3]).double_sided());
    let source = b.add_material(
        Material::diffuse("source", [0.0; 3]).emitting([SQUARE_OCCLUDER_RADIANCE; 3]),
    );
    b.add_mesh_node(
        "floor",
        &horizontal_rect([-4.0, 4.0], [-4.0, 4.0], 0.0, true),
        grey,
    );
    b.add_mesh_node(
        "occluder",
        &horizontal_rect([-0.5, 0.5], [-0.5, 0.5], 1.0, true),
        plate,
    );
    b.add_mesh_node(
        "source",
        &horizontal_rect([-0.5, 0.5], [-0.5, 0.5], 2.0, false),
        source,
    );
    b.to_glb()
}

/// Emitted radiance of the 1 m × 1 m area lights in [`box_on_floor`] and [`instanced`],
/// W/(m² sr).
pub const AREA_LIGHT_RADIANCE: f64 = 10.0;

/// The 1 m² area light shared by [`box_on_floor`] and [`instanced`]: [-0.5, 0.5]² at y = 3
/// facing down, emitting [`AREA_LIGHT_RADIANCE`], reflectance 0.
fn add_area_light(b: &mut GlbBuilder) {
    let m = b.add_material(Material::diffuse("light", [0.0; 3]).emitting([AREA_LIGHT_RADIANCE; 3]));
    b.add_mesh_node(
        "light",
        &horizontal_rect([-0.5, 0.5], [-0.5, 0.5], 3.0, false),
        m,
    );
}

/// The box of [`box_on_floor`]: [-0.5, 0.5] × [0, 1] × [-0.5, 0.5], 5 outward faces, node
/// `box`.
fn add_unit_box(b: &mut GlbBuilder, material: usize) {
    let top = [
        [-0.5, 1.0, -0.5],
        [-0.5, 1.0, 0.5],
        [0.5, 1.0, 0.5],
        [0.5, 1.0, -0.5],
    ];
    b.add_mesh_node("box", &block(top, 0.0, false), material);
}

/// A 1 m cube standing on a floor, lit by an area light.
///
/// * `floor`: [-2, 2]² at y = 0 facing up, reflectance 0.5 grey; one quad, sharing no vertex
///   with the box (the contact edges are T-junction-free only by geometry).
/// * `box`: [-0.5, 0.5] × [0, 1] × [-0.5, 0.5], 5 outward faces (no bottom: it would lie on
///   the floor), reflectance 0.5 grey, 10 triangles.
/// * `light`: [-0.5, 0.5]² at y = 3 facing down, emitting [`AREA_LIGHT_RADIANCE`] = 10
///   W/(m² sr) white (`emissiveStrength` 10), reflectance 0.
pub fn box_on_floor() -> Vec<u8> {
    let mut b = GlbBuilder::new();
    let grey = b.add_material(Material::diffuse("grey", [0.5; 3]));
    b.add_mesh_node(
        "floor",
        &horizontal_rect([-2.0, 2.0], [-2.0, 2.0], 0.0, true),
        grey,
    );
    add_unit_box(&mut b, grey);
    add_area_light(&mut b);
    b.to_glb()
}

/// [`box_on_floor`] with its floor cut into `n` x `n` square tiles (`2 n²` triangles, vertices
/// shared): with enough tiles xatlas cuts the floor into several charts (a chart holds about
/// [`crate::atlas::TRIANGLES_PER_CHART`] average triangles), so lightmap seams cross the floor,
/// its light and the box's shadow: the scene of the seam pictures and tests.
///
/// * `floor`: [-2, 2]² at y = 0 facing up, reflectance 0.5 grey, `n` x `n` tiles.
/// * `box`, `light`: as in [`box_on_floor`].
/// * `camera`: at (2.5, 2.2, 3.2) m looking at (0, 0.3, 0), `yfov` 0.8 rad.
pub fn tiled_box_on_floor(n: usize) -> Vec<u8> {
    let mut b = GlbBuilder::new();
    let grey = b.add_material(Material::diffuse("grey", [0.5; 3]));
    let steps: Vec<f64> = (0..=n.max(1))
        .map(|k| 4.0 * k as f64 / n.max(1) as f64)
        .collect();
    let mut floor = ladder::grid(
        DVec3::new(-2.0, 0.0, -2.0),
        DVec3::Z,
        DVec3::X,
        &steps,
        &steps,
        |_, _| false,
    );
    floor.normals = None;
    b.add_mesh_node("floor", &floor, grey);
    add_unit_box(&mut b, grey);
    add_area_light(&mut b);
    let camera = b.add_camera(PerspectiveCamera {
        name: "camera".into(),
        yfov: 0.8,
        aspect_ratio: Some(1.0),
        znear: 0.01,
        zfar: Some(20.0),
    });
    b.add_node(
        Node::new("camera")
            .with_transform(Transform::look_to(
                [2.5, 2.2, 3.2],
                [-2.5, -1.9, -3.2],
                [0.0, 1.0, 0.0],
            ))
            .with_camera(camera),
    );
    b.to_glb()
}

/// The furnace test: [`furnace_box_with`]`(0.5, 1.0)`, so the radiosity is `B = 2` W/m²
/// everywhere.
pub fn furnace_box() -> Vec<u8> {
    furnace_box_with(0.5, 1.0)
}

/// A closed unit cube [-0.5, 0.5]³ seen from inside: 6 inward-facing quads, 12 triangles, one
/// mesh `furnace` and one material `furnace` on every face: grey reflectance `rho` (in
/// `[0, 1]`) and emitted radiance `exitance / π` W/(m² sr) (so exitance `M = exitance` W/m²).
/// Every point sees only the box, so the radiosity is `B = M / (1 - rho)` everywhere and the
/// irradiance `H = B = M / (1 - rho)` too.
pub fn furnace_box_with(rho: f64, exitance: f64) -> Vec<u8> {
    let mut b = GlbBuilder::new();
    let m = b.add_material(Material::diffuse("furnace", [rho; 3]).emitting([exitance / PI; 3]));
    b.add_mesh_node("furnace", &flip(cuboid([-0.5; 3], [0.5; 3])), m);
    b.to_glb()
}

/// The 4 m × 4 m floor of the punctual-light scenes: [-2, 2]² at y = 0 facing up, 0.5 grey.
fn add_floor(b: &mut GlbBuilder) -> usize {
    let grey = b.add_material(Material::diffuse("grey", [0.5; 3]));
    b.add_mesh_node(
        "floor",
        &horizontal_rect([-2.0, 2.0], [-2.0, 2.0], 0.0, true),
        grey,
    );
    grey
}

/// The small box occluder of [`spot_light`] and [`directional_light`]: [0.2, 0.5] × [0, 0.3] ×
/// [-0.15, 0.15], 5 outward faces.
fn add_small_box(b: &mut GlbBuilder, material: usize) {
    let top = [
        [0.2, 0.3, -0.15],
        [0.2, 0.3, 0.15],
        [0.5, 0.3, 0.15],
        [0.5, 0.3, -0.15],
    ];
    b.add_mesh_node("box", &block(top, 0.0, false), material);
}

/// A point light over a floor, with nothing else: the irradiance at floor point (x, 0, z) is
/// `H = I h / r³` with `I = 10` cd, `h = 2` m, `r² = x² + z² + h²`.
///
/// * `floor`: [-2, 2]² at y = 0 facing up, reflectance 0.5 grey.
/// * `point light` at (0, 2, 0): white, 10 cd, unlimited range.
pub fn point_light() -> Vec<u8> {
    let mut b = GlbBuilder::new();
    add_floor(&mut b);
    let light = b.add_light(Light::point("point light", 10.0));
    b.add_node(
        Node::new("point light")
            .with_transform(Transform::translation([0.0, 2.0, 0.0]))
            .with_light(light),
    );
    b.to_glb()
}

/// A spot light pointing straight down over a floor, with a small box casting a shadow.
///
/// * `floor`: [-2, 2]² at y = 0 facing up, reflectance 0.5 grey.
/// * `box`: [0.2, 0.5] × [0, 0.3] × [-0.15, 0.15], 5 faces, 0.5 grey.
/// * `spot light` at (0, 2, 0) pointing -y: white, 10 cd, inner cone 0.4 rad, outer 0.6 rad
///   (full intensity within 0.85 m of the floor's centre, none beyond 1.37 m).
pub fn spot_light() -> Vec<u8> {
    let mut b = GlbBuilder::new();
    let grey = add_floor(&mut b);
    add_small_box(&mut b, grey);
    let light = b.add_light(Light::spot("spot light", 10.0, 0.4, 0.6));
    b.add_node(
        Node::new("spot light")
            .with_transform(Transform::look_to(
                [0.0, 2.0, 0.0],
                [0.0, -1.0, 0.0],
                [0.0, 0.0, -1.0],
            ))
            .with_light(light),
    );
    b.to_glb()
}

/// A sun at 45° elevation over a floor, with a small box casting a shadow.
///
/// * `floor`: [-2, 2]² at y = 0 facing up, reflectance 0.5 grey.
/// * `box`: [0.2, 0.5] × [0, 0.3] × [-0.15, 0.15], 5 faces, 0.5 grey.
/// * `sun`: directional, white, 2 lux on a surface facing it, light travelling along
///   (1, -1, 0)/√2 (the shadow falls towards +x); the floor gets `2 cos 45°` ≈ 1.414 lux.
///   The node sits at (-2, 2, 0) (its position does not matter).
pub fn directional_light() -> Vec<u8> {
    let mut b = GlbBuilder::new();
    let grey = add_floor(&mut b);
    add_small_box(&mut b, grey);
    let light = b.add_light(Light::directional("sun", 2.0));
    b.add_node(
        Node::new("sun")
            .with_transform(Transform::look_to(
                [-2.0, 2.0, 0.0],
                [1.0, -1.0, 0.0],
                [0.0, 1.0, 0.0],
            ))
            .with_light(light),
    );
    b.to_glb()
}

/// A uniformly lit plane: `floor` [-1, 1]² at y = 0 facing up, reflectance 0.5 grey, and a
/// directional light `sun` of 1 lux pointing straight down (node at (0, 1, 0)); nothing else,
/// so the irradiance is 1 everywhere on the floor.
pub fn plane_uniform() -> Vec<u8> {
    let mut b = GlbBuilder::new();
    let grey = b.add_material(Material::diffuse("grey", [0.5; 3]));
    b.add_mesh_node(
        "floor",
        &horizontal_rect([-1.0, 1.0], [-1.0, 1.0], 0.0, true),
        grey,
    );
    let light = b.add_light(Light::directional("sun", 1.0));
    b.add_node(
        Node::new("sun")
            .with_transform(Transform::look_to(
                [0.0, 1.0, 0.0],
                [0.0, -1.0, 0.0],
                [0.0, 0.0, -1.0],
            ))
            .with_light(light),
    );
    b.to_glb()
}

/// One mesh drawn twice: instances must become separate receivers.
///
/// * `floor`: [-2, 2]² at y = 0 facing up, reflectance 0.5 grey.
/// * mesh `panel`: a 1 m × 1 m quad [-0.5, 0.5]² in its local xz-plane facing local +y, with
///   `TEXCOORD_0` (0,0)…(1,1), reflectance 0.5 grey; drawn by two nodes, children of the node
///   `panels` (translation (0, 0.25, 0)):
///   - `panel A`: TRS translation (-0.8, 0.25, 0) → world centre (-0.8, 0.5, 0), facing +y;
///   - `panel B`: a `matrix` (rotation 30° about +y, translation (0.8, 0.75, 0)) → world
///     centre (0.8, 1.0, 0), facing +y.
/// * `light`: [-0.5, 0.5]² at y = 3 facing down, emitting [`AREA_LIGHT_RADIANCE`] = 10
///   W/(m² sr), reflectance 0.
pub fn instanced() -> Vec<u8> {
    let mut b = GlbBuilder::new();
    let grey = b.add_material(Material::diffuse("grey", [0.5; 3]));
    b.add_mesh_node(
        "floor",
        &horizontal_rect([-2.0, 2.0], [-2.0, 2.0], 0.0, true),
        grey,
    );
    let panel = horizontal_rect([-0.5, 0.5], [-0.5, 0.5], 0.0, true).with_texcoords(vec![
        [0.0, 0.0],
        [0.0, 1.0],
        [1.0, 1.0],
        [1.0, 0.0],
    ]);
    let mesh = b.add_mesh("panel", &[(&panel, grey)]);
    let a = b.add_node(
        Node::new("panel A")
            .with_mesh(mesh)
            .with_transform(Transform::translation([-0.8, 0.25, 0.0])),
    );
    let m = DMat4::from_rotation_translation(
        DQuat::from_rotation_y(PI / 6.0),
        DVec3::new(0.8, 0.75, 0.0),
    );
    let b_node = b.add_node(
        Node::new("panel B")
            .with_mesh(mesh)
            .with_transform(Transform::Matrix(m)),
    );
    b.add_node(
        Node::new("panels")
            .with_transform(Transform::translation([0.0, 0.25, 0.0]))
            .with_children(&[a, b_node]),
    );
    add_area_light(&mut b);
    b.to_glb()
}

/// An `n` × `n` grid of boxes on a floor under one square area light: the scene that scales,
/// for stability tests and benchmarks (not written to `fixtures/`).
///
/// * `floor`: [-h, h]² at y = 0 facing up, `h = 0.1 n + 0.5` m, reflectance 0.5 grey.
/// * `light`: [-0.5, 0.5]² at y = 2 facing down, emitting 5 W/(m² sr) white, reflectance 0.
/// * `boxes`: one mesh of `n²` closed cuboids 0.1 m wide and 0.2 m tall, at a pitch of 0.2 m
///   (the box at grid cell `(i, j)` spans x from `0.2 (i - n/2)`, z from `0.2 (j - n/2)`),
///   12 triangles each, no vertex normals, reflectance 0.5 grey. Their tops are coplanar and
///   their edges aligned, so discontinuity lines cross and overlap along whole rows, and each
///   box's bottom face lies on the floor (a contact outline).
///
/// `12 n² + 4` triangles in all.
pub fn box_grid(n: usize) -> Vec<u8> {
    let mut g = GlbBuilder::new();
    let grey = g.add_material(Material::diffuse("grey", [0.5; 3]));
    let half = 0.1 * n as f64 + 0.5;
    g.add_mesh_node(
        "floor",
        &horizontal_rect([-half, half], [-half, half], 0.0, true),
        grey,
    );
    let light = g.add_material(Material::diffuse("light", [0.0; 3]).emitting([5.0; 3]));
    g.add_mesh_node(
        "light",
        &horizontal_rect([-0.5, 0.5], [-0.5, 0.5], 2.0, false),
        light,
    );
    let mut boxes = TriangleMesh {
        positions: vec![],
        normals: None,
        texcoords: None,
        indices: vec![],
    };
    for i in 0..n {
        for j in 0..n {
            let x = (i as f64 - n as f64 / 2.0) * 0.2;
            let z = (j as f64 - n as f64 / 2.0) * 0.2;
            let mut c = cuboid([x, 0.0, z], [x + 0.1, 0.2, z + 0.1]);
            c.normals = None;
            boxes.append(&c);
        }
    }
    g.add_mesh_node("boxes", &boxes, grey);
    g.to_glb()
}

/// Every generated scene as `(file stem, glb bytes)`, in a fixed order; `make_fixtures` writes
/// each to `fixtures/<stem>.glb`.
pub fn all() -> Vec<(&'static str, Vec<u8>)> {
    vec![
        ("cornell-box", cornell_box()),
        ("square-occluder", square_occluder()),
        ("box-on-floor", box_on_floor()),
        ("furnace-box", furnace_box()),
        ("point-light", point_light()),
        ("spot-light", spot_light()),
        ("directional-light", directional_light()),
        ("plane-uniform", plane_uniform()),
        ("instanced", instanced()),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(glb: &[u8]) -> gltf::Gltf {
        gltf::Gltf::from_slice(glb).expect("fixture must parse")
    }

    /// World-space triangles of every mesh node: (node name, [a, b, c]) per triangle.
    fn world_triangles(glb: &[u8]) -> Vec<(String, [DVec3; 3])> {
        let g = parse(glb);
        let blob = g.blob.clone();
        let mut out = Vec::new();
        fn walk(
            node: gltf::Node,
            parent: DMat4,
            blob: &Option<Vec<u8>>,
            out: &mut Vec<(String, [DVec3; 3])>,
        ) {
            let local =
                DMat4::from_cols_array_2d(&node.transform().matrix().map(|c| c.map(f64::from)));
            let world = parent * local;
            if let Some(mesh) = node.mesh() {
                for p in mesh.primitives() {
                    let r = p.reader(|_| blob.as_deref());
                    let pos: Vec<DVec3> = r
                        .read_positions()
                        .unwrap()
                        .map(|v| world.transform_point3(DVec3::from(v.map(f64::from))))
                        .collect();
                    let idx: Vec<u32> = r.read_indices().unwrap().into_u32().collect();
                    for t in idx.chunks_exact(3) {
                        out.push((
                            node.name().unwrap().to_owned(),
                            [t[0], t[1], t[2]].map(|i| pos[i as usize]),
                        ));
                    }
                }
            }
            for c in node.children() {
                walk(c, world, blob, out);
            }
        }
        for n in g.default_scene().unwrap().nodes() {
            walk(n, DMat4::IDENTITY, &blob, &mut out);
        }
        out
    }

    fn normal(t: &[DVec3; 3]) -> DVec3 {
        (t[1] - t[0]).cross(t[2] - t[0]).normalize()
    }

    #[test]
    fn every_scene_parses_and_is_deterministic() {
        let first = all();
        let second = all();
        assert_eq!(first.len(), 9);
        for ((name, a), (_, b)) in first.iter().zip(&second) {
            assert_eq!(a, b, "{name}: bytes differ between calls");
            let g = parse(a);
            assert_eq!(g.scenes().count(), 1, "{name}");
            assert!(g.default_scene().is_some(), "{name}");
            assert!(a.len() < 16 * 1024, "{name} is {} bytes", a.len());
        }
    }

    #[test]
    fn glb_layout() {
        for (name, glb) in all() {
            let word = |i: usize| u32::from_le_bytes(glb[i..i + 4].try_into().unwrap());
            assert_eq!(&glb[0..4], b"glTF", "{name}");
            assert_eq!(word(4), 2);
            assert_eq!(word(8) as usize, glb.len());
            let json_len = word(12) as usize;
            assert_eq!(word(16), CHUNK_JSON);
            assert_eq!(json_len % 4, 0);
            let bin_at = 20 + json_len;
            let bin_len = word(bin_at) as usize;
            assert_eq!(word(bin_at + 4), CHUNK_BIN);
            assert_eq!(bin_len % 4, 0);
            assert_eq!(bin_at + 8 + bin_len, glb.len());
            let json: Value = serde_json::from_slice(&glb[20..bin_at]).unwrap();
            assert_eq!(
                json["buffers"][0]["byteLength"].as_u64().unwrap() as usize,
                bin_len
            );
            for view in json["bufferViews"].as_array().unwrap() {
                assert_eq!(view["byteOffset"].as_u64().unwrap() % 4, 0, "{name}");
                assert!(view["target"].is_u64(), "{name}");
            }
        }
    }

    #[test]
    fn cornell_box_geometry() {
        let glb = cornell_box();
        let tris = world_triangles(&glb);
        assert_eq!(tris.len(), CORNELL_TRIANGLES);
        let centre = DVec3::new(0.278, 0.274, 0.28);
        let expect = [
            ("floor", DVec3::Y),
            ("ceiling", DVec3::NEG_Y),
            ("back wall", DVec3::NEG_Z),
            ("green wall", DVec3::X),
            ("red wall", DVec3::NEG_X),
            ("light", DVec3::NEG_Y),
        ];
        for (name, n_expected) in expect {
            let mine: Vec<_> = tris.iter().filter(|(n, _)| n == name).collect();
            assert_eq!(mine.len(), 2, "{name}");
            for (_, t) in mine {
                let n = normal(t);
                assert!(n.dot(n_expected) > 0.999, "{name}: normal {n}");
                // Faces into the box.
                assert!(n.dot(centre - t[0]) > 0.0, "{name}");
            }
        }
        // Blocks: 10 triangles each, every face outward.
        for name in ["short block", "tall block"] {
            let mine: Vec<_> = tris
                .iter()
                .filter(|(n, _)| n == name)
                .map(|(_, t)| *t)
                .collect();
            assert_eq!(mine.len(), 10, "{name}");
            let c = mine.iter().flatten().sum::<DVec3>() / (3.0 * mine.len() as f64);
            for t in &mine {
                let f = (t[0] + t[1] + t[2]) / 3.0;
                assert!(normal(t).dot(f - c) > 0.0, "{name}: face points inward");
                assert!(t.iter().all(|p| p.y >= 0.0));
            }
        }
        // The light is below the ceiling and inside its outline.
        let light: Vec<_> = tris.iter().filter(|(n, _)| n == "light").collect();
        assert!(
            light
                .iter()
                .all(|(_, t)| t.iter().all(|p| (p.y - 0.5487).abs() < 1e-6))
        );

        let g = parse(&glb);
        let mat = g.materials().find(|m| m.name() == Some("light")).unwrap();
        let f = mat.emissive_factor();
        let s = mat.emissive_strength().unwrap();
        for k in 0..3 {
            assert!(f[k] <= 1.0);
            assert!((f64::from(f[k] * s) - CORNELL_LIGHT_RADIANCE[k]).abs() < 1e-4);
        }
        let cam = g.nodes().find(|n| n.camera().is_some()).unwrap();
        let m = DMat4::from_cols_array_2d(&cam.transform().matrix().map(|c| c.map(f64::from)));
        let forward = m.transform_vector3(DVec3::NEG_Z);
        assert!(forward.dot(DVec3::Z) > 0.999999);
        assert!(m.transform_vector3(DVec3::Y).dot(DVec3::Y) > 0.999999);
        assert!((m.transform_point3(DVec3::ZERO) - DVec3::new(0.278, 0.273, -0.8)).length() < 1e-6);
        match cam.camera().unwrap().projection() {
            gltf::camera::Projection::Perspective(p) => {
                assert!((f64::from(p.yfov()) - 2.0 * (12.5f64 / 35.0).atan()).abs() < 1e-6);
                assert_eq!(p.aspect_ratio(), Some(1.0));
            }
            _ => panic!("orthographic camera"),
        }
        let mut used: Vec<_> = g.extensions_used().collect();
        used.sort();
        assert_eq!(used, [KHR_MATERIALS_EMISSIVE_STRENGTH]);
    }

    #[test]
    fn vertex_normals_match_winding() {
        for (name, glb) in all() {
            let g = parse(&glb);
            let blob = g.blob.clone();
            for mesh in g.meshes() {
                for p in mesh.primitives() {
                    let r = p.reader(|_| blob.as_deref());
                    let pos: Vec<DVec3> = r
                        .read_positions()
                        .unwrap()
                        .map(|v| DVec3::from(v.map(f64::from)))
                        .collect();
                    let nor: Vec<DVec3> = r
                        .read_normals()
                        .unwrap()
                        .map(|v| DVec3::from(v.map(f64::from)))
                        .collect();
                    let idx: Vec<u32> = r.read_indices().unwrap().into_u32().collect();
                    for t in idx.chunks_exact(3) {
                        let tri = [t[0], t[1], t[2]].map(|i| pos[i as usize]);
                        let n = normal(&tri);
                        for &i in t {
                            assert!(
                                nor[i as usize].dot(n) > 0.99,
                                "{name}: vertex normal against winding"
                            );
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn furnace_faces_inward() {
        let tris = world_triangles(&furnace_box());
        assert_eq!(tris.len(), 12);
        for (_, t) in &tris {
            let f = (t[0] + t[1] + t[2]) / 3.0;
            assert!(normal(t).dot(-f) > 0.0);
        }
        let g = parse(&furnace_box());
        let m = g.materials().next().unwrap();
        assert!((m.emissive_factor()[0] - (1.0 / PI) as f32).abs() < 1e-7);
        assert_eq!(m.emissive_strength(), None);
        assert_eq!(g.extensions_used().count(), 0);
        // Strong emission goes through the extension.
        let g = parse(&furnace_box_with(0.25, 10.0));
        let m = g.materials().next().unwrap();
        assert_eq!(m.emissive_factor(), [1.0; 3]);
        assert!((f64::from(m.emissive_strength().unwrap()) - 10.0 / PI).abs() < 1e-5);
    }

    #[test]
    fn lights() {
        let g = parse(&point_light());
        let l: Vec<_> = g.lights().unwrap().collect();
        assert_eq!(l.len(), 1);
        assert_eq!(l[0].intensity(), 10.0);
        assert!(matches!(
            l[0].kind(),
            gltf::khr_lights_punctual::Kind::Point
        ));
        let node = g.nodes().find(|n| n.light().is_some()).unwrap();
        assert_eq!(node.transform().decomposed().0, [0.0, 2.0, 0.0]);

        let dir_of = |glb: &[u8]| {
            let g = parse(glb);
            let node = g.nodes().find(|n| n.light().is_some()).unwrap();
            let m = DMat4::from_cols_array_2d(&node.transform().matrix().map(|c| c.map(f64::from)));
            m.transform_vector3(DVec3::NEG_Z)
        };
        assert!(dir_of(&spot_light()).dot(DVec3::NEG_Y) > 0.999999);
        assert!(dir_of(&plane_uniform()).dot(DVec3::NEG_Y) > 0.999999);
        assert!(
            dir_of(&directional_light()).dot(DVec3::new(1.0, -1.0, 0.0).normalize()) > 0.999999
        );
        let g = parse(&spot_light());
        match g.lights().unwrap().next().unwrap().kind() {
            gltf::khr_lights_punctual::Kind::Spot {
                inner_cone_angle,
                outer_cone_angle,
            } => {
                assert_eq!((inner_cone_angle, outer_cone_angle), (0.4, 0.6));
            }
            _ => panic!("not a spot light"),
        }
        assert_eq!(world_triangles(&spot_light()).len(), 2 + 10);
        let mut used: Vec<_> = g.extensions_used().collect();
        used.sort();
        assert_eq!(used, [KHR_LIGHTS_PUNCTUAL]);
    }

    #[test]
    fn instances_are_separate() {
        let tris = world_triangles(&instanced());
        let centre = |name: &str| {
            let mine: Vec<_> = tris.iter().filter(|(n, _)| n == name).collect();
            assert_eq!(mine.len(), 2);
            mine.iter().map(|(_, t)| t[0] + t[1] + t[2]).sum::<DVec3>() / 6.0
        };
        assert!((centre("panel A") - DVec3::new(-0.8, 0.5, 0.0)).length() < 1e-6);
        assert!((centre("panel B") - DVec3::new(0.8, 1.0, 0.0)).length() < 1e-6);
        let g = parse(&instanced());
        assert_eq!(g.meshes().count(), 3);
        let panel = g.meshes().find(|m| m.name() == Some("panel")).unwrap();
        assert!(
            panel
                .primitives()
                .next()
                .unwrap()
                .get(&gltf::Semantic::TexCoords(0))
                .is_some()
        );
    }

    #[test]
    fn square_occluder_layout() {
        let glb = square_occluder();
        let g = parse(&glb);
        let occ = g
            .materials()
            .find(|m| m.name() == Some("occluder"))
            .unwrap();
        assert!(occ.double_sided());
        let tris = world_triangles(&glb);
        for (name, y, n) in [
            ("floor", 0.0, DVec3::Y),
            ("occluder", 1.0, DVec3::Y),
            ("source", 2.0, DVec3::NEG_Y),
        ] {
            for (_, t) in tris.iter().filter(|(m, _)| m == name) {
                assert!(t.iter().all(|p| p.y == y), "{name}");
                assert!(normal(t).dot(n) > 0.999999, "{name}");
            }
        }
    }

    #[test]
    fn emissive_split() {
        let m = Material::diffuse("m", [0.5; 3]).emitting([17.0, 12.0, 4.0]);
        let (f, s) = m.emissive_factor_and_strength();
        assert_eq!(s, 17.0);
        assert_eq!(f[0], 1.0);
        assert!((f[1] * s - 12.0).abs() < 1e-12);
        let (f, s) = Material::diffuse("m", [0.5; 3])
            .emitting([0.5, 1.0, 0.0])
            .emissive_factor_and_strength();
        assert_eq!((f, s), ([0.5, 1.0, 0.0], 1.0));
    }

    #[test]
    fn large_meshes_use_u32_indices_and_correct_bounds() {
        let mut big = TriangleMesh::default();
        for i in 0..17000 {
            let x = i as f64 * 0.01;
            big.append(&quad([
                [x, 0.0, 0.0],
                [x, 0.0, 1.0],
                [x + 0.01, 0.0, 1.0],
                [x + 0.01, 0.0, 0.0],
            ]));
        }
        assert_eq!(big.positions.len(), 68000);
        let mut b = GlbBuilder::new();
        let m = b.add_material(Material::diffuse("m", [0.5; 3]));
        b.add_mesh_node("big", &big, m);
        let small = b.add_mesh(
            "small",
            &[(
                &quad([[0.0; 3], [0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [1.0, 0.0, 0.0]]),
                m,
            )],
        );
        b.add_node(Node::new("small").with_mesh(small));
        let json = b.to_json();
        let acc = json["accessors"].as_array().unwrap();
        assert_eq!(acc[2]["componentType"], json!(UNSIGNED_INT));
        assert_eq!(acc[5]["componentType"], json!(UNSIGNED_SHORT));
        let g = parse(&b.to_glb());
        let bb = g
            .meshes()
            .next()
            .unwrap()
            .primitives()
            .next()
            .unwrap()
            .bounding_box();
        assert_eq!(bb.min, [0.0, 0.0, 0.0]);
        assert_eq!(bb.max, [(17000.0f64 * 0.01) as f32, 0.0, 1.0]);
        assert_eq!(b.extensions_used(), Vec::<&str>::new());
    }

    #[test]
    fn mesh_helpers() {
        let c = cuboid([0.0; 3], [1.0, 2.0, 3.0]);
        assert_eq!((c.positions.len(), c.triangle_count()), (24, 12));
        assert_eq!(c.bounds(), ([0.0; 3], [1.0, 2.0, 3.0]));
        for t in 0..12 {
            let [a, b, d] =
                [0, 1, 2].map(|k| DVec3::from(c.positions[c.indices[3 * t + k] as usize]));
            let f = (a + b + d) / 3.0;
            let n = DVec3::from(c.face_normal(t));
            assert!(n.dot(f - DVec3::new(0.5, 1.0, 1.5)) > 0.0);
        }
        let inside = flip(c.clone());
        for t in 0..12 {
            assert_eq!(
                DVec3::from(inside.face_normal(t)),
                -DVec3::from(c.face_normal(t))
            );
        }
        let down = horizontal_rect([0.0, 1.0], [0.0, 1.0], 0.0, false);
        assert_eq!(down.face_normal(0), [0.0, -1.0, 0.0]);
        assert_eq!(down.normals.as_ref().unwrap()[0], [0.0, -1.0, 0.0]);
    }
}
