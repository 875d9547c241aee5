//! Light probes (`--probes SPACING`): the irradiance at points of a regular grid over the
//! scene's bounds (at the centres of cells of side `SPACING`, the grid centred on the bounds), for the moving objects that a lightmap cannot light (characters, doors).
//!
//! Per probe at `p`, the irradiance `E(n)` (W/m²) of a surface there facing `n`, in two forms:
//!
//! * **An ambient cube** (Valve's; what Bevy's irradiance volumes hold): `E` for the six axis
//!   directions `±x, ±y, ±z`.
//! * **Second-order spherical harmonics** of the radiance arriving at `p`, nine RGB coefficients
//!   in three.js's `SphericalHarmonics3` order and normalisation, from which a client evaluates
//!   `E(n) = Σ_l Â_l Σ_m c_lm Y_lm(n)` with `Â = (π, 2π/3, π/4)` (Ramamoorthi, Hanrahan, "An
//!   efficient representation for irradiance environment maps", SIGGRAPH 2001): exactly what
//!   three.js's `LightProbe` does. Nine coefficients smooth the light: under a small bright
//!   source `E` facing it is overestimated by up to 6% and facing away it is not quite 0.
//!
//! The light has two parts:
//!
//! * **Direct**, from the emitters, punctual lights and the sky, exactly as at the mesh
//!   vertices ([`crate::solve::Direct`]: the visible part of each emitter by backprojection) for
//!   the six axis directions and twenty more (the cube's edges and corners); the harmonics of
//!   the direct part are the least-squares fit of their irradiance coefficients to those 26.
//! * **Indirect**, by `rays` uniformly distributed rays (a Hammersley set on the sphere, rotated
//!   per probe): each that meets the front of a surface brings its reflected radiance
//!   `rho H / pi`, `H` the solved irradiance there (the lightmap's own interpolation over the
//!   receiver mesh). Emitters' own emission and the sky are direct light, not counted again.
//!
//! A probe whose rays meet the back of a surface more often than not is inside geometry: it is
//! flagged, and takes the mean of its neighbours outside (ring by ring, as the lightmap's
//! padding is dilated), so that a client interpolating between probes near a wall does not
//! blend in the dark inside it.

use crate::light::{NO_POLYGON, SurfacePoint, radical_inverse2};
use crate::mesh::ReceiverMesh;
use crate::rng::{mix64, unit_f64};
use crate::scene::Scene;
use crate::solve::reflected::{Reflected, Seen};
use crate::solve::{Direct, SolveOptions};
use crate::visibility::Visibility;
use glam::DVec3;
use rayon::prelude::*;
use std::f64::consts::PI;

/// What `--probes` asks for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProbeOptions {
    /// Distance between neighbouring probes, scene units.
    pub spacing: f64,
    /// Rays per probe for the indirect light (`--probe-rays`).
    pub rays: usize,
}

/// Default of `--probe-rays`.
pub const DEFAULT_RAYS: usize = 4096;

/// The most probes a bake makes.
pub(crate) const MAX_PROBES: usize = 1_000_000;

/// The probe grid: `counts[0] x counts[1] x counts[2]` probes at `origin + spacing (i, j, k)`,
/// numbered with x fastest, then y, then z.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Probes {
    pub origin: DVec3,
    pub spacing: f64,
    pub counts: [usize; 3],
    /// Per probe, the irradiance facing `+x, -x, +y, -y, +z, -z`, W/m².
    pub cube: Vec<[DVec3; 6]>,
    /// Per probe, the radiance's spherical-harmonic coefficients (three.js order), W/(m² sr).
    pub sh: Vec<[DVec3; 9]>,
    /// Per probe, true when it lies inside geometry.
    pub inside: Vec<bool>,
}

