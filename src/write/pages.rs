//! The lightmap's textures in the file: one per page, with its convention in `extras`, and
//! beside them the light groups' layers, the directional lightmap's pages and the ambient
//! occlusion, each page's named in its `MOZ_lightmap` (the AO's bound by the caller).

use super::{Bin, DIRECTIONAL_DECODE, LightmapImage, array_mut, push_png_texture};
use crate::atlas::Atlas;
use crate::error::{Error, Result};
use serde_json::{Value, json};

/// Adds the textures of `image` to `root` and `bin`; returns per page its `MOZ_lightmap`
/// object and (with AO) its `occlusionTexture` reference.
pub(super) fn textures(
    root: &mut Value,
    bin: &mut Bin,
    image: &LightmapImage,
    atlas: &Atlas,
) -> Result<(Vec<Value>, Vec<Value>)> {
    // 3. The lightmap textures, one per page, with their convention in `extras`.
    if image.pngs.len() != atlas.pages.max(1) as usize {
        return Err(Error::Image(format!(
            "{} lightmap images for {} atlas pages",
            image.pngs.len(),
            atlas.pages
        )));
    }
    let samplers = array_mut(root, "samplers");
    samplers.push(json!({"magFilter": 9729, "minFilter": 9987, "wrapS": 33071, "wrapT": 33071}));
    let sampler_index = samplers.len() - 1;
    let mut moz_of_page = Vec::new();
    for (page, png) in image.pngs.iter().enumerate() {
        let name = match page {
            0 => "penumbra lightmap".to_string(),
            p => format!("penumbra lightmap {p}"),
        };
        let extras = json!({"penumbra": {
            "quantity": "irradiance",
            "units": "W/m^2",
            "encoding": image.encoding.name(),
            "scale": image.intensity,
            "page": page,
        }});
        let texture_index = push_png_texture(root, bin, &name, png, sampler_index, extras);
        moz_of_page
            .push(json!({"index": texture_index, "texCoord": 1, "intensity": image.intensity}));
    }
    // The light groups' layers: one texture per group and page, named in the page's
    // `MOZ_lightmap.extras.penumbra.layers`.
    for layer in &image.layers {
        for (page, png) in layer.pngs.iter().enumerate() {
            let name = format!("penumbra lightmap layer {} {page}", layer.name);
            let extras = json!({"penumbra": {
                "quantity": "irradiance",
                "layer": layer.name,
                "units": "W/m^2",
                "encoding": image.encoding.name(),
                "scale": layer.intensity,
                "page": page,
            }});
            let texture = push_png_texture(root, bin, &name, png, sampler_index, extras);
            let entry = json!({
                "group": layer.name,
                "index": texture,
                "texCoord": 1,
                "intensity": layer.intensity,
            });
            if let Some(moz) = moz_of_page.get_mut(page) {
                let list = &mut moz["extras"]["penumbra"]["layers"];
                if !list.is_array() {
                    *list = json!([]);
                }
                if let Some(list) = list.as_array_mut() {
                    list.push(entry);
                }
            }
        }
    }
    // The directional lightmap (`--directional`): three textures per page, named in the page's
    // `MOZ_lightmap.extras.penumbra.directional`.
    if let Some(axes) = &image.directional {
        for (axis, pngs) in ["x", "y", "z"].iter().zip(axes) {
            for (page, png) in pngs.iter().enumerate() {
                let name = match page {
                    0 => format!("penumbra lightmap L1 {axis}"),
                    p => format!("penumbra lightmap L1 {axis} {p}"),
                };
                let extras = json!({"penumbra": {
                    "quantity": "irradiance L1 ratio",
                    "axis": axis,
                    "encoding": "linear",
                    "decode": DIRECTIONAL_DECODE,
                    "page": page,
                }});
                let texture = push_png_texture(root, bin, &name, png, sampler_index, extras);
                if let Some(moz) = moz_of_page.get_mut(page) {
                    moz["extras"]["penumbra"]["directional"][*axis] =
                        json!({"index": texture, "texCoord": 1});
                }
            }
        }
    }
    // The ambient occlusion (`--ao`): one texture per page, bound below as `occlusionTexture`.
    let mut ao_of_page = Vec::new();
    if let Some(ao) = &image.ao {
        for (page, png) in ao.pngs.iter().enumerate() {
            let name = match page {
                0 => "penumbra ambient occlusion".to_string(),
                p => format!("penumbra ambient occlusion {p}"),
            };
            let extras = json!({"penumbra": {
                "quantity": "ambient occlusion",
                "distance": ao.distance,
                "encoding": "linear",
                "page": page,
            }});
            let texture = push_png_texture(root, bin, &name, png, sampler_index, extras);
            ao_of_page.push(json!({"index": texture, "texCoord": 1}));
        }
    }
    Ok((moz_of_page, ao_of_page))
}
