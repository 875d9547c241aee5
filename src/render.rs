//! Pictures of a baked glb as a client shows it: per pixel, the first surface hit, its
//! `MOZ_lightmap` texel (bilinear, decoded by the texture's `extras.penumbra.encoding`: `srgb`
//! or `linear`, linear when absent) x intensity = irradiance H, shown as `albedo/pi x H` plus
//! the surface's own emission, exposed and encoded as sRGB. Each primitive reads the lightmap
//! page its material's `MOZ_lightmap.index` names.
//!
//! It reads only the output file (the UV set `MOZ_lightmap.texCoord` names, the lightmap image,
//! the materials; through [`crate::write::binding`]), so it checks what a client would see, not
//! the baker's internal state.

use crate::error::{Error, Result};
use crate::lightmap::Lightmap;
use crate::load::{self, Gltf};
use crate::scene::Scene;
use crate::visibility::Visibility;
use crate::write::binding::{self, Binding};
use glam::{DMat4, DVec2, DVec3};
use rayon::prelude::*;
use std::collections::BTreeMap;

/// A pinhole camera in world space.
#[derive(Clone, Copy, Debug)]
pub struct Camera {
    pub(crate) eye: DVec3,
    /// Unit vectors: forward (view direction), up and right.
    pub(crate) forward: DVec3,
    pub(crate) up: DVec3,
    pub(crate) right: DVec3,
    /// Vertical field of view, radians.
    pub(crate) yfov: f64,
}

impl Camera {
    /// The first perspective camera of the default scene, if any.
    pub fn from_gltf(gltf: &Gltf) -> Option<Camera> {
        Self::find(gltf, None)
    }

    /// The perspective camera of the default scene whose camera or node is called `name`.
    pub fn named(gltf: &Gltf, name: &str) -> Option<Camera> {
        Self::find(gltf, Some(name))
    }

    /// Names of the default scene's perspective cameras (camera name, else node name).
    pub fn names(gltf: &Gltf) -> Vec<String> {
        gltf.document
            .nodes()
            .filter_map(|n| {
                let cam = n.camera()?;
                matches!(cam.projection(), gltf::camera::Projection::Perspective(_))
                    .then(|| cam.name().or(n.name()).unwrap_or("").to_string())
            })
            .collect()
    }

    fn find(gltf: &Gltf, name: Option<&str>) -> Option<Camera> {
        let scene = gltf
            .document
            .default_scene()
            .or_else(|| gltf.document.scenes().next())?;
        let mut stack: Vec<(gltf::Node, DMat4)> =
            scene.nodes().map(|n| (n, DMat4::IDENTITY)).collect();
        let mut visited = vec![false; gltf.document.nodes().len()];
        while let Some((node, parent)) = stack.pop() {
            if std::mem::replace(&mut visited[node.index()], true) {
                continue; // not a tree: load::scene reports it
            }
            let world = parent
                * DMat4::from_cols_array_2d(&node.transform().matrix().map(|c| c.map(f64::from)));
            if let Some(cam) = node.camera()
                && let gltf::camera::Projection::Perspective(p) = cam.projection()
                && name.is_none_or(|n| cam.name() == Some(n) || node.name() == Some(n))
            {
                let forward = world.transform_vector3(DVec3::NEG_Z).normalize();
                let up0 = world.transform_vector3(DVec3::Y).normalize();
                let right = forward.cross(up0).normalize();
                return Some(Camera {
                    eye: world.transform_point3(DVec3::ZERO),
                    forward,
                    up: right.cross(forward),
                    right,
                    yfov: p.yfov() as f64,
                });
            }
            stack.extend(node.children().map(|c| (c, world)));
        }
        None
    }

    /// A camera at `eye` looking at `target` (world space), with vertical field of view `yfov`
    /// (radians); `up` is +y, or +z when looking straight up or down. `None` when the two
    /// points coincide or a value is not finite.
    pub fn look_at(eye: DVec3, target: DVec3, yfov: f64) -> Option<Camera> {
        let forward = (target - eye).try_normalize()?;
        if !(eye.is_finite() && target.is_finite() && yfov.is_finite()) {
            return None;
        }
        let up0 = if forward.cross(DVec3::Y).length() > 1e-6 {
            DVec3::Y
        } else {
            DVec3::Z
        };
        let right = forward.cross(up0).normalize();
        Some(Camera {
            eye,
            forward,
            up: right.cross(forward),
            right,
            yfov,
        })
    }

