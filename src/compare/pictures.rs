//! The comparison's pictures: false-colour error maps and region maps over the lightmap grid,
//! wireframe close-ups of one shadow, and the side-by-side strip with captions (text in DejaVu
//! Sans, bundled by the `dejavu` crate, so PNGs draw the same on any machine); and
//! [`write_pictures`], which renders and writes them for one measured scene.

use super::runs::{Measured, nearest_budget};
use super::{CompareOptions, Method, Region, compare_error};
use crate::color::{linear_to_srgb, srgb_to_linear};
use crate::error::{Error, Result};
use crate::geometry::barycentric_2d;
use crate::lightmap::{self, Lightmap, Locator};
use crate::load::{self, Gltf};
use crate::mesh::Mesher;
use crate::mesh::ReceiverMesh;
use crate::reference::ReferenceMap;
use crate::render::{self, Camera, Shading};
use crate::scene::{Polygon, point_in_triangle};
use crate::solve::DirectMethod;
use glam::{DVec2, DVec3};
use image::RgbImage;
use plotters::prelude::*;

/// Registers the bundled font as plotters' "sans-serif" (once per process).
pub(crate) fn register_font() -> Result<()> {
    static DONE: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    let ok = *DONE.get_or_init(|| {
        plotters::style::register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular())
            .is_ok()
            && plotters::style::register_font("sans-serif", FontStyle::Bold, dejavu::sans::bold())
                .is_ok()
    });
    if ok {
        Ok(())
    } else {
        Err(Error::Image("cannot load the bundled font".into()))
    }
}

fn linear(rgb: [u8; 3]) -> DVec3 {
    DVec3::from(rgb.map(|c| srgb_to_linear(c as f64 / 255.0)))
}

/// Signed relative error of the false-colour maps at which the colour saturates.
pub(crate) const ERROR_RANGE: f64 = 0.25;

/// The diverging colour of a signed relative error: white at 0, red where the bake is too
/// bright, blue where it is too dark, saturated at ±[`ERROR_RANGE`]. Linear RGB.
pub(crate) fn error_colour(e: f64) -> DVec3 {
    let t = (e / ERROR_RANGE).clamp(-1.0, 1.0);
    let end = if t >= 0.0 {
        linear([178, 24, 43])
    } else {
        linear([33, 102, 172])
    };
    DVec3::ONE.lerp(end, t.abs())
}

/// The colour of each region in the region map and its legend (sRGB).
pub(crate) fn region_colour(r: Region) -> [u8; 3] {
    match r {
        Region::Lit => [250, 230, 160],
        Region::Penumbra => [240, 140, 40],
        Region::Umbra => [40, 50, 110],
        Region::Contact => [200, 40, 160],
        Region::Indirect => [150, 150, 150],
    }
}

/// Per texel the false colour of `(bake - reference) / scale` (channel means), dilated over the
/// whole image so bilinear lookups at chart edges stay in colour.
pub(crate) fn error_map(bake: &Lightmap, reference: &ReferenceMap, scale: f64) -> Lightmap {
    let texels = (0..reference.mean.len())
        .map(|i| {
            if reference.coverage[i] > 0.0 {
                let d = (bake.texels[i] - reference.mean[i]).element_sum() / 3.0;
                error_colour(d / scale)
            } else {
                DVec3::ZERO
            }
        })
        .collect();
    filled(reference, texels)
}

/// Per texel the colour of its region.
pub(crate) fn region_map(reference: &ReferenceMap, regions: &[Option<Region>]) -> Lightmap {
    let texels = regions
        .iter()
        .map(|r| r.map_or(DVec3::ZERO, |r| linear(region_colour(r))))
        .collect();
    filled(reference, texels)
}

/// The reference irradiance as a float lightmap, dilated like a baked one.
pub(crate) fn reference_lightmap(reference: &ReferenceMap) -> Lightmap {
    filled(reference, reference.mean.clone())
}

fn filled(reference: &ReferenceMap, texels: Vec<DVec3>) -> Lightmap {
    let mut map = Lightmap {
        width: reference.width,
        height: reference.height,
        texels,
        coverage: reference.coverage.clone(),
    };
    lightmap::dilate_into_padding(&mut map, u32::MAX);
    map
}

/// A square window of one polygon's plane, scene units.
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub(crate) struct Window {
    pub(crate) polygon: usize,
    pub(crate) min: [f64; 2],
    pub(crate) side: f64,
}

