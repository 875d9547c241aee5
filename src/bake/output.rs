//! The bake's output files: [`bake_file`] reads, bakes and writes them all or none, and
//! [`glb_bytes`] encodes a bake's lightmap, layers, ambient occlusion and probes into the glb.

use super::{Bake, BakeOptions, bake};
use crate::error::{Error, Result};
use crate::files::{self, Staged};
use crate::lightmap::{Encoding, Lightmap};
use crate::load::{self, Gltf};
use crate::progress::Progress;
use crate::stats::stage;
use crate::write::{self, LightmapImage};
use std::path::{Path, PathBuf};

/// Where [`bake_file`] writes: the lightmapped glb, and optionally the float lightmap and the
/// statistics.
#[derive(Clone, Debug, Default)]
pub struct OutputFiles {
    /// The lightmapped glb.
    pub glb: PathBuf,
    /// The float lightmap (irradiance H, W/m², linear RGB) as OpenEXR: page 0 here, page `p`
    /// >= 1 next to it as [`exr_page_path`] names it.
    pub exr: Option<PathBuf>,
    /// `--stats` JSON.
    pub stats: Option<PathBuf>,
}

impl OutputFiles {
    /// Just the glb.
    pub fn glb(path: impl Into<PathBuf>) -> OutputFiles {
        OutputFiles {
            glb: path.into(),
            ..OutputFiles::default()
        }
    }
}

