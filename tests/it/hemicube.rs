//! Hemicube form factors (`--form-factors hemicube`) against closed forms: the unit squares of
//! Howell's catalogue, parallel and perpendicular, at several distances and resolutions. Two
//! errors are measured apart, and neither is hidden:
//!
//! * the hemicube's own (discretization) error, against the exact point-to-polygon form factor
//!   from the same point (Lambert's contour formula): it shrinks with the resolution, except
//!   where a small far square aliases against the cells;
//! * the proximity error of the classic method, which takes the form factor from the patch's
//!   centre as the patch's: against Howell's area-to-area closed form. It does not shrink with
//!   the resolution, and it grows as the squares come near (and worst where they touch).
//!
//! `cargo test --release --test it hemicube -- --nocapture` prints the tables that the README
//! quotes.

use crate::parallel_rectangles;
use glam::DVec3;
use penumbra::geometry::point_polygon_form_factor;
use penumbra::solve::hemicube::Hemicube;
use std::f64::consts::PI;

/// Howell C-14: from a rectangle of width `w` to a perpendicular one of height `h` sharing its
/// edge of length 1.
fn perpendicular_common_edge(w: f64, h: f64) -> f64 {
    if h <= 0.0 {
        return 0.0;
    }
    let (w2, h2) = (w * w, h * h);
    let s = w2 + h2;
    let log = ((1.0 + w2) * (1.0 + h2) / (1.0 + s)).ln()
        + w2 * (w2 * (1.0 + s) / ((1.0 + w2) * s)).ln()
        + h2 * (h2 * (1.0 + s) / ((1.0 + h2) * s)).ln();
    (w * (1.0 / w).atan() + h * (1.0 / h).atan() - s.sqrt() * (1.0 / s.sqrt()).atan() + log / 4.0)
        / (PI * w)
}

/// A configuration: the receiving unit square's centre and normal, the other square's corners
/// (two triangles), and Howell's area-to-area form factor.
struct Case {
    name: String,
    p: DVec3,
    n: DVec3,
    square: [DVec3; 4],
    area_to_area: f64,
}

fn triangles(q: &[DVec3; 4]) -> [[DVec3; 3]; 2] {
    [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]
}

/// The receiver is the unit square `[0,1]² x {0}` facing +z (centre `(0.5, 0.5, 0)`).
fn parallel(d: f64) -> Case {
    Case {
        name: format!("parallel, distance {d}"),
        p: DVec3::new(0.5, 0.5, 0.0),
        n: DVec3::Z,
        square: [[0.0, 0.0, d], [1.0, 0.0, d], [1.0, 1.0, d], [0.0, 1.0, d]].map(DVec3::from_array),
        area_to_area: parallel_rectangles(1.0, 1.0, d),
    }
}

/// The other square stands on the receiver's edge `y = 1`, from `z = gap` to `gap + 1`
/// (form-factor algebra on Howell C-14 for the gap).
fn perpendicular(gap: f64) -> Case {
    Case {
        name: format!("perpendicular, gap {gap}"),
        p: DVec3::new(0.5, 0.5, 0.0),
        n: DVec3::Z,
        square: [
            [0.0, 1.0, gap],
            [1.0, 1.0, gap],
            [1.0, 1.0, gap + 1.0],
            [0.0, 1.0, gap + 1.0],
        ]
        .map(DVec3::from_array),
        area_to_area: perpendicular_common_edge(1.0, gap + 1.0)
            - perpendicular_common_edge(1.0, gap),
    }
}

fn hemicube(case: &Case, resolution: u32) -> f64 {
    Hemicube::new(resolution)
        .form_factors(case.p, case.n, &triangles(&case.square), &|_| false)
        .form_factors
        .iter()
        .sum()
}

const RESOLUTIONS: [u32; 5] = [8, 16, 32, 64, 256];

/// The closed forms themselves, against the values in Howell's catalogue.
#[test]
fn howell_closed_forms() {
    assert!((parallel_rectangles(1.0, 1.0, 1.0) - 0.199_825).abs() < 1e-6);
    assert!((perpendicular_common_edge(1.0, 1.0) - 0.200_044).abs() < 1e-6);
}

