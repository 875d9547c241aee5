//! Materials: a glTF material's albedo and emitted radiance, out-of-range values refused or
//! clamped. A base-colour texture is decoded (within the image limits) and kept for lookups
//! ([`crate::scene::Base`]), with its `texCoord`, sampler and `KHR_texture_transform`; its mean
//! colour is the material's `rho` where one colour stands for the surface. An emissive texture
//! is kept the same way (emitters are split where it changes, [`crate::scene::emission`]); its
//! mean scales the material's radiance where one value stands for the surface.

use super::{Gltf, MIB, limits, name_suffix, short};
use crate::scene::MAX_ALBEDO;
use crate::color::srgb_to_linear;
use crate::error::Result;
use crate::scene::texture::{Image, TextureRef, Wrap};
use crate::scene::{Base, Material, Passes};
use glam::{DVec2, DVec3};
use std::collections::BTreeMap;

pub(super) fn material(
    gltf: &Gltf,
    m: &gltf::Material,
    textures: &mut Textures,
) -> Result<Material> {
    let pbr = m.pbr_metallic_roughness();
    let base = pbr.base_color_factor();
    let factor = DVec3::new(base[0] as f64, base[1] as f64, base[2] as f64);
    let mut rho = factor;
    let mut texture = None;
    if let Some(info) = pbr.base_color_texture() {
        let (mean, image) = textures.load(gltf, &info.texture(), true)?;
        rho *= mean;
        texture = image.map(|image| texture_ref(&info, image));
    }
    let strength = m.emissive_strength().unwrap_or(1.0);
    if !(strength.is_finite() && strength >= 0.0) {
        return Err(gltf.bad(
            format!(
                "materials[{}] KHR_materials_emissive_strength",
                m.index().unwrap_or(0)
            ),
            format!("emissiveStrength {strength} must be a finite number of at least 0"),
        ));
    }
    let mut radiance = DVec3::from_array(m.emissive_factor().map(|c| c as f64)) * strength as f64;
    let mut emission = None;
    if radiance.max_element() > 0.0
        && let Some(info) = m.emissive_texture()
    {
        let (mean, image) = textures.load(gltf, &info.texture(), true)?;
        emission = image.map(|image| (radiance, texture_ref(&info, image)));
        radiance *= mean;
    }
    let name = m
        .name()
        .map(str::to_string)
        .unwrap_or_else(|| format!("material {}", m.index().unwrap_or(0)));
    if pbr.metallic_factor() > 0.0 {
        textures.warnings.push(format!(
            "material {name}: metallicFactor {} is baked as a Lambertian surface of its base colour (a client shows metals with little or no diffuse light, so their lightmap barely shows)",
            pbr.metallic_factor()
        ));
    }
    if !rho.is_finite() || !radiance.is_finite() || radiance.min_element() < 0.0 {
        return Err(gltf.bad(
            format!("material {name}"),
            "colour factors are not finite, or the emission is negative",
        ));
    }
    let clamped = rho.clamp(DVec3::ZERO, DVec3::splat(MAX_ALBEDO));
    // Not for the rounding of an f32 factor (0.99 is read as 0.990000009).
    if (clamped - rho).abs().max_element() > 1e-6 {
        textures.warnings.push(format!(
            "material {name}: albedo {} is outside [0, {MAX_ALBEDO}], clamped to {} \
             (a surface that reflects all light it receives is not physical, and the bounces \
             would not converge)",
            short(rho),
            short(clamped)
        ));
    }
    let opacity = f64::from(base[3]);
    let cutoff = match m.alpha_mode() {
        gltf::material::AlphaMode::Mask => {
            let cutoff = f64::from(m.alpha_cutoff().unwrap_or(0.5));
            if texture.is_none() && opacity < cutoff {
                textures.warnings.push(format!(
                    "material {name}: alphaMode MASK with baseColorFactor alpha {opacity} under \
                     alphaCutoff {cutoff} and no texture: the surface is a hole everywhere (it \
                     neither casts shadows nor reflects light)"
                ));
            }
            Some(cutoff)
        }
        _ => None,
    };
    // What passes through: transmission wins over BLEND (glTF viewers draw such a surface as
    // transmissive). Its texture's red channel scales the factor.
    let extension = m
        .extensions()
        .and_then(|e| e.get("KHR_materials_transmission"));
    let transmission = extension
        .map(|t| {
            t["transmissionFactor"]
                .as_f64()
                .filter(|f| f.is_finite())
                .unwrap_or(0.0)
                .clamp(0.0, 1.0)
        })
        .filter(|&f| f > 0.0);
    let mut transmission_texture = None;
    if transmission.is_some()
        && let Some(info) = extension.map(|t| &t["transmissionTexture"])
        && !info.is_null()
    {
        let item = || format!("material {name}: KHR_materials_transmission transmissionTexture");
        let texture = info["index"]
            .as_u64()
            .and_then(|i| gltf.document.textures().nth(i as usize))
            .ok_or_else(|| gltf.bad(item(), "names no texture of the file"))?;
        let (_, image) = textures.load(gltf, &texture, true)?;
        let tex_coord = info["texCoord"].as_u64().unwrap_or(0);
        transmission_texture = image.map(|image| {
            texture_ref_of(
                &texture,
                image,
                tex_coord.min(u64::from(u32::MAX)) as u32,
                info.get("extensions")
                    .and_then(|e| e.get("KHR_texture_transform")),
            )
        });
    }
    let passes = match (transmission, m.alpha_mode()) {
        (Some(f), _) => Some(Passes::Transmission(f)),
        (None, gltf::material::AlphaMode::Blend) => Some(Passes::Blend),
        _ => None,
    };
    let varies = texture.is_some() || cutoff.is_some() || emission.is_some() || passes.is_some();
    let base = varies.then_some(Base {
        factor,
        opacity,
        texture,
        cutoff,
        emission,
        passes,
        transmission_texture,
    });
    Ok(Material {
        name,
        rho: clamped,
        radiance,
        base,
    })
}

