//! Materials: a glTF material's albedo and emitted radiance, texture colours averaged over
//! their decoded images (within the image limits), out-of-range values refused or clamped.

use super::{Gltf, MAX_ALBEDO, MIB, limits, name_suffix, short};
use crate::color::srgb_to_linear;
use crate::error::Result;
use crate::scene::Material;
use glam::DVec3;
use std::collections::BTreeMap;

pub(super) fn material(
    gltf: &Gltf,
    m: &gltf::Material,
    textures: &mut TextureMeans,
) -> Result<Material> {
    let pbr = m.pbr_metallic_roughness();
    let base = pbr.base_color_factor();
    let mut rho = DVec3::new(base[0] as f64, base[1] as f64, base[2] as f64);
    if let Some(info) = pbr.base_color_texture() {
        rho *= textures.mean(gltf, &info.texture())?;
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
    if radiance.max_element() > 0.0
        && let Some(info) = m.emissive_texture()
    {
        radiance *= textures.mean(gltf, &info.texture())?;
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
    if clamped != rho {
        textures.warnings.push(format!(
            "material {name}: albedo {} is outside [0, {MAX_ALBEDO}], clamped to {} \
             (a surface that reflects all light it receives is not physical, and the bounces \
             would not converge)",
            short(rho),
            short(clamped)
        ));
    }
    Ok(Material {
        name,
        rho: clamped,
        radiance,
    })
}

/// Mean linear colour of each decoded texture image, cached by image index.
#[derive(Default)]
pub(super) struct TextureMeans {
    cache: BTreeMap<usize, DVec3>,
    pub(super) warnings: Vec<String>,
    /// Bytes of the images decoded so far, counted as [`Limits::image_bytes`](super::Limits::image_bytes) counts them.
    decoded: u64,
}

impl TextureMeans {
    fn mean(&mut self, gltf: &Gltf, texture: &gltf::Texture) -> Result<DVec3> {
        let image = texture.source();
        let index = image.index();
        if let Some(m) = self.cache.get(&index) {
            return Ok(*m);
        }
        let item = format!("image {index}{}", name_suffix(image.name()));
        let bytes = match image.source() {
            gltf::image::Source::View { view, .. } => gltf.view_bytes(&view, &item)?.to_vec(),
            gltf::image::Source::Uri { uri, .. } => gltf.uri_bytes(uri, &item)?,
        };
        let mean = match gltf.decode_image(&bytes, &item) {
            Ok(Ok(img)) => {
                self.decoded += limits::decoded_bytes(img.width(), img.height());
                let most = gltf
                    .options
                    .limits
                    .image_bytes
                    .saturating_mul(limits::IMAGES_TOGETHER);
                if self.decoded > most {
                    return Err(gltf.bad(
                        &item,
                        format!(
                            "the images decoded so far take more than {} MiB together, {} times \
                             the limit of one image (--max-image-mib raises it)",
                            most / MIB,
                            limits::IMAGES_TOGETHER
                        ),
                    ));
                }
                let rgb = img.to_rgb32f();
                let mut sum = DVec3::ZERO;
                for p in rgb.pixels() {
                    sum += DVec3::new(
                        srgb_to_linear(p[0] as f64),
                        srgb_to_linear(p[1] as f64),
                        srgb_to_linear(p[2] as f64),
                    );
                }
                let n = (rgb.width() as f64 * rgb.height() as f64).max(1.0);
                sum / n
            }
            Ok(Err(e)) => {
                self.warnings.push(format!(
                    "{item}: cannot decode ({e}); its mean colour is taken as white"
                ));
                DVec3::ONE
            }
            Err(e) => return Err(e),
        };
        self.cache.insert(index, mean);
        Ok(mean)
    }
}
