//! The sweep's bakes: every [`Method`] at every budget into one lightmap layout, the reference
//! of that layout and each bake's error ([`measure`]); the matrix-against-progressive scaling
//! measure; the failure sweep's settings.

use super::metrics::{ErrorStats, classify, lightmap_error, mean_lit_irradiance};
use super::{CompareOptions, MIB, Region, Run, ScalingRow, SceneReport, compare_error};
use crate::error::{Error, Result};
use crate::lightmap::Lightmap;
use crate::load::{self, Gltf};
use crate::mesh::Mesher;
use crate::reference::{self, ReferenceMap, ReferenceOptions};
use crate::solve::{DirectMethod, FormFactors, Solver};
use crate::visibility::Visibility;
use crate::{Bake, BakeOptions};
use glam::DVec2;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// A way to bake: a mesher, a direct-light method, an indirect solver and its form factors.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct Method {
    pub mesher: Mesher,
    pub direct: DirectMethod,
    pub solver: Solver,
    pub form_factors: FormFactors,
    /// The hierarchical solver's `--hr-tolerance` as a multiple of its default (1: the
    /// default; the solver's speed/accuracy dial).
    pub hr_scale: u32,
}

impl Method {
    /// A mesher and direct-light method with the default solver (progressive, closed-form
    /// form factors).
    pub fn new(mesher: Mesher, direct: DirectMethod) -> Method {
        Method {
            mesher,
            direct,
            solver: Solver::Progressive,
            form_factors: FormFactors::ClosedForm,
            hr_scale: 1,
        }
    }

    /// `mesher-direct[-solver][-form factors]`, e.g. `discontinuity-exact`,
    /// `discontinuity-exact-matrix`; the solver is named unless progressive, the form factors
    /// unless closed-form. With hemicube form factors the direct-light method is left out
    /// (the hemicube carries the area emitters' light): `uniform-matrix-hemicube`. A
    /// hierarchical solve at `n` times the default tolerance ends in `-xn`:
    /// `discontinuity-exact-hierarchical-x10`.
    pub fn name(&self) -> String {
        let mut name = format!("{:?}", self.mesher).to_lowercase();
        if self.form_factors != FormFactors::Hemicube {
            name = format!("{name}-{:?}", self.direct).to_lowercase();
        }
        if self.solver != Solver::Progressive {
            name = format!("{name}-{}", self.solver.name());
        }
        if self.form_factors != FormFactors::ClosedForm {
            name = format!("{name}-{}", self.form_factors.name());
        }
        if self.hr_scale != 1 {
            name = format!("{name}-x{}", self.hr_scale);
        }
        name
    }

    /// Every mesher with exact and with sampled direct light (progressive, closed form).
    pub(crate) fn all() -> Vec<Method> {
        let meshers = [Mesher::Uniform, Mesher::Adaptive, Mesher::Discontinuity];
        meshers
            .iter()
            .flat_map(|&mesher| {
                [DirectMethod::Exact, DirectMethod::Sampled]
                    .map(|direct| Method::new(mesher, direct))
            })
            .collect()
    }

    /// The other solvers and form factors, on the discontinuity mesh (the same vertices as
    /// `discontinuity-exact`, so only the indirect solve differs): classic radiosity
    /// (`-matrix`), hierarchical radiosity at its default tolerance and at ten times it (its
    /// speed/accuracy dial), hemicube form factors with either patch solver; and the whole
    /// classic 1985 pipeline, `uniform-matrix-hemicube`.
    pub(crate) fn classic() -> Vec<Method> {
        let d = Method::new(Mesher::Discontinuity, DirectMethod::Exact);
        vec![
            Method {
                solver: Solver::Matrix,
                ..d
            },
            Method {
                solver: Solver::Hierarchical,
                ..d
            },
            Method {
                solver: Solver::Hierarchical,
                hr_scale: 10,
                ..d
            },
            Method {
                form_factors: FormFactors::Hemicube,
                ..d
            },
            Method {
                solver: Solver::Matrix,
                form_factors: FormFactors::Hemicube,
                ..d
            },
            Method {
                mesher: Mesher::Uniform,
                solver: Solver::Matrix,
                form_factors: FormFactors::Hemicube,
                ..d
            },
        ]
    }