/// Reads `input`, bakes, and writes the outputs. Every output is checked against the input
/// (and against the files a `.gltf` reads) before the bake starts, and all are written to
/// temporary files before any is renamed into place ([`files`]). Returns the bake with its
/// write timings filled in.
pub fn bake_file(
    input: &Path,
    outputs: &OutputFiles,
    options: &BakeOptions,
    progress: &Progress<'_>,
) -> Result<Bake> {
    let start = std::time::Instant::now();
    let mut read_time = 0.0;
    let gltf = stage(&mut read_time, "read", progress, || {
        load::read_with(input, &options.load)
    })?;
    let mut named: Vec<(&'static str, &Path)> = vec![("OUT", &outputs.glb)];
    if let Some(exr) = &outputs.exr {
        named.push(("--exr", exr));
    }
    if let Some(stats) = &outputs.stats {
        named.push(("--stats", stats));
    }
    // Resolved in the order named: the glb, then the EXR and the stats where asked for.
    let mut paths = files::check_outputs(&gltf.files_read(), &named)?.into_iter();
    let glb_path = paths.next();
    let exr_path = outputs.exr.as_ref().and_then(|_| paths.next());
    let stats_path = outputs.stats.as_ref().and_then(|_| paths.next());
    let mut result = bake(&gltf, options, progress)?;
    result.stats.timings_s.load += read_time;
    // The EXRs of pages 1.. are known only now: check them too, with all the others.
    let page_exrs: Vec<PathBuf> = match &outputs.exr {
        Some(exr) => (1..result.atlas.pages)
            .map(|p| exr_page_path(exr, p))
            .collect(),
        None => Vec::new(),
    };
    let page_paths = if page_exrs.is_empty() {
        Vec::new()
    } else {
        let mut all = named.clone();
        all.extend(page_exrs.iter().map(|p| ("--exr", p.as_path())));
        files::check_outputs(&gltf.files_read(), &all)?.split_off(named.len())
    };
    let mut write_time = 0.0;
    let mut staged = stage(&mut write_time, "write", progress, || -> Result<Staged> {
        let mut staged = Staged::new();
        if let Some(path) = &glb_path {
            staged.add(path, &glb_bytes(&gltf, &mut result, options.encoding)?)?;
        }
        if let Some(path) = &exr_path {
            let map = &result.lightmap;
            for (p, path) in std::iter::once(path).chain(&page_paths).enumerate() {
                staged.add(path, &write::exr_bytes(map.page(p), map.width, map.height)?)?;
            }
        }
        Ok(staged)
    })?;
    result.stats.timings_s.write = write_time;
    result.stats.timings_s.total = start.elapsed().as_secs_f64();
    if let Some(path) = &stats_path {
        let json = serde_json::to_vec_pretty(&result.stats).map_err(|e| Error::Write {
            path: path.clone(),
            source: e.into(),
        })?;
        staged.add(path, &json)?;
    }
    staged.commit()?;
    Ok(result)
}

/// Where `--exr FILE` puts page `page` (>= 1) of a multi-page lightmap: next to `FILE`, its
/// stem plus `-<page>`, same extension (`light.exr` → `light-1.exr`, `light-2.exr`, ...).
/// Page 0 is `FILE` itself.
pub(crate) fn exr_page_path(exr: &Path, page: u32) -> PathBuf {
    let stem = exr
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let name = match exr.extension() {
        Some(ext) => format!("{stem}-{page}.{}", ext.to_string_lossy()),
        None => format!("{stem}-{page}"),
    };
    exr.with_file_name(name)
}

/// A bake's result as lightmapped glb bytes (one 8-bit PNG per page in `encoding`, their scale
/// in `stats.lightmap_intensity`).
pub fn glb_bytes(gltf: &Gltf, bake: &mut Bake, encoding: Encoding) -> Result<Vec<u8>> {
    let (pngs, intensity) = page_pngs(&bake.lightmap, encoding)?;
    bake.stats.lightmap_intensity = intensity;
    let ao = match (&bake.ao, &bake.stats.ao) {
        (Some(map), Some(stats)) => Some(write::AoImage {
            pngs: grey_pngs(map)?,
            distance: stats.distance,
        }),
        _ => None,
    };
    let layers = bake
        .layers
        .iter()
        .map(|(name, map)| {
            let (pngs, intensity) = page_pngs(map, encoding)?;
            Ok(write::LayerImage {
                name: name.clone(),
                pngs,
                intensity,
            })
        })
        .collect::<Result<Vec<_>>>()?;
    let directional = match &bake.directional {
        Some([x, y, z]) => Some([ratio_pngs(x)?, ratio_pngs(y)?, ratio_pngs(z)?]),
        None => None,
    };
    let image = LightmapImage {
        pngs,
        intensity,
        encoding,
        ao,
        layers,
        probes: bake.probes.clone(),
        directional,
    };
    write::build(gltf, &bake.scene, &bake.atlas, &image)
}

/// One 8-bit RGB PNG per page of `map` in `encoding`, and their scale (W/m² of a full-scale
/// texel, [`Lightmap::to_rgb8`]).
fn page_pngs(map: &Lightmap, encoding: Encoding) -> Result<(Vec<Vec<u8>>, f64)> {
    let (rgb, intensity) = map.to_rgb8(encoding);
    let page_bytes = 3 * map.width as usize * map.height as usize;
    let pngs = rgb
        .chunks(page_bytes.max(1))
        .map(|page| write::png_bytes(page, map.width, map.height))
        .collect::<Result<Vec<_>>>()?;
    Ok((pngs, intensity))
}

/// One 8-bit RGB PNG per page of a directional lightmap's ratio map
/// ([`crate::lightmap::directional::to_rgb8`]).
fn ratio_pngs(map: &Lightmap) -> Result<Vec<Vec<u8>>> {
    let rgb = crate::lightmap::directional::to_rgb8(map);
    let page_bytes = 3 * map.width as usize * map.height as usize;
    rgb.chunks(page_bytes.max(1))
        .map(|page| write::png_bytes(page, map.width, map.height))
        .collect()
}

/// One linear 8-bit grey PNG per page of `map`, whose values are in 0..1 (the red channel's).
fn grey_pngs(map: &Lightmap) -> Result<Vec<Vec<u8>>> {
    let page = map.width as usize * map.height as usize;
    map.texels
        .chunks(page.max(1))
        .map(|texels| {
            let grey: Vec<u8> = texels
                .iter()
                .map(|t| (t.x.clamp(0.0, 1.0) * 255.0).round() as u8)
                .collect();
            write::grey_png_bytes(&grey, map.width, map.height)
        })
        .collect()
}