impl Window {
    /// The plane point at the centre of pixel `(x, y)` of an `s x s` image (row 0 on top).
    fn point(&self, x: u32, y: u32, s: u32) -> DVec2 {
        DVec2::new(
            self.min[0] + (x as f64 + 0.5) / s as f64 * self.side,
            self.min[1] + (1.0 - (y as f64 + 0.5) / s as f64) * self.side,
        )
    }

    fn pixel(&self, q: DVec2, s: u32) -> (i32, i32) {
        let u = (q.x - self.min[0]) / self.side * s as f64;
        let v = (1.0 - (q.y - self.min[1]) / self.side) * s as f64;
        (u.round() as i32, v.round() as i32)
    }
}

/// The window around the densest part of one shadow: on the polygon with the most penumbra
/// texels (umbra if there is no penumbra), a square of 40% of the polygon's larger side, placed
/// over as many of that polygon's penumbra texels as it can hold. `texels[i]` is texel `i`'s
/// polygon and plane point. `None` when nothing is shadowed.
pub(crate) fn shadow_window(
    polygons: &[Polygon],
    texels: &[Option<(usize, DVec2)>],
    regions: &[Option<Region>],
) -> Option<Window> {
    let pick = |want: Region| {
        let mut count = vec![0usize; polygons.len()];
        for (t, r) in texels.iter().zip(regions) {
            if let (Some((p, _)), Some(r)) = (t, r)
                && *r == want
            {
                count[*p] += 1;
            }
        }
        let best = (0..count.len()).max_by_key(|&p| (count[p], std::cmp::Reverse(p)))?;
        (count[best] > 0).then_some(best)
    };
    let (want, polygon) = pick(Region::Penumbra)
        .map(|p| (Region::Penumbra, p))
        .or_else(|| pick(Region::Umbra).map(|p| (Region::Umbra, p)))?;
    let points: Vec<DVec2> = texels
        .iter()
        .zip(regions)
        .filter_map(|(t, r)| match (t, r) {
            (Some((p, q)), Some(r)) if *p == polygon && *r == want => Some(*q),
            _ => None,
        })
        .collect();
    let poly = &polygons[polygon];
    let (mut lo, mut hi) = (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY));
    for t in &poly.triangles_plane {
        for v in t {
            lo = lo.min(*v);
            hi = hi.max(*v);
        }
    }
    let side = 0.4 * (hi - lo).max_element();
    let place = |c: DVec2| {
        DVec2::new(
            (c.x - side / 2.0).clamp(lo.x, (hi.x - side).max(lo.x)),
            (c.y - side / 2.0).clamp(lo.y, (hi.y - side).max(lo.y)),
        )
    };
    let step = (points.len() / 256).max(1);
    let inside = |m: DVec2| {
        points
            .iter()
            .filter(|q| q.x >= m.x && q.y >= m.y && q.x <= m.x + side && q.y <= m.y + side)
            .count()
    };
    let min = points
        .iter()
        .step_by(step)
        .map(|&c| place(c))
        .max_by_key(|&m| inside(m))?;
    Some(Window {
        polygon,
        min: min.to_array(),
        side,
    })
}

/// Greyscale of irradiance `h / white`, sRGB-encoded.
fn grey(h: DVec3, white: f64) -> [u8; 3] {
    let v = (h.element_sum() / 3.0 / white).clamp(0.0, 1.0);
    let g = (linear_to_srgb(v) * 255.0).round() as u8;
    [g, g, g]
}

const OUTSIDE: [u8; 3] = [235, 235, 240];

/// A close-up of `window` (`s x s` pixels) shaded by `value(q)` (irradiance at plane point q),
/// greyscale with `white` as full white; points outside the polygon are light grey.
pub(crate) fn closeup(
    polygon: &Polygon,
    window: &Window,
    s: u32,
    white: f64,
    value: &(dyn Fn(DVec2) -> DVec3 + Sync),
) -> RgbImage {
    use rayon::prelude::*;
    let pixels: Vec<[u8; 3]> = (0..s * s)
        .into_par_iter()
        .map(|i| {
            let q = window.point(i % s, i / s, s);
            if polygon.contains(q) {
                grey(value(q), white)
            } else {
                OUTSIDE
            }
        })
        .collect();
    let mut img = RgbImage::new(s, s);
    for (i, p) in pixels.into_iter().enumerate() {
        img.put_pixel(i as u32 % s, i as u32 / s, image::Rgb(p));
    }
    img
}

