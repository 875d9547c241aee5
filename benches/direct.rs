//! Direct light at the mesh vertices: exact (backprojection) against sampled visibility with
//! 64 and 256 shadow rays, on the Cornell box and on grids of boxes under an area light.
//!
//! ```text
//! cargo bench --bench direct [-- --budget N --reps R]
//! ```
//!
//! For each scene and method: the wall time of the direct light at every vertex of a uniform
//! mesh of `--budget` elements (best of `--reps` runs, all threads), and the error of the
//! sampled methods against exact, relative to the brightest vertex: maximum and RMS over all
//! vertices, and over the penumbra vertices only (those that see between 0.1% and 99.9% of
//! their unoccluded light). Timings belong here, never in tests.

use penumbra::fixtures::{self, GlbBuilder, Material};
use penumbra::scene::Scene;
use penumbra::solve::{self, Direct, DirectMethod, DirectStats, SolveOptions};
use penumbra::visibility::Visibility;
use std::f64::consts::PI;
use std::path::Path;
use std::time::Instant;

/// `n x n` boxes on a floor under one square area light.
///
/// Boxes 0.5 m wide on a 1 m pitch, their heights cycling through 0.25 to 1.0 m; the floor
/// reaches 1 m past the grid; the light (radiance 10 W/(m² sr), facing down) is `n / 4` m
/// wide, centred 3 m above the floor. All grey (reflectance 0.5).
fn box_grid(n: usize) -> Vec<u8> {
    let mut b = GlbBuilder::new();
    let grey = b.add_material(Material::diffuse("grey", [0.5; 3]));
    let light = b.add_material(Material::diffuse("light", [0.0; 3]).emitting([10.0; 3]));
    let half = n as f64 / 2.0;
    b.add_mesh_node(
        "floor",
        &fixtures::horizontal_rect(
            [-half - 1.0, half + 1.0],
            [-half - 1.0, half + 1.0],
            0.0,
            true,
        ),
        grey,
    );
    for i in 0..n {
        for j in 0..n {
            let (x, z) = (-half + 0.5 + i as f64, -half + 0.5 + j as f64);
            let h = 0.25 + 0.25 * ((3 * i + 7 * j) % 4) as f64;
            let top = [
                [x - 0.25, h, z - 0.25],
                [x - 0.25, h, z + 0.25],
                [x + 0.25, h, z + 0.25],
                [x + 0.25, h, z - 0.25],
            ];
            b.add_mesh_node(
                &format!("box {i} {j}"),
                &fixtures::block(top, 0.0, false),
                grey,
            );
        }
    }
    let s = n as f64 / 8.0;
    b.add_mesh_node(
        "light",
        &fixtures::horizontal_rect([-s, s], [-s, s], 3.0, false),
        light,
    );
    b.to_glb()
}