/// The six axis directions of the ambient cube, in [`Probes::cube`]'s order.
pub const AXES: [DVec3; 6] = [
    DVec3::X,
    DVec3::NEG_X,
    DVec3::Y,
    DVec3::NEG_Y,
    DVec3::Z,
    DVec3::NEG_Z,
];

/// The nine real spherical harmonics of unit direction `d`, three.js's `SphericalHarmonics3`
/// basis (`getBasisAt`).
pub(crate) fn sh_basis(d: DVec3) -> [f64; 9] {
    let (x, y, z) = (d.x, d.y, d.z);
    [
        0.282095,
        0.488603 * y,
        0.488603 * z,
        0.488603 * x,
        1.092548 * x * y,
        1.092548 * y * z,
        0.315392 * (3.0 * z * z - 1.0),
        1.092548 * x * z,
        0.546274 * (x * x - y * y),
    ]
}

/// The cosine lobe's factor per coefficient (`Â_l`: π, 2π/3, π/4 for bands 0, 1, 2).
const LOBE: [f64; 9] = [
    PI,
    2.0 * PI / 3.0,
    2.0 * PI / 3.0,
    2.0 * PI / 3.0,
    PI / 4.0,
    PI / 4.0,
    PI / 4.0,
    PI / 4.0,
    PI / 4.0,
];

/// The irradiance (W/m²) facing unit `n` from radiance coefficients `sh`, as three.js's
/// `shGetIrradianceAt` computes it.
pub fn sh_irradiance(sh: &[DVec3; 9], n: DVec3) -> DVec3 {
    let y = sh_basis(n);
    (0..9).map(|i| sh[i] * (LOBE[i] * y[i])).sum()
}

/// The grid of probes of `scene` at `spacing` (scene units): its first probe and its counts
/// along x, y and z; an error, which names the counts, when it has more than [`MAX_PROBES`].
pub(crate) fn grid(scene: &Scene, spacing: f64) -> Result<(DVec3, [usize; 3]), String> {
    let extent = scene.bounds_max - scene.bounds_min;
    let s = spacing;
    // Cells of side `s` over the bounds, a probe at each cell's centre (none on the bounds,
    // where the outer surfaces lie).
    let count = |e: f64| ((e / s).ceil() as usize).max(1);
    let counts = [count(extent.x), count(extent.y), count(extent.z)];
    counts
        .iter()
        .try_fold(1usize, |a, &c| a.checked_mul(c))
        .filter(|&n| n <= MAX_PROBES)
        .ok_or_else(|| {
            format!(
                "a probe spacing of {s} gives {} x {} x {} probes over the scene's bounds (at \
                 most {MAX_PROBES}): raise it",
                counts[0], counts[1], counts[2]
            )
        })?;
    // The grid centred on the bounds.
    let used = DVec3::new(
        (counts[0] - 1) as f64,
        (counts[1] - 1) as f64,
        (counts[2] - 1) as f64,
    ) * s;
    Ok((scene.bounds_min + (extent - used) * 0.5, counts))
}

/// Bakes the probes of `scene` from its solved `meshes` (`irradiance` at their vertices) on a
/// grid of `options.spacing`; an error when the grid would have more than [`MAX_PROBES`].
pub(crate) fn bake(
    scene: &Scene,
    vis: &Visibility,
    meshes: &[ReceiverMesh],
    irradiance: &[Vec<DVec3>],
    solve: &SolveOptions,
    options: &ProbeOptions,
) -> Result<Probes, String> {
    let (origin, counts) = grid(scene, options.spacing)?;
    let (s, total) = (options.spacing, counts.iter().product::<usize>());
    let baker = ProbeBaker::new(scene, vis, meshes, irradiance, solve, options.rays);
    let at = |i: usize| {
        let (x, y, z) = (
            i % counts[0],
            i / counts[0] % counts[1],
            i / (counts[0] * counts[1]),
        );
        origin + DVec3::new(x as f64, y as f64, z as f64) * s
    };
    let mut probes: Vec<Probe> = (0..total)
        .into_par_iter()
        .map(|i| baker.probe(at(i), i as u64))
        .collect();
    fill_inside(&mut probes, counts);
    Ok(Probes {
        origin,
        spacing: s,
        counts,
        cube: probes.iter().map(|p| p.cube).collect(),
        sh: probes.iter().map(|p| p.sh).collect(),
        inside: probes.iter().map(|p| p.inside).collect(),
    })
}