    internal! {
        /// A camera that frames the scene's bounding box from the front-above diagonal.
        pub fn auto(scene: &Scene) -> Camera {
            let center = (scene.bounds_min + scene.bounds_max) * 0.5;
            let radius = scene.extent() * 0.5;
            let yfov: f64 = 0.8;
            let dir = DVec3::new(0.6, -0.45, -1.0).normalize();
            let eye = center - dir * (radius / (yfov * 0.5).sin());
            let right = dir.cross(DVec3::Y).normalize();
            Camera {
                eye,
                forward: dir,
                up: right.cross(dir),
                right,
                yfov,
            }
        }
    }
}

/// What a lightmapped surface shows.
#[derive(Clone, Copy, Debug)]
pub enum Shading<'a> {
    /// `albedo/pi x H` with H from the file's own lightmap texture (as a client shows it).
    Lightmap,
    /// [`Shading::Lightmap`] as a game adjusts it at run time: each light group's layer
    /// (`MOZ_lightmap.extras.penumbra.layers`) scaled by its factor in `layers` (group name,
    /// factor; `H + (factor - 1) H_group`), and with `occlusion` H times the material's
    /// `occlusionTexture` (its red channel, linear, by its `strength`: `1 + strength (ao -
    /// 1)`), as three.js applies an `aoMap` to a `lightMap` (and Bevy and Godot their
    /// occlusion to baked indirect light).
    Adjusted {
        layers: &'a [(String, f64)],
        occlusion: bool,
        /// A white sphere (centre, radius in scene units) lit by the file's light probes
        /// (`extras.penumbra_probes`), as a moving object is: the probes' harmonics
        /// interpolated trilinearly at its centre (probes inside geometry left out), shown as
        /// `E(n) / pi`.
        probe_sphere: Option<(DVec3, f64)>,
        /// The directional lightmap's pages (a bake's `--directional`) with the materials'
        /// `normalTexture`: H for the normal-mapped normal `n`, `H (1/2 + 2 r · n)`
        /// ([`crate::lightmap::directional`]).
        directional: bool,
    },
    /// The reference picture: `albedo/pi x E` with E the irradiance at each pixel's surface
    /// point for its normal-mapped normal (the materials' `normalTexture`), path-traced with
    /// `spp` paths, under the uniform sky `sky` (W/(m² sr)); no lightmap is read. Slow: what a
    /// directional lightmap is checked against.
    PathTraced { spp: u32, sky: DVec3 },
    /// `H/pi` from the file's own lightmap texture: the lightmap alone, on white surfaces, no
    /// emission (what a lightmap holds, whatever the textures and colours).
    LightmapAlone,
    /// `albedo/pi x H` with H from this float map over the same texel grid (e.g. a reference
    /// or another bake of the same layout), sampled bilinearly like the texture.
    Irradiance(&'a Lightmap),
    /// This map's value as the displayed colour itself (false colour), no albedo or emission;
    /// surfaces without a lightmap show dark grey.
    Colour(&'a Lightmap),
}

/// Renders a baked glb as a client shows it. `exposure`: radiance that maps to white;
/// `None`: automatic.
pub fn render(
    gltf: &Gltf,
    camera: Option<Camera>,
    width: u32,
    height: u32,
    exposure: Option<f64>,
) -> Result<image::RgbImage> {
    render_shaded(gltf, camera, width, height, exposure, Shading::Lightmap)
}

/// [`render`] with the surfaces shaded as `shading` says: for example lit by a float lightmap
/// or a reference instead of the file's own lightmap ([`Shading::Irradiance`]), or the
/// lightmap alone ([`Shading::LightmapAlone`]).
pub fn render_shaded(
    gltf: &Gltf,
    camera: Option<Camera>,
    width: u32,
    height: u32,
    exposure: Option<f64>,
    shading: Shading,
) -> Result<image::RgbImage> {
    let radiance = render_radiance(gltf, camera, width, height, shading)?;
    let scale = exposure.unwrap_or_else(|| auto_exposure(&radiance));
    Ok(tone_map(&radiance, width, height, scale))
}

/// Reads a float lightmap (OpenEXR, linear RGB): `path` is page 0, and the pages after it are
/// read from beside it while they exist ([`crate::bake::exr_page_path`]), each the size of the
/// first.
pub fn read_irradiance(path: &std::path::Path) -> Result<Lightmap> {
    let first = image::open(path).map_err(|e| Error::BadItem {
        path: path.to_path_buf(),
        item: "lightmap".into(),
        reason: format!("cannot read it as OpenEXR: {e}"),
    })?;
    let (width, height) = (first.width(), first.height());
    let mut pages = 1;
    while crate::bake::exr_page_path(path, pages).is_file() {
        pages += 1;
    }
    let texels = crate::reference::accuracy::read_lightmap(path, width, height * pages, pages)?;
    Ok(Lightmap {
        width,
        height,
        texels,
        coverage: Vec::new(),
    })
}

/// Per pixel (row-major, top row first) the radiance the camera sees (or the false colour,
/// for [`Shading::Colour`]), linear RGB.
pub fn render_radiance(
    gltf: &Gltf,
    camera: Option<Camera>,
    width: u32,
    height: u32,
    shading: Shading<'_>,
) -> Result<Vec<DVec3>> {
    let scene = load::scene(gltf)?;
    let vis = Visibility::new(&scene);
    let camera = camera.unwrap_or_else(|| Camera::auto(&scene));
    let bad = |item: String, reason: &str| Error::BadItem {
        path: gltf.path.clone(),
        item,
        reason: reason.into(),
    };
    // Decoded textures per texture index: lightmaps (and layers) by their encoding, occlusion
    // textures as their red channel, linear.
    let mut textures: BTreeMap<usize, Lightmap> = BTreeMap::new();
    let mut decode = |texture: usize, occlusion: bool| -> Result<()> {
        if textures.contains_key(&texture) {
            return Ok(());
        }
        let item = format!("texture {texture}");
        let bytes = binding::texture_bytes(gltf, texture)?;
        let encoding = binding::texture_encoding(gltf, texture)?;
        let img = gltf
            .decode_image(&bytes, &item)?
            .map_err(|e| bad(item, &e))?
            .to_rgb32f();
        let texels = img
            .pixels()
            .map(|p| match occlusion {
                true => DVec3::splat(f64::from(p.0[0])),
                false => DVec3::from(p.0.map(|c| encoding.decode(f64::from(c)))),
            })
            .collect();
        textures.insert(
            texture,
            Lightmap {
                width: img.width(),
                height: img.height(),
                texels,
                coverage: Vec::new(),
            },
        );
        Ok(())
    };
    // Per instance: its lightmap binding with its page; with [`Shading::Adjusted`], the layer
    // textures to add (texture, weight: intensity x (factor - 1)) and its occlusion binding;
    // with directional shading or the path tracer, its normal map.
    let directional = matches!(
        shading,
        Shading::Adjusted {
            directional: true,
            ..
        }
    );
    let traced = match shading {
        Shading::PathTraced { sky, .. } => {
            Some(crate::reference::Tracer::new(&scene, &vis, None, sky))
        }
        _ => None,
    };
    let mut bindings: Vec<Option<(Binding, usize)>> = Vec::new();
    let mut added: Vec<Vec<(usize, f64)>> = Vec::new();
    let mut occlusions: Vec<Option<Binding>> = Vec::new();
    let mut normal_maps: Vec<Option<Binding>> = Vec::new();
    for inst in &scene.instances {
        let b = binding::binding(gltf, inst)?;
        let mut add = Vec::new();
        if let Some(b) = &b {
            decode(b.texture, false)?;
            if let Shading::Adjusted { layers, .. } = shading {
                for (group, factor) in layers {
                    if let Some(&(texture, intensity)) = b.layers.get(group) {
                        decode(texture, false)?;
                        add.push((texture, intensity * (factor - 1.0)));
                    }
                }
            }
            if directional {
                let pages = b.directional.ok_or_else(|| {
                    bad(
                        format!("mesh {} primitive {}", inst.mesh, inst.primitive),
                        "its lightmap has no directional pages (bake with --directional)",
                    )
                })?;
                for t in pages {
                    decode(t, false)?;
                }
            }
        }
        added.push(add);
        let normal_map = match directional || traced.is_some() {
            true => binding::normal_map(gltf, inst)?,
            false => None,
        };
        if let Some(m) = &normal_map {
            decode(m.texture, false)?;
        }
        normal_maps.push(normal_map);
        let o = match shading {
            Shading::Adjusted {
                occlusion: true, ..
            } => binding::occlusion(gltf, inst)?,
            _ => None,
        };
        if let Some(o) = &o {
            decode(o.texture, true)?;
        }
        occlusions.push(o);
        bindings.push(b.map(|b| {
            let page = binding::texture_page(gltf, b.texture);
            (b, page)
        }));
    }
    if let Shading::Adjusted { layers, .. } = shading {
        let known: std::collections::BTreeSet<&String> = bindings
            .iter()
            .flatten()
            .flat_map(|(b, _)| b.layers.keys())
            .collect();
        if let Some((missing, _)) = layers.iter().find(|(g, _)| !known.contains(g)) {
            return Err(Error::BadItem {
                path: gltf.path.clone(),
                item: format!("light group {missing:?}"),
                reason: format!("no lightmap layer of that name (layers: {known:?})"),
            });
        }
    }
    let aspect = width as f64 / height as f64;
    let tan = (camera.yfov * 0.5).tan();
    let sphere = match shading {
        Shading::Adjusted {
            probe_sphere: Some((centre, radius)),
            ..
        } => Some((centre, radius, probe_light_at(gltf, centre)?)),
        _ => None,
    };
    let radiance: Vec<DVec3> = (0..width * height)
        .into_par_iter()
        .map(|i| {
            let (x, y) = ((i % width) as f64 + 0.5, (i / width) as f64 + 0.5);
            let sx = (2.0 * x / width as f64 - 1.0) * tan * aspect;
            let sy = (1.0 - 2.0 * y / height as f64) * tan;
            let dir = (camera.forward + camera.right * sx + camera.up * sy).normalize();
            let hit = vis.first_hit(camera.eye, dir, f64::MAX);
            if let Some((centre, radius, sh)) = &sphere
                && let Some(t) = sphere_hit(camera.eye, dir, *centre, *radius)
                && hit.is_none_or(|h| t < h.t)
            {
                let n = (camera.eye + dir * t - *centre) / *radius;
                return crate::probes::sh_irradiance(sh, n) / std::f64::consts::PI;
            }
            let Some(hit) = hit else {
                return DVec3::ZERO;
            };
            let tri = &scene.triangles[hit.triangle];
            let mat = &scene.materials[tri.material];
            let p = camera.eye + dir * hit.t;
            let bary = crate::geometry::barycentric_3d(&tri.p, p);
            let uv = bindings[tri.instance].as_ref().map(|(b, page)| {
                let inst = &scene.instances[tri.instance];
                let k = tri.local_index;
                let ids = &inst.indices[3 * k..3 * k + 3];
                let uv: DVec2 = (0..3).map(|c| b.uv[ids[c] as usize] * bary[c]).sum();
                (b, *page, uv)
            });
            if let Shading::Colour(map) = shading {
                return uv.map_or(DVec3::splat(0.02), |(_, page, uv)| {
                    sample_page(map, page, uv)
                });
            }
            let alone = matches!(shading, Shading::LightmapAlone);
            let mut l = if tri.normal.dot(dir) < 0.0 && !alone {
                mat.radiance
            } else {
                DVec3::ZERO
            };
            let inst = &scene.instances[tri.instance];
            let ids = &inst.indices[3 * tri.local_index..3 * tri.local_index + 3];
            let shading_normal = || match &normal_maps[tri.instance] {
                Some(m) => {
                    let uv = [0, 1, 2].map(|c| m.uv[ids[c] as usize]);
                    let at: DVec2 = (0..3).map(|c| uv[c] * bary[c]).sum();
                    let t = sample_map(&textures[&m.texture], at) * 2.0 - DVec3::ONE;
                    normal_mapped(&tri.p, &uv, tri.normal, t, m.intensity)
                }
                None => tri.normal,
            };
            if let (Some(tracer), Some(poly)) = (&traced, tri.polygon) {
                let Shading::PathTraced { spp, .. } = shading else {
                    unreachable!("a tracer only for the path-traced picture")
                };
                let frame = &scene.polygons[poly].frame;
                let on = p - frame.n * frame.n.dot(p - frame.origin);
                let at = crate::light::SurfacePoint::new(on, frame.n, poly, &vis);
                let mut rng = crate::rng::SplitMix64(crate::rng::mix64(u64::from(i)));
                let e = tracer.irradiance_facing(&at, shading_normal(), spp, &mut rng);
                return l + scene.albedo_at(hit.triangle, bary) / std::f64::consts::PI * e;
            }
            if let Some((b, page, uv)) = uv {
                let mut h = match shading {
                    Shading::Irradiance(map) => sample_page(map, page, uv),
                    _ => sample_map(&textures[&b.texture], uv) * b.intensity,
                };
                if directional && let Some(pages) = b.directional {
                    let r = pages.map(|t| sample_map(&textures[&t], uv) * 2.0 - DVec3::ONE);
                    h = crate::lightmap::directional::shade(h, r, shading_normal());
                }
                for &(texture, weight) in &added[tri.instance] {
                    h += sample_map(&textures[&texture], uv) * weight;
                }
                if let Some(o) = &occlusions[tri.instance] {
                    let uv: DVec2 = (0..3).map(|c| o.uv[ids[c] as usize] * bary[c]).sum();
                    let ao = sample_map(&textures[&o.texture], uv).x;
                    h *= 1.0 + o.intensity * (ao - 1.0);
                }
                let albedo = if alone {
                    DVec3::ONE
                } else {
                    scene.albedo_at(hit.triangle, bary)
                };
                l += albedo / std::f64::consts::PI * h;
            }
            l
        })
        .collect();
    Ok(radiance)
}

/// The normal that a tangent-space normal map's value `t` (in [-1, 1]³) gives on the triangle
/// with world corners `p`, normal-map UVs `uv` and unit normal `n`, its x and y scaled by
/// `scale` (the `normalTexture.scale`). The tangent frame is the triangle's own, as MikkTSpace
/// (glTF's default for a mesh without `TANGENT`s) gives it on a flat face: the unit tangent
/// `T` along increasing u in the surface's plane, the bitangent `B = ±n × T` on the side of
/// decreasing v (glTF's convention: +y of the map is up the texture).
fn normal_mapped(p: &[DVec3; 3], uv: &[DVec2; 3], n: DVec3, t: DVec3, scale: f64) -> DVec3 {
    let (e1, e2) = (p[1] - p[0], p[2] - p[0]);
    let (d1, d2) = (uv[1] - uv[0], uv[2] - uv[0]);
    let det = d1.x * d2.y - d2.x * d1.y;
    if det == 0.0 || !det.is_finite() {
        return n;
    }
    // dP/du and dP/dv of the triangle's linear map from UV to space.
    let dpdu = (e1 * d2.y - e2 * d1.y) / det;
    let dpdv = (e2 * d1.x - e1 * d2.x) / det;
    let Some(tangent) = (dpdu - n * n.dot(dpdu)).try_normalize() else {
        return n;
    };
    let b = n.cross(tangent);
    let bitangent = if b.dot(dpdv) > 0.0 { -b } else { b };
    let m = (tangent * t.x + bitangent * t.y) * scale + n * t.z;
    m.try_normalize().unwrap_or(n)
}

/// The nearest `t > 0` where the ray `eye + t dir` (unit `dir`) meets the sphere.
fn sphere_hit(eye: DVec3, dir: DVec3, centre: DVec3, radius: f64) -> Option<f64> {
    let oc = eye - centre;
    let b = oc.dot(dir);
    let disc = b * b - (oc.length_squared() - radius * radius);
    if disc < 0.0 {
        return None;
    }
    let root = disc.sqrt();
    [-b - root, -b + root].into_iter().find(|&t| t > 0.0)
}

/// The probes' harmonics (`extras.penumbra_probes`) at `p`: trilinear over the eight probes
/// around it (clamped to the grid), the probes inside geometry left out and the weights of the
/// others renormalised. An error when the file has no probes.
fn probe_light_at(gltf: &Gltf, p: DVec3) -> Result<[DVec3; 9]> {
    let probes = &gltf.json["extras"]["penumbra_probes"];
    let bad = |reason: &str| Error::BadItem {
        path: gltf.path.clone(),
        item: "extras.penumbra_probes".into(),
        reason: reason.into(),
    };
    let num = |v: &serde_json::Value| v.as_f64().ok_or_else(|| bad("is not a probe grid"));
    let origin = DVec3::new(
        num(&probes["origin"][0])?,
        num(&probes["origin"][1])?,
        num(&probes["origin"][2])?,
    );
    let spacing = num(&probes["spacing"])?;
    let counts: Vec<usize> = (0..3)
        .map(|k| probes["counts"][k].as_u64().map(|c| c as usize))
        .collect::<Option<_>>()
        .filter(|c: &Vec<usize>| c.iter().all(|&c| c > 0))
        .ok_or_else(|| bad("has no counts"))?;
    let inside: std::collections::BTreeSet<u64> = probes["inside"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(|v| v.as_u64())
        .collect();
    let g = (p - origin) / spacing;
    let (mut sum, mut weights) = ([DVec3::ZERO; 9], 0.0);
    for corner in 0..8 {
        let mut index = 0;
        let mut w = 1.0;
        for (axis, stride) in [(0, 1), (1, counts[0]), (2, counts[0] * counts[1])] {
            let c = g[axis].clamp(0.0, (counts[axis] - 1) as f64);
            let lo = (c.floor() as usize).min(counts[axis] - 1);
            let f = c - lo as f64;
            let up = (corner >> axis) & 1 == 1;
            let k = if up {
                (lo + 1).min(counts[axis] - 1)
            } else {
                lo
            };
            w *= if up { f } else { 1.0 - f };
            index += k * stride;
        }
        if w <= 0.0 || inside.contains(&(index as u64)) {
            continue;
        }
        let c = &probes["sh"][index];
        for (k, s) in sum.iter_mut().enumerate() {
            *s += DVec3::new(num(&c[3 * k])?, num(&c[3 * k + 1])?, num(&c[3 * k + 2])?) * w;
        }
        weights += w;
    }
    if weights <= 0.0 {
        return Err(bad("has no probe outside geometry around the sphere"));
    }
    Ok(sum.map(|s| s / weights))
}

/// The exposure of [`render`]'s automatic mode: the 97th percentile of the luminance of what
/// was hit maps to 0.9.
pub(crate) fn auto_exposure(radiance: &[DVec3]) -> f64 {
    let mut lum: Vec<f64> = radiance
        .iter()
        .map(|c| crate::light::luminance(*c))
        .filter(|&v| v > 0.0)
        .collect();
    lum.sort_by(|a, b| a.total_cmp(b));
    lum.get(lum.len() * 97 / 100).copied().unwrap_or(1.0) / 0.9
}

/// Linear RGB divided by `scale`, clamped and sRGB-encoded to 8 bits.
pub(crate) fn tone_map(radiance: &[DVec3], width: u32, height: u32, scale: f64) -> image::RgbImage {
    let mut img = image::RgbImage::new(width, height);
    for (i, c) in radiance.iter().enumerate() {
        let v = (*c / scale)
            .to_array()
            .map(|x| (crate::color::linear_to_srgb(x.clamp(0.0, 1.0)) * 255.0).round() as u8);
        img.put_pixel(i as u32 % width, i as u32 / width, image::Rgb(v));
    }
    img
}

/// Bilinear sample of a float map (its first page) at normalized UV with clamp-to-edge, as the
/// output's sampler says.
pub(crate) fn sample_map(map: &Lightmap, uv: DVec2) -> DVec3 {
    sample_page(map, 0, uv)
}

/// [`sample_map`] on page `page` of a multi-page map (black when the map has no such page).
pub(crate) fn sample_page(map: &Lightmap, page: usize, uv: DVec2) -> DVec3 {
    let (w, h) = (map.width as usize, map.height as usize);
    if w == 0 || h == 0 || map.texels.len() < (page + 1) * w * h {
        return DVec3::ZERO;
    }
    let texel_uv = uv * DVec2::new(w as f64, h as f64);
    crate::lightmap::seams::Footprint::at(map.width, map.height, page, texel_uv).sample(&map.texels)
}