/// A UV sphere lamp (radius 0.3 m, `rings` x `2 rings` faces, radiance 10 W/(m² sr), facing
/// out) 1.5 m above a floor with a 3 x 3 grid of boxes: hundreds of small emitter polygons
/// (each planar quad of the sphere is one).
fn sphere_lamp(rings: usize) -> Vec<u8> {
    let mut b = GlbBuilder::new();
    let grey = b.add_material(Material::diffuse("grey", [0.5; 3]));
    let light = b.add_material(Material::diffuse("light", [0.0; 3]).emitting([10.0; 3]));
    b.add_mesh_node(
        "floor",
        &fixtures::horizontal_rect([-3.0, 3.0], [-3.0, 3.0], 0.0, true),
        grey,
    );
    for i in 0..3 {
        for j in 0..3 {
            let (x, z) = (-1.5 + 1.5 * i as f64, -1.5 + 1.5 * j as f64);
            let top = [
                [x - 0.3, 0.6, z - 0.3],
                [x - 0.3, 0.6, z + 0.3],
                [x + 0.3, 0.6, z + 0.3],
                [x + 0.3, 0.6, z - 0.3],
            ];
            b.add_mesh_node(
                &format!("box {i} {j}"),
                &fixtures::block(top, 0.0, false),
                grey,
            );
        }
    }
    let (r, c) = (0.3, [0.0, 1.5, 0.0]);
    let segments = 2 * rings;
    let mut positions = Vec::new();
    for i in 0..=rings {
        let theta = std::f64::consts::PI * i as f64 / rings as f64;
        for j in 0..=segments {
            let phi = 2.0 * std::f64::consts::PI * j as f64 / segments as f64;
            positions.push([
                c[0] + r * theta.sin() * phi.cos(),
                c[1] + r * theta.cos(),
                c[2] + r * theta.sin() * phi.sin(),
            ]);
        }
    }
    let mut indices = Vec::new();
    let at = |i: usize, j: usize| (i * (segments + 1) + j) as u32;
    for i in 0..rings {
        for j in 0..segments {
            let (a, bb, cc, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
            // Outward: counter-clockwise seen from outside.
            if i != 0 {
                indices.extend([a, d, cc]);
            }
            if i != rings - 1 {
                indices.extend([a, cc, bb]);
            }
        }
    }
    let sphere = fixtures::TriangleMesh {
        positions,
        normals: None,
        texcoords: None,
        tangents: None,
        indices,
    };
    b.add_mesh_node("lamp", &sphere, light);
    b.to_glb()
}

struct Run {
    seconds: f64,
    values: Vec<f64>,
    stats: DirectStats,
}

fn run(
    scene: &Scene,
    vis: &Visibility,
    meshes: &[penumbra::mesh::ReceiverMesh],
    options: &SolveOptions,
    reps: usize,
) -> Run {
    let mut best = f64::INFINITY;
    let mut out = None;
    for _ in 0..reps {
        let direct = Direct::with_options(scene, vis, options);
        let start = Instant::now();
        let h = solve::direct_light(scene, vis, &direct, meshes, &|_, _, _| {});
        best = best.min(start.elapsed().as_secs_f64());
        out = Some((h, direct.stats()));
    }
    let (h, stats) = out.expect("at least one rep");
    Run {
        seconds: best,
        values: h.iter().flatten().map(|v| v.element_sum() / 3.0).collect(),
        stats,
    }
}

/// Unoccluded direct irradiance (mean over RGB) at every vertex, to tell penumbra vertices.
fn unoccluded(
    scene: &Scene,
    vis: &Visibility,
    meshes: &[penumbra::mesh::ReceiverMesh],
) -> Vec<f64> {
    let direct = Direct::new(scene, vis, 1);
    let mut out = Vec::new();
    for m in meshes {
        let poly = &scene.polygons[m.polygon];
        for v in &m.vertices {
            let p = poly.frame.world_from_plane(*v);
            let h: f64 = direct
                .emitters
                .iter()
                .map(|e| PI * e.radiance.element_sum() / 3.0 * e.form_factor(p, poly.frame.n))
                .sum();
            out.push(h);
        }
    }
    out
}

fn main() {
    let mut budget = 20_000;
    let mut reps = 3;
    // `cargo bench` passes --bench; filters are not supported.
    let mut args = std::env::args().skip(1).filter(|a| a != "--bench");
    while let Some(a) = args.next() {
        let value = args.next().and_then(|v| v.parse().ok());
        match (a.as_str(), value) {
            ("--budget", Some(v)) => budget = v,
            ("--reps", Some(v)) => reps = v,
            _ => {
                eprintln!("usage: cargo bench --bench direct [-- --budget N --reps R]");
                std::process::exit(2);
            }
        }
    }
    let scenes: Vec<(&str, Vec<u8>)> = vec![
        ("cornell box", fixtures::cornell_box()),
        ("box grid 10x10", box_grid(10)),
        ("box grid 20x20", box_grid(20)),
        ("sphere lamp", sphere_lamp(12)),
    ];
    println!(
        "budget {budget} elements, best of {reps}, {} threads\n",
        rayon::current_num_threads()
    );
    println!(
        "| scene | vertices | method | time (s) | x exact | max err | RMS err | max err (penumbra) | RMS err (penumbra) |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    let mut notes = Vec::new();
    for (name, glb) in &scenes {
        let gltf = penumbra::load::from_bytes(glb.clone(), Path::new("bench.glb")).expect("parses");
        let scene = penumbra::load::scene(&gltf).expect("loads");
        let vis = Visibility::new(&scene);
        let meshes = penumbra::mesh::uniform(&scene, budget);
        let options = |direct, shadow_samples| SolveOptions {
            direct,
            shadow_samples,
            ..SolveOptions::default()
        };
        let exact = run(
            &scene,
            &vis,
            &meshes,
            &options(DirectMethod::Exact, 64),
            reps,
        );
        let free = unoccluded(&scene, &vis, &meshes);
        let peak = exact.values.iter().copied().fold(0.0, f64::max);
        let penumbra: Vec<bool> = exact
            .values
            .iter()
            .zip(&free)
            .map(|(e, u)| *e > 1e-3 * u && *e < (1.0 - 1e-3) * u)
            .collect();
        let vertices = exact.values.len();
        println!(
            "| {name} | {vertices} | exact | {:.3} | 1 | 0 | 0 | 0 | 0 |",
            exact.seconds
        );
        for samples in [64, 256] {
            let s = run(
                &scene,
                &vis,
                &meshes,
                &options(DirectMethod::Sampled, samples),
                reps,
            );
            let (mut max, mut sum, mut pmax, mut psum, mut pn) = (0.0f64, 0.0, 0.0f64, 0.0, 0);
            for ((a, b), pen) in s.values.iter().zip(&exact.values).zip(&penumbra) {
                let e = (a - b).abs() / peak;
                max = max.max(e);
                sum += e * e;
                if *pen {
                    pmax = pmax.max(e);
                    psum += e * e;
                    pn += 1;
                }
            }
            println!(
                "| {name} | {vertices} | sampled {samples} | {:.3} | {:.2} | {:.2e} | {:.2e} | {:.2e} | {:.2e} |",
                s.seconds,
                s.seconds / exact.seconds,
                max,
                (sum / vertices as f64).sqrt(),
                pmax,
                (psum / pn.max(1) as f64).sqrt(),
            );
        }
        let st = &exact.stats;
        notes.push(format!(
            "{name}: {} penumbra vertices of {vertices}; exact: {} evaluations, {:.1} candidates \
             and {:.1} occluders each on average, at most {}, at most {} visible pieces, {} \
             fallbacks",
            penumbra.iter().filter(|p| **p).count(),
            st.evaluations,
            st.candidates as f64 / st.evaluations.max(1) as f64,
            st.occluders as f64 / st.evaluations.max(1) as f64,
            st.occluders_max,
            st.pieces_max,
            st.fallbacks
        ));
    }
    println!();
    for n in notes {
        println!("{n}");
    }
}