/// How a material reads its base-colour texture: the image kept as scene image `image`, the
/// `texCoord` set, the sampler's wrap modes and the `KHR_texture_transform` (whose own
/// `texCoord` overrides the info's, as the extension says).
fn texture_ref(info: &gltf::texture::Info, image: usize) -> TextureRef {
    texture_ref_of(
        &info.texture(),
        image,
        info.tex_coord(),
        info.extensions()
            .and_then(|e| e.get("KHR_texture_transform")),
    )
}

/// [`texture_ref`] from a texture info's parts: the texture, its kept image, its `texCoord` and
/// its `KHR_texture_transform` object, if any (for texture infos inside extensions, which the
/// gltf crate leaves as JSON).
fn texture_ref_of(
    texture: &gltf::Texture,
    image: usize,
    tex_coord: u32,
    transform_json: Option<&serde_json::Value>,
) -> TextureRef {
    let sampler = texture.sampler();
    let mut tex_coord = tex_coord;
    let mut transform = TextureRef::IDENTITY;
    if let Some(t) = transform_json {
        let pair = |key: &str, default: f64| {
            let v = |i: usize| {
                t[key][i]
                    .as_f64()
                    .filter(|x| x.is_finite())
                    .unwrap_or(default)
            };
            DVec2::new(v(0), v(1))
        };
        let rotation = t["rotation"]
            .as_f64()
            .filter(|x| x.is_finite())
            .unwrap_or(0.0);
        transform = TextureRef::transform_of(pair("offset", 0.0), rotation, pair("scale", 1.0));
        if let Some(n) = t["texCoord"].as_u64() {
            tex_coord = n.min(u64::from(u32::MAX)) as u32;
        }
    }
    TextureRef {
        image,
        tex_coord,
        wrap: [
            Wrap::from_gl(sampler.wrap_s().as_gl_enum()),
            Wrap::from_gl(sampler.wrap_t().as_gl_enum()),
        ],
        transform,
    }
}

