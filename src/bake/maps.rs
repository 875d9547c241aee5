//! The stages after the solve: the solution rasterized into the atlas (the lightmap, its light
//! groups' layers, the directional ratio pages, ambient occlusion) and the light probes.

use super::BakeOptions;
use crate::error::{Error, Result};
use crate::lightmap::{self, Lightmap};
use crate::progress::Progress;
use crate::solve::{self, Solution};
use crate::stats::{ProbeStats, Stats, stage};
use glam::DVec3;

/// The maps a bake writes, in the atlas's layout.
pub(super) struct Maps {
    pub lightmap: Lightmap,
    pub layers: Vec<(String, Lightmap)>,
    pub directional: Option<[Lightmap; 3]>,
    pub ao: Option<Lightmap>,
}

/// Rasterizes the solution into the atlas: the lightmap (its seams stitched or measured into
/// `stats.seams`), one layer per light group, the directional ratio pages where the solve kept
/// the light's direction, and ambient occlusion with `--ao`. Their times add up in
/// `stats.timings_s.lightmap`.
pub(super) fn rasterize(
    raster: &lightmap::Raster,
    solution: &Solution,
    options: &BakeOptions,
    stats: &mut Stats,
    progress: &Progress<'_>,
) -> Maps {
    let t = &mut stats.timings_s.lightmap;
    let (lightmap, seams) = stage(t, "lightmap", progress, || {
        lightmap_stage(raster, &solution.irradiance, &solution.texel_lights)
    });
    stats.seams = seams;
    let t = &mut stats.timings_s.lightmap;
    let layers = stage(t, "light groups", progress, || {
        solution
            .layers
            .iter()
            .zip(&solution.layer_texel_lights)
            .map(|((name, values), texel_lights)| {
                let (map, _) = lightmap_stage(raster, values, texel_lights);
                (name.clone(), map)
            })
            .collect()
    });
    let directional = (!solution.light.is_empty()).then(|| {
        stage(t, "directional", progress, || {
            lightmap::directional::ratio_maps(raster, &solution.light, &solution.irradiance)
        })
    });
    let ao = options.ao.map(|ao| {
        let (map, ao_stats) = stage(t, "ambient occlusion", progress, || {
            lightmap::ao::ambient_occlusion(raster, &ao)
        });
        stats.ao = Some(ao_stats);
        map
    });
    Maps {
        lightmap,
        layers,
        directional,
        ao,
    }
}

/// The lightmap stage: the meshes' irradiance rasterized into the atlas, the seams stitched
/// (or only measured, with `--seams off`).
fn lightmap_stage(
    raster: &lightmap::Raster,
    irradiance: &[Vec<DVec3>],
    texel_lights: &solve::texel_lights::TexelLights,
) -> (Lightmap, lightmap::seams::SeamStats) {
    let mut map = lightmap::rasterize(raster, irradiance, texel_lights);
    let seams = raster.stitch_seams(&mut map);
    (map, seams)
}

/// The light probes (`--probes`), their counts and time in `stats.probes`; `None` without
/// `--probes`.
pub(super) fn probes(
    raster: &lightmap::Raster,
    solution: &Solution,
    options: &BakeOptions,
    stats: &mut Stats,
    progress: &Progress<'_>,
) -> Result<Option<crate::probes::Probes>> {
    let Some(p) = &options.probes else {
        return Ok(None);
    };
    let start = std::time::Instant::now();
    progress("probes", 0, 1);
    let (scene, vis, meshes) = (raster.scene, raster.vis, raster.meshes);
    let probes = crate::probes::bake(scene, vis, meshes, &solution.irradiance, &options.solve, p)
        .map_err(|reason| Error::Option {
            option: "--probes",
            reason,
        })?;
    progress("probes", 1, 1);
    stats.probes = Some(ProbeStats {
        probes: probes.inside.len(),
        inside: probes.inside.iter().filter(|&&i| i).count(),
        seconds: start.elapsed().as_secs_f64(),
    });
    Ok(Some(probes))
}
