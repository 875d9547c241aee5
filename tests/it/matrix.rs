//! Classic radiosity (`--solver matrix`) and the form-factor methods of the patch solvers
//! (`--form-factors`): agreement with progressive refinement at convergence, the furnace,
//! determinism, and the memory limit through the command line.

use crate::bad_input::penumbra;
use crate::output::bake_to_file_with;
use crate::{bake, quick, scratch};
use glam::DVec3;
use penumbra::BakeOptions;
use penumbra::fixtures;
use penumbra::solve::{FormFactors, Solver};

fn with(solver: Solver, form_factors: FormFactors) -> BakeOptions {
    let mut o = quick();
    o.solve.solver = solver;
    o.solve.form_factors = form_factors;
    o
}

/// The largest difference between two bakes' vertex irradiance, relative to the larger's peak.
fn max_difference(a: &[Vec<DVec3>], b: &[Vec<DVec3>]) -> f64 {
    let peak = a
        .iter()
        .flatten()
        .map(|h| h.max_element())
        .fold(0.0, f64::max);
    a.iter()
        .flatten()
        .zip(b.iter().flatten())
        .map(|(x, y)| (*x - *y).abs().max_element())
        .fold(0.0, f64::max)
        / peak
}

fn mean(a: &[Vec<DVec3>]) -> f64 {
    let all: Vec<f64> = a.iter().flatten().map(|h| h.element_sum() / 3.0).collect();
    all.iter().sum::<f64>() / all.len() as f64
}

/// At convergence the matrix and progressive solvers solve the same system with the same form
/// factors and the same final gather: every vertex agrees to 1e-5 of the peak (the tolerance
/// of both solves is 1e-7). With `--bounces 2` both carry exactly two bounces.
#[test]
fn matrix_and_progressive_agree_at_convergence() {
    let mut pr = with(Solver::Progressive, FormFactors::ClosedForm);
    pr.solve.tolerance = 1e-7;
    let mut mx = with(Solver::Matrix, FormFactors::ClosedForm);
    mx.solve.tolerance = 1e-7;
    let a = bake(&fixtures::cornell_box(), &pr);
    let b = bake(&fixtures::cornell_box(), &mx);
    let d = max_difference(&a.solution.irradiance, &b.solution.irradiance);
    let indirect = max_difference(&a.solution.irradiance, &a.solution.direct);
    eprintln!("matrix vs progressive at convergence: max difference {d:.2e} of the peak");
    assert!(indirect > 0.01, "the scene must have indirect light");
    assert!(d < 1e-5, "max difference {d:.3e} of the peak");
    let m = b.stats.solve.matrix.as_ref().expect("matrix stats");
    assert_eq!(m.entries, (m.patches * m.patches) as u64);
    assert_eq!(m.bytes, 8 * m.entries);
    assert!(m.sweeps > 1 && m.last_change <= 1e-9, "{m:?}");
    // Two bounces: the same light, the matrix by Jacobi generations.
    pr.solve.bounces = Some(2);
    mx.solve.bounces = Some(2);
    let a2 = bake(&fixtures::cornell_box(), &pr);
    let b2 = bake(&fixtures::cornell_box(), &mx);
    let d2 = max_difference(&a2.solution.irradiance, &b2.solution.irradiance);
    assert!(d2 < 1e-9, "two bounces: {d2:.3e}");
    assert!(max_difference(&a.solution.irradiance, &a2.solution.irradiance) > 1e-4);
}

/// Furnace: B = M/(1-rho) at every vertex with the matrix solver, with closed-form and with
/// hemicube form factors (where the emission itself goes through the hemicube: its delta form
/// factors sum to 1.00013 at 64 cells, and no cell may be left empty in a closed box).
#[test]
fn matrix_furnace_radiosity_is_m_over_one_minus_rho() {
    let (rho, m) = (0.5, 1.0);
    for (ff, tolerance) in [
        (FormFactors::ClosedForm, 1e-3),
        (FormFactors::Hemicube, 3e-4),
    ] {
        let b = bake(
            &fixtures::furnace_box_with(rho, m),
            &with(Solver::Matrix, ff),
        );
        let expected = m / (1.0 - rho);
        let worst = b
            .solution
            .irradiance
            .iter()
            .flatten()
            .map(|h| ((m + rho * h.x) / expected - 1.0).abs())
            .fold(0.0, f64::max);
        eprintln!(
            "furnace, matrix, {}: worst relative error of B {worst:.2e}",
            ff.name()
        );
        assert!(
            worst < tolerance,
            "{ff:?}: worst relative error of B {worst}"
        );
    }
}

