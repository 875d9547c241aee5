//! Classic radiosity (`--solver matrix`): the form factors between all pairs of patches into a
//! matrix, and the system `(I - rho F) B = S` solved by Gauss-Seidel (Goral, Torrance,
//! Greenberg, Battaile, "Modeling the interaction of light between diffuse surfaces", SIGGRAPH
//! 1984; Cohen and Greenberg, "The hemi-cube: a radiosity solution for complex environments",
//! SIGGRAPH 1985).
//!
//! The patches and their system are the progressive solver's ([`super::patches`](mod@super::patches)), and so is
//! the final gather at the vertices; only the solve differs. Row `i` of `F` holds the form
//! factors from patch `i`'s centroid to every patch (`--form-factors`: closed form, ray cast, or
//! one hemicube per row). The matrix is dense, `n²` f64 entries: its memory and the time to fill
//! it grow with the square of the patch count, which is why progressive refinement and
//! hierarchical radiosity replaced it. A bake refuses more patches than fit in
//! `--matrix-memory` ([`check_memory`]) before any expensive stage.
//!
//! [`gauss_seidel`] solves the full system with closed-form form factors, apart from a bake: the
//! progressive solver's test oracle.
//!
//! Irradiance `H` and radiosity `B` in W/m² per linear RGB channel; memory in bytes.

use super::SolveOptions;
use super::SolveStats;
use super::form_factors::{FormFactors, Kernel};
use super::patches::{Patch, PatchSystem};
use crate::visibility::Visibility;
use glam::DVec3;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

/// Default `--matrix-memory`, MiB: 1024 MiB holds 11 585 patches.
pub const DEFAULT_MEMORY_MIB: u64 = 1024;

/// Bytes per matrix entry (f64).
pub(crate) const BYTES_PER_ENTRY: u64 = 8;

/// Most Gauss-Seidel sweeps of an unbounded solve.
pub(crate) const MAX_SWEEPS: usize = 1000;

/// Gauss-Seidel stops when a sweep changes the power by less than this fraction of
/// `--tolerance` (relative to the source power): a sweep costs `n²` multiplications, far less
/// than a row of form factors, so the matrix is solved well past the progressive solver's
/// stopping point.
const SWEEP_TOLERANCE: f64 = 1e-2;

/// Bytes of the form-factor matrix of `n` patches.
pub(crate) fn bytes(n: usize) -> u64 {
    (n as u64)
        .saturating_mul(n as u64)
        .saturating_mul(BYTES_PER_ENTRY)
}

/// The most patches whose matrix fits in `limit_mib` MiB.
pub(crate) fn max_patches(limit_mib: u64) -> usize {
    let entries = limit_mib.saturating_mul(1 << 20) / BYTES_PER_ENTRY;
    let mut n = (entries as f64).sqrt() as u64;
    while n * n > entries {
        n -= 1;
    }
    while (n + 1) * (n + 1) <= entries {
        n += 1;
    }
    n as usize
}

/// Refuses `n` patches whose matrix exceeds `limit_mib` MiB, with the sizes and what to do.
pub(crate) fn check_memory(n: usize, limit_mib: u64) -> Result<(), String> {
    if bytes(n) <= limit_mib.saturating_mul(1 << 20) {
        return Ok(());
    }
    Err(format!(
        "{n} patches need a {n} x {n} form-factor matrix of {:.0} MiB ({} bytes per entry), \
         more than the memory limit of {limit_mib} MiB (--matrix-memory); classic radiosity \
         stores every pair of patches. Use at most {} patches (--patches), raise the limit, or \
         use --solver progressive or hierarchical",
        bytes(n) as f64 / (1 << 20) as f64,
        BYTES_PER_ENTRY,
        max_patches(limit_mib)
    ))
}

/// Counters of the matrix solve, reported in `--stats` (`solve.matrix`).
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct MatrixStats {
    pub patches: usize,
    /// `n²`.
    pub entries: u64,
    /// Memory of the matrix, bytes.
    pub bytes: u64,
    /// The limit it had to fit, bytes.
    pub limit_bytes: u64,
    /// Entries that are not 0.
    pub nonzero: u64,
    /// Time to fill the matrix, seconds.
    pub form_factor_seconds: f64,
    /// Time of the Gauss-Seidel (or Jacobi, with `--bounces`) iterations, seconds.
    pub solve_seconds: f64,
    pub sweeps: usize,
    /// The power changed by the last sweep, relative to the source power.
    pub last_change: f64,
}

/// The dense form-factor matrix, row-major: `F_ij` from patch `i`'s centroid to patch `j`.
pub(crate) struct FormFactorMatrix {
    n: usize,
    f: Vec<f64>,
}

impl FormFactorMatrix {
    /// Fills the `n x n` matrix by `kernel`, one row per task; returns it and the rays cast.
    pub(crate) fn new(kernel: &Kernel<'_>, n: usize) -> (FormFactorMatrix, u64) {
        let mut f = vec![0.0; n * n];
        let rays = AtomicU64::new(0);
        f.par_chunks_mut(n.max(1)).enumerate().for_each(|(i, row)| {
            let mut r = 0;
            let values = kernel.gather(&kernel.centroid_point(i), &|j| j != i, &mut r);
            row.copy_from_slice(&values);
            rays.fetch_add(r, Ordering::Relaxed);
        });
        (FormFactorMatrix { n, f }, rays.into_inner())
    }

