//! Every stage of a default bake on scenes of three sizes, and the bake's own rays replayed
//! against a plain obvhs loop.
//!
//! ```text
//! cargo bench --bench stages [-- --rays N --reps R]
//! ```
//!
//! Scenes: [`fixtures::box_grid`] at 5 x 5, 10 x 10 and 20 x 20 boxes, and the Cornell box.
//! For each, in one process:
//!
//! 1. **Stages.** The best of `--reps` bakes with [`BakeOptions::default`]: each stage's wall
//!    time (`Bake.stats.timings_s`; *load* adds the glb parse to the scene build), input
//!    triangles and mesh elements; then how each stage's time grows from one grid to the next
//!    against the growth of the input (`k` in `time ∝ triangles^k`).
//! 2. **Rays.** One more bake with the ray recorder on ([`visibility::record_rays`]): the rays
//!    each ray-casting stage casts, by query kind, and the stage's effective rays/s (its rays /
//!    its wall time in step 1).
//! 3. **Replay.** An evenly spread sample of up to `--rays` of those rays (default 2M), cast
//!    again (a) through penumbra's [`Visibility`] API, from world coordinates, as the stages
//!    call it, and (b) through a plain obvhs loop: a `Bvh2` built here from the same
//!    triangles, centred and in f32 as `visibility.rs` does (so both answer the same queries;
//!    the 8-wide CWBVH misses near-origin hits, measured below), queried with `ray_traverse` /
//!    `ray_traverse_miss` and obvhs's own triangle test. For reference, (c) the same loop over
//!    obvhs's `CwBvh`, with its disagreements. Each on one thread and on all (rayon); best of 3,
//!    the loops interleaved. Agreement of the hit/miss answers is printed.
//!
//! The tables go to stdout and to `target/bench-stages.md`. Timings belong in benchmarks, never
//! in tests; compare ratios measured in one run (the machine may be shared and noisy).

use glam::{DVec3, Vec3A};
use obvhs::{bvh2::Bvh2, cwbvh::CwBvh, ray::Ray, ray::RayHit, triangle::Triangle};
use penumbra::fixtures;
use penumbra::scene::Scene;
use penumbra::visibility::{self, Query, RayCounts, RecordedRay, Visibility};
use penumbra::{Bake, BakeOptions};
use rayon::prelude::*;
use std::fmt::Write as _;
use std::hint::black_box;
use std::path::Path;
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// Stage names as `bake` reports them, in pipeline order, with the table's column titles.
const STAGES: [(&str, &str); 7] = [
    ("scene", "load"),
    ("visibility", "visibility"),
    ("discontinuity", "discontinuity"),
    ("mesh", "mesh"),
    ("solve", "solve"),
    ("atlas", "atlas"),
    ("lightmap", "lightmap"),
];

struct Options {
    rays: usize,
    reps: usize,
}

fn options() -> Options {
    let mut o = Options {
        rays: 2_000_000,
        reps: 2,
    };
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--rays" => o.rays = args.next().and_then(|v| v.parse().ok()).expect("--rays N"),
            "--reps" => o.reps = args.next().and_then(|v| v.parse().ok()).expect("--reps R"),
            "--bench" => {} // `cargo bench` passes it.
            other => {
                // `--help`, or a typo: say what it takes instead of running with the defaults.
                let usage = "usage: cargo bench --bench stages [-- --rays N --reps R]";
                if other == "--help" || other == "-h" {
                    println!("{usage}");
                    std::process::exit(0);
                }
                eprintln!("unknown argument {other:?}\n{usage}");
                std::process::exit(2);
            }
        }
    }
    o.reps = o.reps.max(1);
    o
}