/// [`closeup`] of a receiver mesh's own interpolant, with its wireframe drawn over it: edges
/// dark and thin, discontinuity constraints orange.
pub(crate) fn mesh_closeup(
    polygon: &Polygon,
    window: &Window,
    s: u32,
    white: f64,
    mesh: &ReceiverMesh,
    values: &[DVec3],
) -> Result<RgbImage> {
    let loc = Locator::new(mesh, values);
    let mut img = closeup(polygon, window, s, white, &|q| loc.value(q));
    let mut edges: Vec<(u32, u32)> = mesh
        .triangles
        .iter()
        .flat_map(|t| [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])])
        .map(|(a, b)| (a.min(b), a.max(b)))
        .collect();
    edges.sort_unstable();
    edges.dedup();
    let mut constraints: Vec<(u32, u32)> = mesh
        .constraints
        .iter()
        .map(|c| (c.a.min(c.b), c.a.max(c.b)))
        .collect();
    constraints.sort_unstable();
    {
        let (w, h) = img.dimensions();
        let root = BitMapBackend::with_buffer(&mut img, (w, h)).into_drawing_area();
        let wire = RGBColor(20, 30, 60).mix(0.55).stroke_width(1);
        let cons = RGBColor(255, 120, 0).stroke_width(2);
        let px = |v: u32| window.pixel(mesh.vertices[v as usize], s);
        let far = |p: (i32, i32)| p.0.abs() > 4 * s as i32 || p.1.abs() > 4 * s as i32;
        for (a, b) in &edges {
            let (pa, pb) = (px(*a), px(*b));
            if far(pa) || far(pb) || constraints.binary_search(&(*a, *b)).is_ok() {
                continue;
            }
            root.draw(&PathElement::new(vec![pa, pb], wire))
                .map_err(|e| Error::Image(format!("wireframe: {e:?}")))?;
        }
        for (a, b) in &constraints {
            let (pa, pb) = (px(*a), px(*b));
            if far(pa) || far(pb) {
                continue;
            }
            root.draw(&PathElement::new(vec![pa, pb], cons))
                .map_err(|e| Error::Image(format!("wireframe: {e:?}")))?;
        }
        root.present()
            .map_err(|e| Error::Image(format!("wireframe: {e:?}")))?;
    }
    Ok(img)
}

/// Point location in a polygon's input triangles: the triangle (index into
/// `polygon.triangles`) containing plane point `q`, with its barycentrics.
pub(crate) fn locate(polygon: &Polygon, q: DVec2) -> Option<(usize, [f64; 3])> {
    polygon
        .triangles_plane
        .iter()
        .position(|t| point_in_triangle(q, t))
        .map(|k| (k, barycentric_2d(&polygon.triangles_plane[k], q)))
}

/// One column of the strip: a title, caption lines, and its cells top to bottom (all cells of a
/// row the same size).
pub(crate) struct Column {
    pub(crate) title: String,
    pub(crate) caption: Vec<String>,
    pub(crate) cells: Vec<RgbImage>,
}

const HEADER: u32 = 58;
const GAP: u32 = 6;