    /// Row `i`: the form factors from patch `i`'s centroid.
    pub(crate) fn row(&self, i: usize) -> &[f64] {
        &self.f[i * self.n..(i + 1) * self.n]
    }

    /// `H_i = D_i + sum_j F_ij B_j`.
    pub(crate) fn irradiance(&self, system: &PatchSystem<'_>, b: &[DVec3]) -> Vec<DVec3> {
        (0..self.n)
            .map(|i| {
                let row = self.row(i);
                system.direct[i] + (0..self.n).map(|j| b[j] * row[j]).sum::<DVec3>()
            })
            .collect()
    }
}

/// Classic radiosity on `system`: fills the matrix, then Gauss-Seidel until converged (or, with
/// `--bounces n`, exactly the light of `n` bounces by Jacobi iterations, as the progressive
/// solver's generations). Returns each patch's irradiance `H`; fills `stats` (its
/// `unshot_fraction` is the last sweep's relative change).
pub(crate) fn solve(
    kernel: &Kernel<'_>,
    system: &PatchSystem<'_>,
    options: &SolveOptions,
    stats: &mut SolveStats,
) -> Vec<DVec3> {
    let n = system.patches.len();
    let start = Instant::now();
    let (f, rays) = FormFactorMatrix::new(kernel, n);
    let form_factor_seconds = start.elapsed().as_secs_f64();
    let start = Instant::now();
    let source = system.source();
    let mut b = source.clone();
    let (h, sweeps, last_change) = match options.bounces {
        Some(k) => {
            // Generations of exchanged light, as `progressive::refine` counts them.
            let generations = (k as usize + system.emits() as usize).saturating_sub(1);
            if generations == 0 {
                (system.direct.clone(), 0, 0.0)
            } else {
                for _ in 1..generations {
                    let next: Vec<DVec3> = (0..n)
                        .map(|i| {
                            let row = f.row(i);
                            let g: DVec3 = (0..n).map(|j| b[j] * row[j]).sum();
                            source[i] + system.patches[i].rho * g
                        })
                        .collect();
                    b = next;
                }
                (f.irradiance(system, &b), generations - 1, 0.0)
            }
        }
        None => {
            let (sweeps, change) = sweeps(
                &f,
                system,
                &mut b,
                options.tolerance * SWEEP_TOLERANCE,
                MAX_SWEEPS,
            );
            (f.irradiance(system, &b), sweeps, change)
        }
    };
    stats.patches = n;
    stats.rays += rays;
    stats.unshot_fraction = last_change;
    stats.matrix = Some(MatrixStats {
        patches: n,
        entries: (n * n) as u64,
        bytes: bytes(n),
        limit_bytes: options.matrix_memory_mib.saturating_mul(1 << 20),
        nonzero: f.f.iter().filter(|x| **x != 0.0).count() as u64,
        form_factor_seconds,
        solve_seconds: start.elapsed().as_secs_f64(),
        sweeps,
        last_change,
    });
    h
}

/// Gauss-Seidel sweeps on `B = S + rho F B` (`S` the source of `system`, `F` the matrix),
/// starting from `b` and updating it in place, until the power changed by one sweep is at most
/// `tolerance` of the source's power, or `max_sweeps`. Returns the sweeps done and the last
/// sweep's relative change. Sequential sums in index order: deterministic.
pub(crate) fn sweeps(
    f: &FormFactorMatrix,
    system: &PatchSystem<'_>,
    b: &mut [DVec3],
    tolerance: f64,
    max_sweeps: usize,
) -> (usize, f64) {
    let n = system.patches.len();
    let source = system.source();
    let scale = system.power(&source).max(f64::MIN_POSITIVE);
    let mut change = f64::INFINITY;
    let mut done = 0;
    while done < max_sweeps && (change > tolerance || change.is_nan()) {
        let mut moved = 0.0;
        for i in 0..n {
            let row = f.row(i);
            let gathered: DVec3 = (0..n).map(|j| b[j] * row[j]).sum();
            let new = source[i] + system.patches[i].rho * gathered;
            moved += (new - b[i]).abs().element_sum() / 3.0 * system.patches[i].area;
            b[i] = new;
        }
        change = moved / scale;
        done += 1;
    }
    (done, change)
}

/// The full patch system with closed-form form factors, solved by `sweeps` Gauss-Seidel
/// sweeps: returns each patch's irradiance like
/// the progressive solver. Quadratic memory: for small scenes and
/// tests.
pub fn gauss_seidel(
    vis: &Visibility,
    patches: &[Patch],
    direct: &[DVec3],
    sweeps_: usize,
) -> Vec<DVec3> {
    let kernel = Kernel::new(vis, patches, FormFactors::ClosedForm, 0);
    let system = PatchSystem::new(patches, direct.to_vec(), vec![DVec3::ZERO; patches.len()]);
    let (f, _) = FormFactorMatrix::new(&kernel, patches.len());
    let mut b = system.source();
    sweeps(&f, &system, &mut b, 0.0, sweeps_);
    f.irradiance(&system, &b)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn memory_limit_in_patches() {
        // 1 MiB = 131072 entries: 362² = 131044 fits, 363² does not.
        assert_eq!(max_patches(1), 362);
        assert!(check_memory(362, 1).is_ok());
        let e = check_memory(363, 1).unwrap_err();
        assert!(e.contains("363 patches") && e.contains("1 MiB") && e.contains("at most 362"));
        assert_eq!(max_patches(DEFAULT_MEMORY_MIB), 11585);
    }
}