/// One scene's measurements.
struct Row {
    name: String,
    triangles: usize,
    polygons: usize,
    elements: usize,
    /// Seconds per stage, indexed like [`STAGES`] (best over the repetitions).
    stage_s: [f64; 7],
    /// Of `solve`: the direct light at the vertices (the rest is patches, shooting, gather).
    direct_s: f64,
    /// Rays cast per phase: (phase, counts), from the recording bake.
    rays: Vec<(&'static str, RayCounts)>,
    total_rays: RayCounts,
    /// The recording bake's lightmap is the timed bake's, bit for bit.
    recording_identical: bool,
    replay: Replay,
}

/// Replay throughput, rays per second, and agreement.
#[derive(Default)]
struct Replay {
    sample: usize,
    closest: usize,
    api_1: f64,
    plain_1: f64,
    cw_1: f64,
    api_n: f64,
    plain_n: f64,
    cw_n: f64,
    hits_bake: usize,
    hits_api: usize,
    hits_plain: usize,
    hits_cw: usize,
    api_vs_plain: usize,
    api_vs_bake: usize,
    cw_vs_plain: usize,
}

fn main() {
    let o = options();
    let threads = rayon::current_num_threads();
    let scenes: Vec<(String, Vec<u8>)> = [5, 10, 20]
        .into_iter()
        .map(|n| (format!("box grid {n}x{n}"), fixtures::box_grid(n)))
        .chain([("cornell box".to_string(), fixtures::cornell_box())])
        .collect();
    let start = Instant::now();
    let load_before = loadavg();
    let mut rows = Vec::new();
    for (name, glb) in &scenes {
        eprintln!("[{:6.1} s] {name}: baking", start.elapsed().as_secs_f64());
        let (bake, stage_s, direct_s) = timed_bakes(name, glb, o.reps);
        eprintln!(
            "[{:6.1} s] {name}: recording rays",
            start.elapsed().as_secs_f64()
        );
        let (recorded, rays, total_rays, texels) = recording_bake(name, glb, o.rays);
        eprintln!(
            "[{:6.1} s] {name}: replaying {} rays",
            start.elapsed().as_secs_f64(),
            recorded.len()
        );
        let replay = replay(&bake.scene, &recorded);
        rows.push(Row {
            name: name.clone(),
            triangles: bake.stats.triangles,
            polygons: bake.stats.polygons,
            elements: bake.stats.elements,
            stage_s,
            direct_s,
            rays,
            total_rays,
            recording_identical: texels == bake.lightmap.texels,
            replay,
        });
    }
    let load = format!("{load_before} before, {} after", loadavg());
    let report = report(&rows, &o, threads, &load, start.elapsed());
    print!("{report}");
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("target"));
    let out = target.join("bench-stages.md");
    match std::fs::create_dir_all(&target).and_then(|_| std::fs::write(&out, &report)) {
        Ok(()) => eprintln!("written to {}", out.display()),
        Err(e) => eprintln!("could not write {}: {e}", out.display()),
    }
}

/// Parses and bakes once.
fn bake_once(name: &str, glb: &[u8], progress: &penumbra::progress::Progress<'_>) -> (Bake, f64) {
    let t = Instant::now();
    let gltf = penumbra::load::from_bytes(glb.to_vec(), Path::new(name)).expect("parses");
    let parse = t.elapsed().as_secs_f64();
    let bake = penumbra::bake(&gltf, &BakeOptions::default(), progress).expect("bakes");
    (bake, parse)
}

/// A bake longer than this is not repeated (to keep the whole run within a few minutes).
const LONG_BAKE: Duration = Duration::from_secs(10);

/// The best of `reps` bakes (one if it takes over [`LONG_BAKE`]), stage by stage: the last
/// bake, the stage times and the time of the direct light within `solve`.
fn timed_bakes(name: &str, glb: &[u8], reps: usize) -> (Bake, [f64; 7], f64) {
    let mut best = [f64::INFINITY; 7];
    let mut direct = f64::INFINITY;
    let mut last = None;
    for _ in 0..reps {
        let started = Instant::now();
        let (bake, parse) = bake_once(name, glb, &|_, _, _| {});
        let long = started.elapsed() > LONG_BAKE;
        let t = &bake.stats.timings_s;
        let s = [
            parse + t.load,
            t.visibility,
            t.discontinuity,
            t.mesh,
            t.solve,
            t.atlas,
            t.lightmap,
        ];
        for (b, s) in best.iter_mut().zip(s) {
            *b = b.min(s);
        }
        direct = direct.min(bake.stats.solve.direct.seconds);
        last = Some(bake);
        if long {
            break;
        }
    }
    (last.expect("reps >= 1"), best, direct)
}