    /// Every method `--methods` accepts: [`Method::all`], [`Method::classic`], and ray-cast
    /// form factors on the discontinuity mesh (`discontinuity-exact-raycast`, not in the
    /// default set: 16 rays per patch pair make it the slowest).
    pub fn known() -> Vec<Method> {
        let mut v = Method::all();
        v.extend(Method::classic());
        v.push(Method {
            form_factors: FormFactors::Raycast,
            ..Method::new(Mesher::Discontinuity, DirectMethod::Exact)
        });
        v
    }

    /// True for the default solver and form factors (progressive, closed form).
    pub(super) fn is_default_solve(&self) -> bool {
        self.solver == Solver::Progressive && self.form_factors == FormFactors::ClosedForm
    }

    /// Chart colour per mesher (sampled direct light is drawn dashed in the same colour); per
    /// solver and form factors for the others (dashed on the uniform mesh).
    pub(super) fn colour(&self) -> (u8, u8, u8) {
        match (self.solver, self.form_factors) {
            (Solver::Progressive, FormFactors::ClosedForm) => match self.mesher {
                Mesher::Uniform => (31, 119, 180),
                Mesher::Adaptive => (255, 127, 14),
                Mesher::Discontinuity => (44, 160, 44),
            },
            (Solver::Matrix, FormFactors::Hemicube) => (127, 127, 127),
            (Solver::Matrix, _) => (148, 103, 189),
            (Solver::Hierarchical, _) => (140, 86, 75),
            (_, FormFactors::Hemicube) => (227, 119, 194),
            (_, FormFactors::Raycast) => (188, 189, 34),
        }
    }

    pub(super) fn dashed(&self) -> bool {
        self.direct == DirectMethod::Sampled
            || self.hr_scale != 1
            || (!self.is_default_solve() && self.mesher == Mesher::Uniform)
    }
}

/// A scene's bakes, reference and regions, as [`measure`] leaves them for the pictures.
pub(super) struct Measured {
    pub(super) report: SceneReport,
    pub(super) reference: ReferenceMap,
    pub(super) regions: Vec<Option<Region>>,
    /// The bakes at the picture budget with the glb each was written to.
    pub(super) pictures: Vec<(Method, Bake, PathBuf)>,
    /// Per texel, the polygon and plane point of its first covered sub-sample.
    pub(super) texel_points: Vec<Option<(usize, DVec2)>>,
    /// The baked glb the reference read its layout from.
    pub(super) baked: Gltf,
}

pub(super) fn nearest_budget(budgets: &[usize], want: usize) -> usize {
    budgets
        .iter()
        .copied()
        .min_by_key(|&b| (b.abs_diff(want), b))
        .unwrap_or(want)
}