/// Gives each probe inside geometry the mean of its neighbours (the 26 around it) that are not,
/// ring by ring outward, so that a client interpolating between probes near a wall does not
/// blend in the dark inside it; a probe with no such neighbour after as many rings as the grid
/// is wide keeps what it saw. The `inside` flags stay.
fn fill_inside(probes: &mut [Probe], counts: [usize; 3]) {
    let mut filled: Vec<bool> = probes.iter().map(|p| !p.inside).collect();
    if filled.iter().all(|&f| f) || !filled.iter().any(|&f| f) {
        return;
    }
    let index = |x: usize, y: usize, z: usize| x + counts[0] * (y + counts[1] * z);
    for _ in 0..counts.iter().copied().max().unwrap_or(1) {
        let mut next = Vec::new();
        for z in 0..counts[2] {
            for y in 0..counts[1] {
                for x in 0..counts[0] {
                    let i = index(x, y, z);
                    if filled[i] {
                        continue;
                    }
                    let (mut cube, mut sh, mut n) = ([DVec3::ZERO; 6], [DVec3::ZERO; 9], 0.0);
                    for dz in -1i64..=1 {
                        for dy in -1i64..=1 {
                            for dx in -1i64..=1 {
                                let (nx, ny, nz) = (x as i64 + dx, y as i64 + dy, z as i64 + dz);
                                let inside_grid = (0..counts[0] as i64).contains(&nx)
                                    && (0..counts[1] as i64).contains(&ny)
                                    && (0..counts[2] as i64).contains(&nz);
                                if !inside_grid {
                                    continue;
                                }
                                let j = index(nx as usize, ny as usize, nz as usize);
                                if j != i && filled[j] {
                                    let p = &probes[j];
                                    cube.iter_mut().zip(&p.cube).for_each(|(a, b)| *a += *b);
                                    sh.iter_mut().zip(&p.sh).for_each(|(a, b)| *a += *b);
                                    n += 1.0;
                                }
                            }
                        }
                    }
                    if n > 0.0 {
                        next.push((i, cube.map(|c| c / n), sh.map(|c| c / n)));
                    }
                }
            }
        }
        if next.is_empty() {
            break;
        }
        for (i, cube, sh) in next {
            probes[i].cube = cube;
            probes[i].sh = sh;
            filled[i] = true;
        }
    }
}

/// One probe's light (see [`Probes`] for the fields).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Probe {
    pub cube: [DVec3; 6],
    pub sh: [DVec3; 9],
    pub inside: bool,
}

/// What a probe anywhere is computed from: the scene's direct light, its solved meshes, the
/// rays.
pub struct ProbeBaker<'a> {
    vis: &'a Visibility,
    direct: Direct<'a>,
    reflected: Reflected<'a>,
    normals: Vec<DVec3>,
    fit: Vec<Vec<f64>>,
    sphere: Vec<(f64, f64)>,
}