/// What [`recording_bake`] returns: the sampled rays, the rays per phase, the total counts and
/// the lightmap.
type Recording = (
    Vec<RecordedRay>,
    Vec<(&'static str, RayCounts)>,
    RayCounts,
    Vec<DVec3>,
);

/// Bakes with the recorder on. Returns the sampled rays, the rays per phase (the ray-casting
/// stages, `solve` split after the direct light at the vertices), the total counts and the
/// lightmap's texels (recording must not change them).
fn recording_bake(name: &str, glb: &[u8], cap: usize) -> Recording {
    // Counter snapshots at phase boundaries, taken from the progress callback: a stage's
    // (0, 1) call marks its start; "direct light" reaching its total marks the end of the
    // direct light (every vertex is done, so every one of its rays is cast).
    let marks: Mutex<Vec<(&'static str, RayCounts)>> = Mutex::new(Vec::new());
    let progress = |stage: &str, done: u64, total: u64| {
        let phase = match stage {
            "direct light" if done == total => "solve: indirect",
            s if done == 0 && total == 1 => match STAGES.iter().find(|(n, _)| *n == s) {
                Some(("solve", _)) => "solve: direct",
                Some((n, _)) => n,
                None => return,
            },
            _ => return,
        };
        let mut m = marks.lock().unwrap();
        if m.iter().all(|(p, _)| *p != phase) {
            m.push((phase, visibility::recorded_counts()));
        }
    };
    visibility::record_rays(cap);
    let (bake, _) = bake_once(name, glb, &progress);
    let (rays, total) = visibility::take_recorded_rays();
    let mut marks = marks.into_inner().unwrap();
    marks.push(("end", total));
    let phases = marks
        .windows(2)
        .map(|w| (w[0].0, w[1].1.since(&w[0].1)))
        .filter(|(_, c)| c.rays() + c.of(Query::Box) > 0)
        .collect();
    (rays, phases, total, bake.lightmap.texels)
}

/// The plain obvhs setup: the BVH over the scene's polygon triangles, relative to the centre
/// of the scene's bounds, in f32 (as `visibility.rs` builds it).
struct Plain<B> {
    bvh: B,
    /// Triangles in BVH primitive order.
    tris: Vec<Triangle>,
    /// Polygon of each BVH primitive.
    polygons: Vec<u32>,
}

fn scene_triangles(scene: &Scene) -> (DVec3, Vec<Triangle>, Vec<u32>) {
    let center = if scene.triangles.is_empty() {
        DVec3::ZERO
    } else {
        (scene.bounds_min + scene.bounds_max) * 0.5
    };
    let f = |p: DVec3| Vec3A::from((p - center).as_vec3());
    let (tris, polygons) = scene
        .triangles
        .iter()
        .filter_map(|t| {
            let p = t.polygon?;
            let tri = Triangle {
                v0: f(t.p[0]),
                v1: f(t.p[1]),
                v2: f(t.p[2]),
            };
            Some((tri, p as u32))
        })
        .unzip();
    (center, tris, polygons)
}

fn reorder(indices: &[u32], tris: &[Triangle], polygons: &[u32]) -> (Vec<Triangle>, Vec<u32>) {
    indices
        .iter()
        .map(|&i| (tris[i as usize], polygons[i as usize]))
        .unzip()
}

fn plain_bvh2(scene: &Scene) -> (DVec3, Plain<Bvh2>) {
    let (center, tris, polygons) = scene_triangles(scene);
    let bvh = obvhs::bvh2::builder::build_bvh2_from_tris(
        &tris,
        visibility::BVH_BUILD,
        &mut Duration::default(),
    );
    let (tris, polygons) = reorder(&bvh.primitive_indices, &tris, &polygons);
    (
        center,
        Plain {
            bvh,
            tris,
            polygons,
        },
    )
}

fn plain_cwbvh(scene: &Scene) -> Plain<CwBvh> {
    let (_, tris, polygons) = scene_triangles(scene);
    let bvh = obvhs::cwbvh::builder::build_cwbvh_from_tris(
        &tris,
        visibility::BVH_BUILD,
        &mut Duration::default(),
    );
    let (tris, polygons) = reorder(&bvh.primitive_indices, &tris, &polygons);
    Plain {
        bvh,
        tris,
        polygons,
    }
}

/// The ray as obvhs takes it.
fn obvhs_ray(r: &RecordedRay) -> Ray {
    Ray::new(r.origin.into(), r.dir.into(), r.tmin, r.tmax)
}

/// The any-hit test shared by both plain loops: triangles of the skipped polygons never block.
#[inline(always)]
fn skipping<'a>(
    tris: &'a [Triangle],
    polygons: &'a [u32],
    skip: [u32; 2],
) -> impl Fn(&Ray, usize) -> f32 + 'a {
    move |ray, id| {
        if polygons[id] == skip[0] || polygons[id] == skip[1] {
            f32::INFINITY
        } else {
            tris[id].intersect(ray)
        }
    }
}