/// Bakes `gltf` with every method at every budget, writes the picture-budget bakes into
/// `bakes_dir`, computes the reference of their (shared) layout and every bake's error.
pub(super) fn measure(
    gltf: &Gltf,
    name: &str,
    description: &str,
    o: &CompareOptions,
    bakes_dir: &Path,
    log: &dyn Fn(&str),
) -> Result<Measured> {
    let picture_budget = nearest_budget(&o.budgets, o.picture_budget);
    let mut atlas: Option<crate::atlas::Atlas> = None;
    let mut runs: Vec<(Run, Lightmap)> = Vec::new();
    let mut pictures = Vec::new();
    for &method in &o.methods {
        for &budget in &o.budgets {
            let mut options = BakeOptions {
                mesher: method.mesher,
                budget: Some(budget),
                resolution: Some(o.resolution),
                supersample: o.supersample,
                ..BakeOptions::default()
            };
            options.solve.direct = method.direct;
            options.solve.solver = method.solver;
            options.solve.form_factors = method.form_factors;
            options.solve.hr_tolerance *= f64::from(method.hr_scale);
            let start = Instant::now();
            let mut b = match crate::bake(gltf, &options, &|_, _, _| {}) {
                // Classic radiosity only on scenes small enough for its matrix.
                Err(Error::BadItem { item, reason, .. }) if item == "--solver matrix" => {
                    log(&format!("{name}: {} skipped: {reason}", method.name()));
                    break;
                }
                other => other?,
            };
            let total_seconds = start.elapsed().as_secs_f64();
            match &atlas {
                None => atlas = Some(b.atlas.clone()),
                Some(a) if *a != b.atlas => {
                    return Err(compare_error(format!(
                        "{name}: the {} bake at budget {budget} has another lightmap layout than \
                         the first bake, so their texels cannot be compared",
                        method.name()
                    )));
                }
                Some(_) => {}
            }
            let t = &b.stats.timings_s;
            let s = &b.stats.solve;
            let run = Run {
                method: method.name(),
                mesher: method.mesher,
                direct: method.direct,
                solver: method.solver,
                form_factors: method.form_factors,
                hr_scale: method.hr_scale,
                budget,
                elements: b.stats.elements,
                patches: s.patches,
                indirect_seconds: s.indirect_seconds,
                matrix_bytes: s.matrix.as_ref().map(|m| m.bytes),
                hemicubes: s.hemicube.as_ref().map(|h| h.hemicubes),
                seconds: t.discontinuity + t.mesh + t.solve + t.lightmap,
                total_seconds,
                error: ErrorStats::default(),
                regions: BTreeMap::new(),
            };
            log(&format!(
                "{name}: {} budget {budget}: {} elements, {:.2} s",
                run.method, run.elements, run.seconds
            ));
            let lightmap = if budget == picture_budget {
                let path = bakes_dir.join(format!("{}.glb", method.name()));
                crate::files::write_atomically(
                    &path,
                    &crate::bake::glb_bytes(gltf, &mut b, options.encoding)?,
                )?;
                let lightmap = b.lightmap.clone();
                pictures.push((method, b, path));
                lightmap
            } else {
                b.lightmap
            };
            runs.push((run, lightmap));
        }
    }
    let (Some(atlas), Some((_, first, path))) = (atlas, pictures.first()) else {
        return Err(compare_error("no methods or no budgets to compare".into()));
    };

    // The reference reads the layout from a baked file, as `penumbra reference` does.
    let baked = load::read(path)?;
    let scene = load::scene(&baked)?;
    if scene.polygons.len() != first.scene.polygons.len()
        || scene
            .polygons
            .iter()
            .zip(&first.scene.polygons)
            .any(|(a, b)| a.triangles != b.triangles || a.material != b.material)
    {
        return Err(compare_error(format!(
            "{}: its polygons differ from the input's, so texels cannot be located",
            path.display()
        )));
    }
    let vis = Visibility::new(&scene);
    let layout = reference::texel_layout(&baked, &scene, &vis, o.supersample)?;
    if (layout.width, layout.height) != (atlas.width, atlas.height * atlas.pages) {
        return Err(compare_error(format!(
            "{}: its lightmap is {}x{}, the bake's {}x{}",
            path.display(),
            layout.width,
            layout.height,
            atlas.width,
            atlas.height
        )));
    }
    log(&format!(
        "{name}: reference, {} spp over {}x{} texels",
        o.spp, layout.width, layout.height
    ));
    let start = Instant::now();
    let ref_options = ReferenceOptions {
        spp: o.spp,
        seed: o.seed,
        bounces_max: None,
        supersample: o.supersample,
        // The bakes of the sweep have no sky.
        sky: glam::DVec3::ZERO,
    };
    let refmap = reference::reference_with(&scene, &vis, &layout, &ref_options);
    let reference_seconds = start.elapsed().as_secs_f64();
    let regions = classify(&refmap, o.contact_texels / atlas.texels_per_unit as f64);
    let scale = mean_lit_irradiance(&refmap, &regions);
    if scale.is_nan() || scale <= 0.0 {
        return Err(compare_error(format!(
            "{name}: the reference is black (no light reaches the lightmapped surfaces): \
             there is nothing to compare"
        )));
    }
    for (run, lightmap) in &mut runs {
        (run.error, run.regions) = lightmap_error(lightmap, &refmap, &regions, scale);
    }
    let mut region_texels = BTreeMap::new();
    for r in regions.iter().flatten() {
        *region_texels.entry(*r).or_insert(0) += 1;
    }
    let texel_points = layout
        .samples
        .iter()
        .map(|s| {
            s.first().map(|sp| {
                let frame = &scene.polygons[sp.polygon].frame;
                (sp.polygon, frame.plane_from_world(sp.p))
            })
        })
        .collect();
    let report = SceneReport {
        scene: name.to_string(),
        description: description.to_string(),
        lightmap_width: atlas.width,
        lightmap_height: atlas.height,
        texels_per_unit: atlas.texels_per_unit,
        covered_texels: regions.iter().flatten().count(),
        region_texels,
        mean_lit_irradiance: scale,
        reference_spp: o.spp,
        reference_seconds,
        reference_mean_relative_std_error: refmap.summary().mean_relative_std_error,
        runs: runs.into_iter().map(|(r, _)| r).collect(),
        scaling: Vec::new(),
    };
    Ok(Measured {
        report,
        reference: refmap,
        regions,
        pictures,
        texel_points,
        baked,
    })
}