/// The decoded texture images: each one's mean linear colour, and the base-colour ones kept
/// for lookups (they become [`crate::scene::Scene::images`]).
#[derive(Default)]
pub(super) struct Textures {
    /// glTF image index to (mean colour, index into `kept` once kept).
    cache: BTreeMap<usize, (DVec3, Option<usize>)>,
    /// The images kept, in the order first needed.
    pub(super) kept: Vec<Image>,
    pub(super) warnings: Vec<String>,
    /// Bytes of the images decoded so far, counted as [`Limits::image_bytes`](super::Limits::image_bytes) counts them.
    decoded: u64,
}

impl Textures {
    /// The mean linear colour of `texture`'s image and, when `keep`, its index among the kept
    /// images (`None` when it cannot be decoded: a warning, and white).
    fn load(
        &mut self,
        gltf: &Gltf,
        texture: &gltf::Texture,
        keep: bool,
    ) -> Result<(DVec3, Option<usize>)> {
        let image = texture.source();
        let index = image.index();
        let item = format!("image {index}{}", name_suffix(image.name()));
        let cached = self.cache.get(&index).copied();
        let (mean, kept) = match cached {
            Some((mean, kept)) if kept.is_some() || !keep => return Ok((mean, kept)),
            _ => {
                let bytes = match image.source() {
                    gltf::image::Source::View { view, .. } => {
                        gltf.view_bytes(&view, &item)?.to_vec()
                    }
                    gltf::image::Source::Uri { uri, .. } => gltf.uri_bytes(uri, &item)?,
                };
                match gltf.decode_image(&bytes, &item) {
                    Ok(Ok(img)) => {
                        if cached.is_none() {
                            self.count(
                                gltf,
                                &item,
                                limits::decoded_bytes(img.width(), img.height()),
                            )?;
                        }
                        let rgba = img.to_rgba8();
                        let (w, h) = (rgba.width() as usize, rgba.height() as usize);
                        let texels: Vec<[u8; 4]> = rgba.pixels().map(|p| p.0).collect();
                        let mut sum = DVec3::ZERO;
                        for t in &texels {
                            sum += DVec3::new(
                                srgb_to_linear(f64::from(t[0]) / 255.0),
                                srgb_to_linear(f64::from(t[1]) / 255.0),
                                srgb_to_linear(f64::from(t[2]) / 255.0),
                            );
                        }
                        let mean = sum / (texels.len() as f64).max(1.0);
                        let kept = match Image::new(w, h, texels).filter(|_| keep) {
                            Some(img) => {
                                self.kept.push(img);
                                Some(self.kept.len() - 1)
                            }
                            None => None,
                        };
                        if keep && kept.is_none() {
                            self.warnings.push(format!(
                                "{item}: has no pixels; its colour is taken as white"
                            ));
                            (DVec3::ONE, None)
                        } else {
                            (mean, kept)
                        }
                    }
                    Ok(Err(e)) => {
                        self.warnings.push(format!(
                            "{item}: cannot decode ({e}); its colour is taken as white"
                        ));
                        (DVec3::ONE, None)
                    }
                    Err(e) => return Err(e),
                }
            }
        };
        self.cache.insert(index, (mean, kept));
        Ok((mean, kept))
    }

    /// Counts `bytes` more of decoded images against the limit on all of them together.
    fn count(&mut self, gltf: &Gltf, item: &str, bytes: u64) -> Result<()> {
        self.decoded += bytes;
        let most = gltf
            .options
            .limits
            .image_bytes
            .saturating_mul(limits::IMAGES_TOGETHER);
        if self.decoded > most {
            return Err(gltf.bad(
                item,
                format!(
                    "the images decoded so far take more than {} MiB together, {} times \
                     the limit of one image (--max-image-mib raises it)",
                    most / MIB,
                    limits::IMAGES_TOGETHER
                ),
            ));
        }
        Ok(())
    }
}