/// The hemicube against the exact point form factor (its own error) and against Howell's
/// area-to-area form factor (the proximity error of taking the centre for the patch).
#[test]
fn hemicube_form_factors_against_closed_forms() {
    let cases: Vec<Case> = [0.1, 0.5, 1.0, 2.0, 5.0]
        .map(parallel)
        .into_iter()
        .chain([0.0, 0.1, 0.5, 2.0].map(perpendicular))
        .collect();
    eprintln!(
        "| configuration | Howell F (area) | F from centre (exact) | proximity error | {} |",
        RESOLUTIONS.map(|r| format!("hemicube {r}")).join(" | ")
    );
    eprintln!("|---|---|---|---|{}", "---|".repeat(RESOLUTIONS.len()));
    for case in &cases {
        let exact = point_polygon_form_factor(case.p, case.n, &case.square);
        let proximity = exact / case.area_to_area - 1.0;
        let errors: Vec<f64> = RESOLUTIONS
            .iter()
            .map(|&r| hemicube(case, r) / exact - 1.0)
            .collect();
        eprintln!(
            "| {} | {:.6} | {:.6} | {:+.2}% | {} |",
            case.name,
            case.area_to_area,
            exact,
            100.0 * proximity,
            errors
                .iter()
                .map(|e| format!("{:+.3}%", 100.0 * e))
                .collect::<Vec<_>>()
                .join(" | ")
        );
        let at = |r: u32| errors[RESOLUTIONS.iter().position(|&x| x == r).unwrap()].abs();
        if case.area_to_area < 0.02 {
            // The unit square 5 away: its image is 0.2 of the top face wide, 0.8 cells at 8
            // (missed), 6.4 at 64 (aliased: 6 or 7 cell centres across), 26 at 256.
            assert!(at(8) > 0.5, "{}: {errors:?}", case.name);
            assert!(at(64) > 0.05, "{}: {errors:?}", case.name);
            assert!(at(256) < 0.05, "{}: {errors:?}", case.name);
        } else {
            // Within 2% at the default resolution, 0.3% at 256, and much smaller at 256 than
            // at 8 cells.
            assert!(at(64) < 0.02, "{}: {:.4} at 64", case.name, at(64));
            assert!(at(256) < 3e-3, "{}: {:.5} at 256", case.name, at(256));
            assert!(
                at(256) < 0.5 * at(8),
                "{}: no convergence, {errors:?}",
                case.name
            );
        }
    }
    // Proximity: taking the centre for the patch is within 2% for squares 5 apart, but off by
    // more than 10% for near ones (0.1 and 0.5 apart, parallel and perpendicular), at any
    // resolution.
    let far = &cases[4];
    let exact_far = point_polygon_form_factor(far.p, far.n, &far.square);
    assert!((exact_far / far.area_to_area - 1.0).abs() < 0.02);
    for near in [&cases[0], &cases[1], &cases[6], &cases[7]] {
        let exact = point_polygon_form_factor(near.p, near.n, &near.square);
        assert!(
            (exact / near.area_to_area - 1.0).abs() > 0.1,
            "{}: {exact} vs {}",
            near.name,
            near.area_to_area
        );
        assert!((hemicube(near, 256) / near.area_to_area - 1.0).abs() > 0.1);
    }
}

/// Aliasing: a small square (2 cm) far away (2 m) seen from 16 points a few mm apart. The
/// exact form factor hardly changes; the hemicube's jumps between 0 and whole cells at low
/// resolution, and settles only when the cells are much smaller than the square's image.
#[test]
fn hemicube_aliases_small_far_patches() {
    let side = 0.02;
    let square = [
        [0.0, 0.0, 2.0],
        [side, 0.0, 2.0],
        [side, side, 2.0],
        [0.0, side, 2.0],
    ]
    .map(DVec3::from_array);
    let worst = |resolution: u32| -> (f64, f64) {
        let hc = Hemicube::new(resolution);
        let mut worst: f64 = 0.0;
        let mut missed = 0.0;
        for k in 0..16 {
            let p = DVec3::new(0.3 + 0.0037 * k as f64, 0.2 - 0.0021 * k as f64, 0.0);
            let exact = point_polygon_form_factor(p, DVec3::Z, &square);
            let f: f64 = hc
                .form_factors(p, DVec3::Z, &triangles(&square), &|_| false)
                .form_factors
                .iter()
                .sum();
            worst = worst.max((f / exact - 1.0).abs());
            if f == 0.0 {
                missed += 1.0 / 16.0;
            }
        }
        (worst, missed)
    };
    eprintln!("| resolution | worst relative error | points that miss the square |");
    eprintln!("|---|---|---|");
    let table: Vec<(u32, (f64, f64))> = [16, 64, 256, 1024].map(|r| (r, worst(r))).to_vec();
    for (r, (w, m)) in &table {
        eprintln!("| {r} | {:.1}% | {:.0}% |", 100.0 * w, 100.0 * m);
    }
    // At 16 and 64 cells the square falls between cell centres (form factor 0) or takes a
    // whole cell: errors of 100% and more.
    assert!(table[0].1.0 >= 1.0 && table[0].1.1 > 0.5, "{table:?}");
    assert!(table[1].1.0 >= 0.5, "{table:?}");
    // At 1024 cells its image spans about 5 x 5 cells: within 50%, and never missed.
    assert!(table[3].1.0 < 0.5 && table[3].1.1 == 0.0, "{table:?}");
}