impl<'a> ProbeBaker<'a> {
    /// The probes of `scene` with the solved `irradiance` at the vertices of `meshes`, the
    /// direct light as `solve` says, and `rays` rays per probe.
    pub fn new(
        scene: &'a Scene,
        vis: &'a Visibility,
        meshes: &'a [ReceiverMesh],
        irradiance: &'a [Vec<DVec3>],
        solve: &SolveOptions,
        rays: usize,
    ) -> ProbeBaker<'a> {
        let normals = fit_normals();
        let rays = rays.max(1);
        ProbeBaker {
            vis,
            direct: Direct::with_options(scene, vis, solve),
            reflected: Reflected::new(scene, meshes, irradiance),
            fit: least_squares_fit(&normals),
            normals,
            sphere: (0..rays)
                .map(|k| ((k as f64 + 0.5) / rays as f64, radical_inverse2(k as u32)))
                .collect(),
        }
    }

    /// The probe at `p`; `seed` rotates its rays.
    pub fn probe(&self, p: DVec3, seed: u64) -> Probe {
        // Direct: exact at the 26 normals; the first six are the cube's.
        let e_direct: Vec<DVec3> = self
            .normals
            .iter()
            .map(|&n| {
                self.direct.irradiance(&SurfacePoint {
                    p,
                    n,
                    ray_origin: p,
                    polygon: NO_POLYGON,
                })
            })
            .collect();
        let mut cube = [DVec3::ZERO; 6];
        cube.copy_from_slice(&e_direct[..6]);
        let mut sh = [DVec3::ZERO; 9];
        for ((c, row), lobe) in sh.iter_mut().zip(&self.fit).zip(LOBE) {
            // An irradiance coefficient over its lobe is the radiance coefficient.
            *c = row
                .iter()
                .zip(&e_direct)
                .map(|(w, e)| *e * *w)
                .sum::<DVec3>()
                / lobe;
        }
        // Indirect: the reflected radiance along uniform rays.
        let shift = (unit_f64(mix64(seed)), unit_f64(mix64(!seed)));
        let weight = 4.0 * PI / self.sphere.len() as f64;
        let mut backs = 0usize;
        for &(u, v) in &self.sphere {
            let d = sphere_direction((u + shift.0).fract(), (v + shift.1).fract());
            let radiance = match self.reflected.along(self.vis, p, d) {
                Seen::Nothing => continue,
                Seen::Back => {
                    backs += 1;
                    continue;
                }
                Seen::Radiosity(b) => b / PI,
            };
            for (c, y) in sh.iter_mut().zip(sh_basis(d)) {
                *c += radiance * (y * weight);
            }
            for (e, axis) in cube.iter_mut().zip(AXES) {
                *e += radiance * (axis.dot(d).max(0.0) * weight);
            }
        }
        Probe {
            cube,
            sh,
            inside: 2 * backs > self.sphere.len(),
        }
    }
}

