//! The default element budget: from the lightmap's texels, the input's triangles and the
//! elements the geometry and its discontinuity lines take.

use crate::scene::Scene;

/// The default element budget is one element per this many lightmap texels the surfaces cover
/// (about an 8 x 8 texel square per two elements): a finer mesh than the lightmap can show
/// costs time for nothing.
pub(crate) const TEXELS_PER_ELEMENT: f64 = 32.0;

/// The default element budget is at least this many elements per input triangle, so that the
/// light has elements of its own beyond the geometry's.
pub(crate) const ELEMENTS_PER_TRIANGLE: f64 = 1.5;

/// The default element budget is at least this many elements per element of the coarsest
/// meshing of the geometry with every discontinuity line ([`mesh::lines_floor`]): as many again
/// for the light between the lines as the lines and the geometry take. Measured on a real
/// city (Florence, the RMSE against two 64-path references): at 1.5, 5.05% with 559 758
/// elements in 100 s; at 2, 3.96% with 878 172 in 128 s.
pub(crate) const ELEMENTS_PER_FLOOR_ELEMENT: f64 = 2.0;

/// How many times [`element_budget`] counts the geometry's floor, each time at the budget the
/// last count raised it to.
pub(crate) const FLOOR_PASSES: usize = 3;

/// Bounds of the default element budget (elements). The minimum is what a small closed room
/// needs: the shipped Cornell box measured 1.55% RMSE against the reference at 4 600 elements
/// (0.91% at 20 000, for about three times the solve). The maximum holds for the budget from the
/// texels and the triangles; the discontinuity lines may raise it further, to
/// [`LINES_BUDGET_MAX`].
pub(crate) const DEFAULT_BUDGET: std::ops::RangeInclusive<usize> = 5_000..=250_000;

/// The most elements the floor of the geometry and its discontinuity lines may raise the default
/// budget to: a real city's hard shadow lines, all kept, take more than [`DEFAULT_BUDGET`]
/// allows (Florence's 35 373 triangles: 522 071 elements).
pub(crate) const LINES_BUDGET_MAX: usize = 1_000_000;

/// The element budget of a bake, and what chose it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Budget {
    pub(crate) elements: usize,
    /// `--budget`, `lightmap texels`, `input triangles`, `geometry`, `minimum` or `maximum`.
    pub(crate) from: &'static str,
}

/// The element budget: `requested` (`--budget`) if given, else the largest of
///
/// * one element per [`TEXELS_PER_ELEMENT`] lightmap texels the surfaces cover at
///   `texels_per_unit` (the bake passes the atlas's first estimate of its density, so that the
///   mesh need not wait for the final packing: within a few percent of the final density),
/// * [`ELEMENTS_PER_TRIANGLE`] per input triangle,
/// * [`ELEMENTS_PER_FLOOR_ELEMENT`] per element that the geometry and its discontinuity lines take,
///   `geometry_floor(b)` (the bake passes [`mesh::lines_floor`]; called only for a default
///   budget) at `b`, the larger of the first two within [`DEFAULT_BUDGET`] and at least the
///   triangle count; counted again at the budget it raised to, up to [`FLOOR_PASSES`] times,
///   since the floor grows with the budget (closer lines crowd each other less). Thin boards
///   and walls with doors are refined for their angles (on a house interior more than 1.5
///   elements per input triangle), and a real city's ground holds thousands of lines: below
///   this the lines are dropped for the budget and the surfaces between them go unrefined,
///
/// within [`DEFAULT_BUDGET`] (the last up to [`LINES_BUDGET_MAX`]). Either way at least the
/// input's own triangle count: the mesh can
/// hardly have fewer elements than the geometry.
pub(crate) fn element_budget(
    scene: &Scene,
    requested: Option<usize>,
    texels_per_unit: f64,
    mut geometry_floor: impl FnMut(usize) -> usize,
) -> Budget {
    let triangles = scene.triangles.len();
    let within_to = |b: f64, from, most: usize| {
        let b = b.min(1e9) as usize;
        if b < *DEFAULT_BUDGET.start() {
            (*DEFAULT_BUDGET.start(), "minimum")
        } else if b > most {
            (most, "maximum")
        } else {
            (b, from)
        }
    };
    let within = |b: f64, from| within_to(b, from, *DEFAULT_BUDGET.end());
    let (elements, from) = match requested {
        Some(b) => (b, "--budget"),
        None => {
            let area: f64 = scene.polygons.iter().map(|p| p.area).sum();
            let texels = area * texels_per_unit * texels_per_unit / TEXELS_PER_ELEMENT;
            let per_triangle = triangles as f64 * ELEMENTS_PER_TRIANGLE;
            let (b, from) = within(
                texels.max(per_triangle),
                if texels >= per_triangle {
                    "lightmap texels"
                } else {
                    "input triangles"
                },
            );
            // The floor grows with the budget it is counted at (closer lines crowd each other
            // less), so it is counted again at the budget it raised to, a few times at most.
            let (mut at, mut chosen) = (b.max(triangles), (b, from));
            for _ in 0..FLOOR_PASSES {
                let count = geometry_floor(at);
                let geometry = count as f64 * ELEMENTS_PER_FLOOR_ELEMENT;
                if geometry <= chosen.0 as f64 {
                    break;
                }
                chosen = within_to(geometry, "geometry", LINES_BUDGET_MAX);
                if chosen.0 <= at {
                    break;
                }
                at = chosen.0;
            }
            chosen
        }
    };
    if elements < triangles {
        Budget {
            elements: triangles,
            from: "input triangles",
        }
    } else {
        Budget { elements, from }
    }
}