/// Hemicube and ray-cast form factors against closed-form ones on the Cornell box: the mean
/// irradiance within 3% (hemicube, both solvers) and 8% (ray cast, whose disk formula
/// `dA cos cos / (pi r² + dA)` is known to fall short near contacts: measured -6.3%), and the
/// hemicube's direct light within 2% of the exact one on average.
#[test]
fn form_factor_methods_agree_on_the_mean() {
    let reference = bake(&fixtures::cornell_box(), &quick());
    let r = mean(&reference.solution.irradiance);
    for (solver, ff, tolerance) in [
        (Solver::Progressive, FormFactors::Hemicube, 0.03),
        (Solver::Matrix, FormFactors::Hemicube, 0.03),
        (Solver::Progressive, FormFactors::Raycast, 0.08),
    ] {
        let b = bake(&fixtures::cornell_box(), &with(solver, ff));
        let got = mean(&b.solution.irradiance);
        eprintln!(
            "{} {}: mean irradiance {got:.5} vs closed-form {r:.5} ({:+.2}%)",
            solver.name(),
            ff.name(),
            100.0 * (got / r - 1.0)
        );
        assert!(
            (got / r - 1.0).abs() < tolerance,
            "{solver:?} {ff:?}: {got} vs {r}"
        );
        let s = &b.stats.solve;
        assert_eq!(s.hemicube.is_some(), ff == FormFactors::Hemicube);
        if let Some(h) = &s.hemicube {
            assert!(h.hemicubes > 0 && h.cells == 3 * 64 * 64, "{h:?}");
            // The direct light went through the hemicube: close to the exact one on average.
            let (dh, de) = (mean(&b.solution.direct), mean(&reference.solution.direct));
            assert!((dh / de - 1.0).abs() < 0.02, "direct {dh} vs {de}");
        }
    }
}

/// The same bytes on 1 and 2 threads with the matrix solver and hemicube form factors.
#[test]
fn matrix_and_hemicube_bakes_are_deterministic() {
    for (solver, ff) in [
        (Solver::Matrix, FormFactors::Hemicube),
        (Solver::Progressive, FormFactors::Hemicube),
    ] {
        let dir = scratch(&format!("matrix-determinism-{}", solver.name()));
        let mut o = with(solver, ff);
        o.budget = Some(500);
        o.solve.patches = 128;
        let a = bake_to_file_with(&fixtures::box_on_floor(), &dir, 1, &o);
        let b = bake_to_file_with(&fixtures::box_on_floor(), &dir, 2, &o);
        assert!(a == b, "{solver:?} {ff:?}: --threads 1 and 2 differ");
    }
}

/// More patches than the matrix memory limit holds: a clear error that states the limit,
/// exit code 1, no panic, no output.
#[test]
fn matrix_memory_limit_is_refused_through_the_cli() {
    let dir = scratch("matrix-limit");
    let input = dir.join("in.glb");
    std::fs::write(&input, fixtures::cornell_box()).unwrap();
    let output = dir.join("out.glb");
    let run = penumbra(&[
        "bake".as_ref(),
        input.as_os_str(),
        output.as_os_str(),
        "--solver".as_ref(),
        "matrix".as_ref(),
        "--patches".as_ref(),
        "5000".as_ref(),
        "--matrix-memory".as_ref(),
        "64".as_ref(),
    ]);
    assert_eq!(run.code, Some(1), "stderr: {}", run.stderr);
    assert!(!run.stderr.contains("panicked"), "{}", run.stderr);
    for needle in [
        "--solver matrix",
        "patches need a",
        "memory limit of 64 MiB",
        "at most 2896 patches",
    ] {
        assert!(
            run.stderr.contains(needle),
            "{needle:?} not in: {}",
            run.stderr
        );
    }
    assert!(!output.exists(), "an output was written");
    // Bad form-factor options are refused too.
    for (args, needle) in [
        (&["--hemicube-resolution", "7"][..], "--hemicube-resolution"),
        (
            &["--solver", "hierarchical", "--form-factors", "hemicube"][..],
            "--form-factors",
        ),
    ] {
        let mut all: Vec<&std::ffi::OsStr> =
            vec!["bake".as_ref(), input.as_os_str(), output.as_os_str()];
        all.extend(args.iter().map(std::ffi::OsStr::new));
        let run = penumbra(&all);
        assert_eq!(run.code, Some(1), "{args:?}: {}", run.stderr);
        assert!(run.stderr.contains(needle), "{args:?}: {}", run.stderr);
        assert!(!output.exists());
    }
}