/// A unit direction, uniform on the sphere for `(u, v)` uniform in the unit square.
fn sphere_direction(u: f64, v: f64) -> DVec3 {
    let z = 1.0 - 2.0 * u;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * PI * v;
    DVec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// The 26 normals the direct light is evaluated at: the six axes first, then the twelve edge
/// and eight corner directions of a cube.
fn fit_normals() -> Vec<DVec3> {
    let mut n = AXES.to_vec();
    for x in -1..=1 {
        for y in -1..=1 {
            for z in -1..=1 {
                let zeros = [x, y, z].iter().filter(|&&c| c == 0).count();
                if zeros < 2 {
                    n.push(DVec3::new(x as f64, y as f64, z as f64).normalize());
                }
            }
        }
    }
    n
}

/// The least-squares projection from irradiance at `normals` to the nine irradiance
/// coefficients: row `c` holds the weights of each normal's value in coefficient `c`
/// (`(BᵀB)⁻¹ Bᵀ`, `B` the basis at the normals).
fn least_squares_fit(normals: &[DVec3]) -> Vec<Vec<f64>> {
    let b: Vec<[f64; 9]> = normals.iter().map(|&n| sh_basis(n)).collect();
    // BᵀB, 9 x 9, inverted by Gauss-Jordan.
    let mut a = [[0.0; 18]; 9];
    for (i, row) in a.iter_mut().enumerate() {
        for j in 0..9 {
            row[j] = b.iter().map(|r| r[i] * r[j]).sum();
        }
        row[9 + i] = 1.0;
    }
    for c in 0..9 {
        let pivot = (c..9)
            .max_by(|&x, &y| a[x][c].abs().total_cmp(&a[y][c].abs()))
            .unwrap_or(c);
        a.swap(c, pivot);
        let d = a[c][c];
        for v in a[c].iter_mut() {
            *v /= d;
        }
        for r in 0..9 {
            if r != c {
                let f = a[r][c];
                let src = a[c];
                for (v, s) in a[r].iter_mut().zip(src) {
                    *v -= f * s;
                }
            }
        }
    }
    (0..9)
        .map(|c| {
            b.iter()
                .map(|row| (0..9).map(|j| a[c][9 + j] * row[j]).sum())
                .collect()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_fit_reproduces_band_limited_irradiance() {
        // Irradiance that is exactly second order: its fit from the 26 normals is exact.
        let normals = fit_normals();
        let fit = least_squares_fit(&normals);
        let want = [1.0, 0.3, -0.2, 0.1, 0.05, -0.07, 0.02, 0.04, -0.03];
        let e: Vec<f64> = normals
            .iter()
            .map(|&n| sh_basis(n).iter().zip(&want).map(|(y, c)| y * c).sum())
            .collect();
        for (row, w) in fit.iter().zip(want) {
            let got: f64 = row.iter().zip(&e).map(|(a, b)| a * b).sum();
            assert!((got - w).abs() < 1e-9, "{got} {w}");
        }
    }

    #[test]
    fn probes_inside_take_their_neighbours_mean() {
        let probe = |v: f64, inside: bool| Probe {
            cube: [DVec3::splat(v); 6],
            sh: [DVec3::splat(v); 9],
            inside,
        };
        // A row of four: the second and third inside. The second takes the first's value in
        // the first ring (its only neighbour outside), the third the fourth's; the flags stay.
        let mut row = vec![
            probe(1.0, false),
            probe(0.0, true),
            probe(0.0, true),
            probe(5.0, false),
        ];
        fill_inside(&mut row, [4, 1, 1]);
        assert_eq!(row[1].cube[0], DVec3::splat(1.0));
        assert_eq!(row[2].sh[3], DVec3::splat(5.0));
        assert!(row[1].inside && row[2].inside);
        // Further from the outside: a second ring.
        let mut row = vec![probe(2.0, false), probe(0.0, true), probe(0.0, true)];
        fill_inside(&mut row, [3, 1, 1]);
        assert_eq!((row[1].cube[0].x, row[2].cube[0].x), (2.0, 2.0));
        // All inside: nothing to take.
        let mut all = vec![probe(0.5, true); 3];
        fill_inside(&mut all, [3, 1, 1]);
        assert_eq!(all[0].cube[0].x, 0.5);
    }

    #[test]
    fn a_uniform_radiance_gives_pi_l_in_every_direction() {
        // Radiance L from everywhere: c0 = L sqrt(4 pi), the rest 0; E = pi L facing anywhere.
        let l = 2.0;
        let mut sh = [DVec3::ZERO; 9];
        sh[0] = DVec3::splat(l * (4.0 * PI).sqrt());
        for n in fit_normals() {
            let e = sh_irradiance(&sh, n);
            assert!((e.x - PI * l).abs() < 1e-5, "{e}");
        }
        // Uniform rays project a constant radiance onto c0 alone.
        let n = 4096;
        let mut c = [0.0; 9];
        for k in 0..n {
            let d = sphere_direction((k as f64 + 0.5) / n as f64, radical_inverse2(k as u32));
            for (c, y) in c.iter_mut().zip(sh_basis(d)) {
                *c += l * y * 4.0 * PI / n as f64;
            }
        }
        assert!((c[0] - l * (4.0 * PI).sqrt()).abs() < 1e-3, "{c:?}");
        assert!(c[1..].iter().all(|v| v.abs() < 1e-2), "{c:?}");
    }
}