/// (b) The plain loop: one obvhs BVH2 query per ray; true on a hit (closest-hit) or when
/// blocked (any-hit).
fn cast_plain(p: &Plain<Bvh2>, r: &RecordedRay) -> bool {
    let ray = obvhs_ray(r);
    if r.query.closest_hit() {
        let mut hit = RayHit::none();
        p.bvh
            .ray_traverse(ray, &mut hit, |ray, id| p.tris[id].intersect(ray))
    } else {
        !p.bvh
            .ray_traverse_miss(ray, skipping(&p.tris, &p.polygons, r.skip))
    }
}

/// (c) The same over the 8-wide CWBVH.
fn cast_cwbvh(p: &Plain<CwBvh>, r: &RecordedRay) -> bool {
    let ray = obvhs_ray(r);
    if r.query.closest_hit() {
        let mut hit = RayHit::none();
        p.bvh
            .ray_traverse(ray, &mut hit, |ray, id| p.tris[id].intersect(ray))
    } else {
        !p.bvh
            .ray_traverse_miss(ray, skipping(&p.tris, &p.polygons, r.skip))
    }
}

/// A recorded ray as the stages pass it to [`Visibility`]: world coordinates in f64.
#[derive(Clone, Copy)]
struct ApiRay {
    origin: DVec3,
    dir: DVec3,
    /// `first_hit`'s `tmax`, or the far end of an `occluded_skipping` segment.
    tmax: f64,
    end: DVec3,
    skip: [usize; 2],
    query: Query,
}

fn api_ray(vis: &Visibility, r: &RecordedRay) -> ApiRay {
    let origin = vis.center() + r.origin.as_dvec3();
    let dir = r.dir.as_dvec3();
    // `occluded_skipping(a, b)` stops `epsilon` short of `b`.
    let end = origin + dir * (f64::from(r.tmax) + vis.epsilon());
    ApiRay {
        origin,
        dir,
        tmax: f64::from(r.tmax),
        end,
        skip: r.skip.map(|s| {
            if s == u32::MAX {
                usize::MAX
            } else {
                s as usize
            }
        }),
        query: r.query,
    }
}

/// (a) Through penumbra's API; true on a hit (closest-hit) or when blocked (any-hit).
fn cast_api(vis: &Visibility, r: &ApiRay) -> bool {
    match r.query {
        Query::FirstHit => vis.first_hit(r.origin, r.dir, r.tmax).is_some(),
        Query::Segment => vis.occluded_skipping(r.origin, r.end, r.skip),
        Query::Towards => !vis.unoccluded_towards(r.origin, r.dir, r.skip[0]),
        Query::Box => unreachable!("box queries are not recorded"),
    }
}