/// The columns side by side, each under its title and caption, with `footer` lines of
/// explanation below.
pub(crate) fn strip(columns: &[Column], footer: &[String]) -> Result<RgbImage> {
    register_font()?;
    let rows = columns.iter().map(|c| c.cells.len()).max().unwrap_or(0);
    let row_heights: Vec<u32> = (0..rows)
        .map(|r| {
            columns
                .iter()
                .filter_map(|c| c.cells.get(r).map(|i| i.height()))
                .max()
                .unwrap_or(0)
        })
        .collect();
    let col_width = columns
        .iter()
        .flat_map(|c| c.cells.iter().map(|i| i.width()))
        .max()
        .unwrap_or(200);
    let width = columns.len() as u32 * (col_width + GAP) + GAP;
    let body: u32 = row_heights.iter().map(|h| h + GAP).sum();
    let height = HEADER + body + GAP + 18 * footer.len() as u32 + 6;
    let mut img = RgbImage::from_pixel(width, height, image::Rgb([255, 255, 255]));
    for (c, col) in columns.iter().enumerate() {
        let x = GAP + c as u32 * (col_width + GAP);
        let mut y = HEADER;
        for (r, cell) in col.cells.iter().enumerate() {
            image::imageops::overlay(&mut img, cell, x as i64, y as i64);
            y += row_heights[r] + GAP;
        }
    }
    {
        let (w, h) = img.dimensions();
        let root = BitMapBackend::with_buffer(&mut img, (w, h)).into_drawing_area();
        let err = |e| Error::Image(format!("strip: {e:?}"));
        let title = ("sans-serif", 17, FontStyle::Bold)
            .into_font()
            .color(&BLACK);
        let small = ("sans-serif", 13).into_font().color(&RGBColor(40, 40, 40));
        for (c, col) in columns.iter().enumerate() {
            let x = (GAP + c as u32 * (col_width + GAP)) as i32;
            root.draw_text(&col.title, &title, (x, 4)).map_err(err)?;
            for (k, line) in col.caption.iter().enumerate() {
                root.draw_text(line, &small, (x, 24 + 16 * k as i32))
                    .map_err(err)?;
            }
        }
        let y0 = (HEADER + body + GAP) as i32;
        for (k, line) in footer.iter().enumerate() {
            root.draw_text(line, &small, (GAP as i32, y0 + 18 * k as i32))
                .map_err(err)?;
        }
        root.present().map_err(err)?;
    }
    Ok(img)
}

/// Encodes an RGB image as PNG.
pub(crate) fn png(img: &RgbImage) -> Result<Vec<u8>> {
    crate::write::png_bytes(img.as_raw(), img.width(), img.height())
}