/// Classic radiosity against progressive refinement as the patches grow: the patch solve alone
/// (closed-form form factors, to convergence), on the uniform mesh at a 250-element budget so
/// the rest of the bake stays small. Patch counts whose matrix exceeds `limit_mib` are left out.
pub(super) fn scaling(
    gltf: &Gltf,
    counts: &[usize],
    limit_mib: u64,
    log: &dyn Fn(&str),
) -> Result<Vec<ScalingRow>> {
    let mut rows = Vec::new();
    for &n in counts {
        if crate::solve::matrix::check_memory(n, limit_mib).is_err() {
            continue;
        }
        let mut o = BakeOptions {
            mesher: Mesher::Uniform,
            budget: Some(250),
            resolution: Some(64),
            supersample: 1,
            ..BakeOptions::default()
        };
        o.solve.patches = n;
        o.solve.solver = Solver::Matrix;
        let matrix = crate::bake(gltf, &o, &|_, _, _| {})?;
        o.solve.solver = Solver::Progressive;
        let progressive = crate::bake(gltf, &o, &|_, _, _| {})?;
        let Some(m) = matrix.stats.solve.matrix.clone() else {
            continue;
        };
        let row = ScalingRow {
            patches: m.patches,
            matrix_bytes: m.bytes,
            matrix_fill_seconds: m.form_factor_seconds,
            matrix_solve_seconds: m.solve_seconds,
            matrix_sweeps: m.sweeps,
            progressive_seconds: progressive.stats.solve.patch_solve_seconds,
            progressive_shots: progressive.stats.solve.shots,
        };
        log(&format!(
            "scaling: {} patches: matrix {:.1} MiB, {:.2} s fill + {:.3} s solve; progressive {:.2} s, {} shots",
            row.patches,
            row.matrix_bytes as f64 / MIB,
            row.matrix_fill_seconds,
            row.matrix_solve_seconds,
            row.progressive_seconds,
            row.progressive_shots
        ));
        rows.push(row);
    }
    Ok(rows)
}

/// The failure sweep's settings: smaller lightmaps, fewer paths, exact direct light only.
pub(super) fn failure_options(o: &CompareOptions) -> CompareOptions {
    // Exact direct light; of the other solvers only the hemicube's, which has scenes of its own
    // here.
    let mut methods: Vec<Method> = o
        .methods
        .iter()
        .copied()
        .filter(|m| m.direct == DirectMethod::Exact)
        .filter(|m| m.is_default_solve() || m.form_factors == FormFactors::Hemicube)
        .collect();
    if methods.is_empty() {
        methods = o.methods.clone();
    }
    CompareOptions {
        budgets: vec![500, 2000, 8000],
        methods,
        resolution: (o.resolution / 2).max(64),
        spp: (o.spp / 2).max(64),
        ..o.clone()
    }
}