/// Rays per second of `cast` over `rays`, on one thread or on all; and the number of hits.
fn throughput<R: Sync>(rays: &[R], parallel: bool, cast: impl Fn(&R) -> bool + Sync) -> f64 {
    let t = Instant::now();
    let hits: usize = if parallel {
        rays.par_chunks(4096)
            .map(|c| c.iter().filter(|r| cast(black_box(r))).count())
            .sum()
    } else {
        rays.iter().filter(|r| cast(black_box(r))).count()
    };
    black_box(hits);
    rays.len() as f64 / t.elapsed().as_secs_f64()
}

fn replay(scene: &Scene, recorded: &[RecordedRay]) -> Replay {
    let vis = Visibility::new(scene);
    let (center, plain) = plain_bvh2(scene);
    assert_eq!(
        center,
        vis.center(),
        "the plain loop must use visibility.rs's frame"
    );
    let cw = plain_cwbvh(scene);
    let api: Vec<ApiRay> = recorded.iter().map(|r| api_ray(&vis, r)).collect();

    // Agreement, untimed.
    let a: Vec<bool> = api.par_iter().map(|r| cast_api(&vis, r)).collect();
    let p: Vec<bool> = recorded.par_iter().map(|r| cast_plain(&plain, r)).collect();
    let c: Vec<bool> = recorded.par_iter().map(|r| cast_cwbvh(&cw, r)).collect();
    let differ = |x: &[bool], y: &[bool]| x.iter().zip(y).filter(|(x, y)| x != y).count();
    let bake: Vec<bool> = recorded.iter().map(|r| r.hit).collect();
    let count = |x: &[bool]| x.iter().filter(|&&h| h).count();

    let mut out = Replay {
        sample: recorded.len(),
        closest: recorded.iter().filter(|r| r.query.closest_hit()).count(),
        hits_bake: count(&bake),
        hits_api: count(&a),
        hits_plain: count(&p),
        hits_cw: count(&c),
        api_vs_plain: differ(&a, &p),
        api_vs_bake: differ(&a, &bake),
        cw_vs_plain: differ(&c, &p),
        ..Default::default()
    };
    if recorded.is_empty() {
        return out;
    }
    // Best of 3, the three loops interleaved so that noise hits them alike.
    for parallel in [false, true] {
        let (mut ba, mut bp, mut bc) = (0.0f64, 0.0f64, 0.0f64);
        for _ in 0..3 {
            ba = ba.max(throughput(&api, parallel, |r| cast_api(&vis, r)));
            bp = bp.max(throughput(recorded, parallel, |r| cast_plain(&plain, r)));
            bc = bc.max(throughput(recorded, parallel, |r| cast_cwbvh(&cw, r)));
        }
        if parallel {
            (out.api_n, out.plain_n, out.cw_n) = (ba, bp, bc);
        } else {
            (out.api_1, out.plain_1, out.cw_1) = (ba, bp, bc);
        }
    }
    out
}

// The report.

/// The 1-minute load average (Linux), to tell a quiet machine from a busy one.
fn loadavg() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|s| s.split_whitespace().next().map(str::to_string))
        .unwrap_or_else(|| "n/a".into())
}