/// Renders the reference and the picture-budget bakes, the false-colour and region maps, the
/// close-ups, and composes the strip. Returns the files written.
pub(super) fn write_pictures(
    m: &Measured,
    o: &CompareOptions,
    write: &dyn Fn(&str, &[u8]) -> Result<String>,
) -> Result<Vec<String>> {
    let mut files = Vec::new();
    let w = o.picture_width;
    let camera = Camera::from_gltf(&m.baked);
    let scale = m.report.mean_lit_irradiance;
    let ref_map = reference_lightmap(&m.reference);
    let radiance = render::render_radiance(&m.baked, camera, w, w, Shading::Irradiance(&ref_map))?;
    let exposure = render::auto_exposure(&radiance);
    let ref_view = render::tone_map(&radiance, w, w, exposure);
    let colour = |g: &Gltf, map: &Lightmap| -> Result<image::RgbImage> {
        let c = render::render_radiance(g, camera, w, w, Shading::Colour(map))?;
        Ok(render::tone_map(&c, w, w, 1.0))
    };
    let region_view = colour(&m.baked, &region_map(&m.reference, &m.regions))?;
    files.push(write("regions.png", &png(&region_view)?)?);
    let mut views = Vec::new();
    for (method, bake, path) in &m.pictures {
        let g = load::read(path)?;
        let view = render::render(&g, camera, w, w, Some(exposure))?;
        let error = colour(&g, &error_map(&bake.lightmap, &m.reference, scale))?;
        files.push(write(
            &format!("error-{}.png", method.name()),
            &png(&error)?,
        )?);
        views.push((*method, bake, view, error));
    }

    // The close-up: the reference through the atlas, each mesh through its own interpolant.
    let (_, first, _) = &m.pictures[0];
    let (scene, atlas) = (&first.scene, &first.atlas);
    let window = shadow_window(&scene.polygons, &m.texel_points, &m.regions);
    let ref_value = |polygon: usize, q: DVec2| -> DVec3 {
        let poly = &scene.polygons[polygon];
        let Some((k, l)) = locate(poly, q) else {
            return DVec3::ZERO;
        };
        let t = &scene.triangles[poly.triangles[k]];
        let am = &atlas.meshes[t.instance];
        let ids = &am.indices[3 * t.local_index..3 * t.local_index + 3];
        let uv: DVec2 = (0..3)
            .map(|c| DVec2::from(am.uv[ids[c] as usize].map(f64::from)) * l[c])
            .sum();
        let size = DVec2::new(atlas.width as f64, atlas.height as f64);
        render::sample_map(&ref_map, uv / size)
    };
    let closeups = match &window {
        Some(win) => {
            let poly = &scene.polygons[win.polygon];
            // White: the brightest reference value in the window.
            let mut white: f64 = 0.0;
            for i in 0..32 {
                for j in 0..32 {
                    let q = DVec2::new(
                        win.min[0] + (i as f64 + 0.5) / 32.0 * win.side,
                        win.min[1] + (j as f64 + 0.5) / 32.0 * win.side,
                    );
                    if poly.contains(q) {
                        white = white.max(ref_value(win.polygon, q).element_sum() / 3.0);
                    }
                }
            }
            let white = if white > 0.0 { white } else { 1.0 };
            let reference = closeup(poly, win, w, white, &|q| ref_value(win.polygon, q));
            let mut meshes = Vec::new();
            for (_, bake, _, _) in &views {
                let mi = bake
                    .meshes
                    .iter()
                    .position(|mesh| mesh.polygon == win.polygon)
                    .ok_or_else(|| compare_error("a bake lost a receiver mesh".into()))?;
                meshes.push(mesh_closeup(
                    poly,
                    win,
                    w,
                    white,
                    &bake.meshes[mi],
                    &bake.solution.irradiance[mi],
                )?);
            }
            Some((reference, meshes))
        }
        None => None,
    };

    // The strip: the reference, then one column per mesher (exact direct light if baked).
    let pct = |v: f64| format!("{:.1}%", 100.0 * v);
    let noise = m.report.runs.first().map_or(0.0, |r| r.error.noise);
    let mut columns = vec![Column {
        title: "reference".into(),
        caption: vec![
            format!(
                "path traced, {} spp, {:.0} s",
                m.report.reference_spp, m.report.reference_seconds
            ),
            format!("noise {} of lit mean", pct(noise)),
        ],
        cells: [Some(ref_view), Some(region_view)]
            .into_iter()
            .chain([closeups.as_ref().map(|c| c.0.clone())])
            .flatten()
            .collect(),
    }];
    let picture_budget = nearest_budget(&o.budgets, o.picture_budget);
    // One column per mesher (exact direct light, progressive, if baked), then one per other
    // solver or form factors.
    let mut shown: Vec<usize> = [Mesher::Uniform, Mesher::Adaptive, Mesher::Discontinuity]
        .iter()
        .filter_map(|&mesher| {
            let default = |v: &(Method, _, _, _)| v.0.mesher == mesher && v.0.is_default_solve();
            views
                .iter()
                .position(|v| default(v) && v.0.direct == DirectMethod::Exact)
                .or_else(|| views.iter().position(default))
        })
        .collect();
    shown.extend((0..views.len()).filter(|&k| !views[k].0.is_default_solve()));
    for k in shown {
        let (method, _, view, error) = &views[k];
        let Some(run) = m
            .report
            .runs
            .iter()
            .find(|r| r.method == method.name() && r.budget == picture_budget)
        else {
            continue;
        };
        let penumbra = run
            .regions
            .get(&Region::Penumbra)
            .map_or(String::new(), |e| format!(", penumbra {}", pct(e.rmse)));
        let mut title = if method.is_default_solve() {
            format!("{:?}", method.mesher).to_lowercase()
        } else {
            method.name()
        };
        if method.direct == DirectMethod::Sampled {
            title.push_str(" (sampled)");
        }
        columns.push(Column {
            title,
            caption: vec![
                format!("{} elements, {:.2} s", run.elements, run.seconds),
                format!("RMSE {}{penumbra}", pct(run.error.rmse)),
            ],
            cells: [Some(view.clone()), Some(error.clone())]
                .into_iter()
                .chain([closeups.as_ref().map(|c| c.1[k].clone())])
                .flatten()
                .collect(),
        });
    }
    let mut footer = vec![
        format!(
            "{}: every method at budget {picture_budget}, lightmap {}x{}; one exposure for every view; errors relative to the mean lit irradiance.",
            m.report.scene, m.report.lightmap_width, m.report.lightmap_height
        ),
        format!(
            "Row 2: bake minus reference (blue too dark, red too bright, saturating at +-{:.0}%); reference column: regions (lit yellow, penumbra orange, umbra blue, contact magenta).",
            100.0 * ERROR_RANGE
        ),
    ];
    if let Some(win) = &window {
        footer.push(format!(
            "Row 3: close-up ({:.3} units wide) of polygon {}: each mesh's own interpolant and wireframe (orange: discontinuity constraints); reference column: the reference.",
            win.side, win.polygon
        ));
    }
    let strip = strip(&columns, &footer)?;
    files.push(write("strip.png", &png(&strip)?)?);
    Ok(files)
}