fn report(rows: &[Row], o: &Options, threads: usize, load: &str, wall: Duration) -> String {
    let mut s = String::new();
    let w = &mut s;
    let _ = writeln!(w, "# Stage benchmark\n");
    let _ = writeln!(
        w,
        "`cargo bench --bench stages`, {} (UTC), {threads} threads (load average {load}), \
         default bake options (discontinuity mesher, budget 20000, 1024² lightmap); best of {} \
         bakes (one when a bake takes over {} s); at most {} rays replayed per scene; whole run \
         {:.0} s.\n",
        today(),
        o.reps,
        LONG_BAKE.as_secs(),
        o.rays,
        wall.as_secs_f64()
    );

    // Stage times.
    let _ = writeln!(w, "## Stage times (s)\n");
    let _ = write!(w, "| scene | triangles | polygons | elements |");
    for (_, title) in STAGES {
        let _ = write!(w, " {title} |");
    }
    let _ = writeln!(w, " total |");
    let _ = writeln!(w, "|---|--:|--:|--:|{}--:|", "--:|".repeat(STAGES.len()));
    for r in rows {
        let _ = write!(
            w,
            "| {} | {} | {} | {} |",
            r.name, r.triangles, r.polygons, r.elements
        );
        for t in r.stage_s {
            let _ = write!(w, " {} |", secs(t));
        }
        let _ = writeln!(w, " {} |", secs(r.stage_s.iter().sum()));
    }
    let _ = writeln!(
        w,
        "\n*load* is the glb parse plus the scene build; *total* the sum of the stages (no \
         write). Of *solve*, the direct light at the vertices took: {}.\n",
        rows.iter()
            .map(|r| format!("{} {} s", r.name, secs(r.direct_s)))
            .collect::<Vec<_>>()
            .join(", ")
    );

    // Growth.
    let grids: Vec<&Row> = rows
        .iter()
        .filter(|r| r.name.starts_with("box grid"))
        .collect();
    let _ = writeln!(w, "## Growth from one grid to the next\n");
    let _ = writeln!(
        w,
        "Each cell: the ratio of times, and `k` in `time ∝ triangles^k` (k = 1: linear in the \
         input). Times under 5 ms are too short to read (–).\n"
    );
    let _ = write!(w, "| step | triangles × | elements × |");
    for (_, title) in STAGES {
        let _ = write!(w, " {title} |");
    }
    let _ = writeln!(w, " total |");
    let _ = writeln!(w, "|---|--:|--:|{}--:|", "--:|".repeat(STAGES.len()));
    for pair in grids.windows(2) {
        let (a, b) = (pair[0], pair[1]);
        let n = b.triangles as f64 / a.triangles as f64;
        let cell = |ta: f64, tb: f64| {
            if ta < 0.005 || tb < 0.005 {
                "–".to_string()
            } else {
                format!("{:.1}× (k {:.2})", tb / ta, (tb / ta).ln() / n.ln())
            }
        };
        let _ = write!(
            w,
            "| {} → {} | {:.2} | {:.2} |",
            a.name.trim_start_matches("box grid "),
            b.name.trim_start_matches("box grid "),
            n,
            b.elements as f64 / a.elements as f64
        );
        for (ta, tb) in a.stage_s.iter().zip(&b.stage_s) {
            let _ = write!(w, " {} |", cell(*ta, *tb));
        }
        let _ = writeln!(
            w,
            " {} |",
            cell(a.stage_s.iter().sum(), b.stage_s.iter().sum())
        );
    }

    // Rays per stage.
    let _ = writeln!(w, "\n## Rays cast by each stage\n");
    let _ = writeln!(
        w,
        "Counted by the recorder in a separate bake. *closest* = `first_hit`, *segment* = \
         `occluded`/`occluded_skipping`, *towards* = `unoccluded_towards` (any-hit); *box* = \
         `triangles_overlapping` queries (not rays). *effective* = the phase's rays / its wall \
         time; *ray share* = the time the plain all-thread loop needs for those rays / the \
         phase's wall time (how ray-bound the phase is).\n"
    );
    let _ = writeln!(
        w,
        "| scene | phase | rays | closest | segment | towards | box | time (s) | effective Mrays/s | ray share |"
    );
    let _ = writeln!(w, "|---|---|--:|--:|--:|--:|--:|--:|--:|--:|");
    for r in rows {
        for (phase, c) in &r.rays {
            let t = phase_time(r, phase);
            let share = c.rays() as f64 / r.replay.plain_n / t;
            let _ = writeln!(
                w,
                "| {} | {phase} | {} | {} | {} | {} | {} | {} | {:.2} | {:.0}% |",
                r.name,
                c.rays(),
                c.of(Query::FirstHit),
                c.of(Query::Segment),
                c.of(Query::Towards),
                c.of(Query::Box),
                secs(t),
                c.rays() as f64 / t / 1e6,
                100.0 * share
            );
        }
    }

    // Replay.
    let _ = writeln!(
        w,
        "\n## Replay: penumbra's `Visibility` API against a plain obvhs loop\n"
    );
    let _ = writeln!(
        w,
        "Mrays/s over the sampled rays; best of 3, interleaved. *API* = `Visibility` from world \
         f64 coordinates; *plain* = obvhs `Bvh2` traversal of the same f32 rays, built here the \
         way `visibility.rs` builds it; *CWBVH* = the same loop over obvhs's 8-wide BVH \
         (reference only: it misses near-origin hits).\n"
    );
    let _ = writeln!(
        w,
        "| scene | rays cast | replayed | closest-hit | API 1T | plain 1T | API/plain 1T | API {threads}T | plain {threads}T | API/plain {threads}T | CWBVH 1T | CWBVH {threads}T |"
    );
    let _ = writeln!(w, "|---|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|");
    for r in rows {
        let p = &r.replay;
        let _ = writeln!(
            w,
            "| {} | {} | {} | {:.0}% | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} |",
            r.name,
            r.total_rays.rays(),
            p.sample,
            100.0 * p.closest as f64 / p.sample.max(1) as f64,
            p.api_1 / 1e6,
            p.plain_1 / 1e6,
            p.api_1 / p.plain_1,
            p.api_n / 1e6,
            p.plain_n / 1e6,
            p.api_n / p.plain_n,
            p.cw_1 / 1e6,
            p.cw_n / 1e6,
        );
    }
    let _ = writeln!(
        w,
        "\n### Agreement (hits or blocked, of the replayed rays)\n"
    );
    let _ = writeln!(
        w,
        "*bake* = the answers the queries gave in the recording bake. With the recorder on, the \
         lightmap came out bit-identical to the timed bake's: {}.\n",
        rows.iter()
            .map(|r| format!(
                "{} {}",
                r.name,
                if r.recording_identical {
                    "yes"
                } else {
                    "**no**"
                }
            ))
            .collect::<Vec<_>>()
            .join(", ")
    );
    let _ = writeln!(
        w,
        "| scene | bake | API | plain | API ≠ plain | API ≠ bake | CWBVH | CWBVH ≠ plain |"
    );
    let _ = writeln!(w, "|---|--:|--:|--:|--:|--:|--:|--:|");
    for r in rows {
        let p = &r.replay;
        let _ = writeln!(
            w,
            "| {} | {} | {} | {} | {} | {} | {} | {} |",
            r.name,
            p.hits_bake,
            p.hits_api,
            p.hits_plain,
            p.api_vs_plain,
            p.api_vs_bake,
            p.hits_cw,
            p.cw_vs_plain
        );
    }
    s
}

/// Wall time of a phase of [`recording_bake`], from the timed bakes.
fn phase_time(r: &Row, phase: &str) -> f64 {
    let stage = |name: &str| {
        STAGES
            .iter()
            .position(|(n, _)| *n == name)
            .map_or(f64::NAN, |i| r.stage_s[i])
    };
    match phase {
        "solve: direct" => r.direct_s,
        "solve: indirect" => stage("solve") - r.direct_s,
        p => stage(p),
    }
}

fn secs(t: f64) -> String {
    if t < 0.01 {
        format!("{t:.4}")
    } else if t < 10.0 {
        format!("{t:.3}")
    } else {
        format!("{t:.1}")
    }
}

/// Today's date (UTC), `YYYY-MM-DD` (Howard Hinnant's `civil_from_days`).
fn today() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let z = (secs / 86_400) as i64 + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!("{y:04}-{m:02}-{d:02}")
}
