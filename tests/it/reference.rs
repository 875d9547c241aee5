//! The Monte Carlo reference (`penumbra::reference`) against known answers, within its own
//! reported standard error.

use crate::{no_progress, scratch};
use glam::DVec3;
use penumbra::BakeOptions;
use penumbra::fixtures;
use penumbra::load::{self, Gltf};
use penumbra::reference::{self, ReferenceMap, ReferenceOptions, TexelLayout};
use penumbra::scene::Scene;
use penumbra::solve::Direct;
use penumbra::visibility::Visibility;

/// Bakes `bytes` with small options into a scratch dir and reads the baked glb back.
fn baked(bytes: &[u8], name: &str) -> Gltf {
    baked_with(bytes, name, penumbra::DoubleSided::Separate, 64)
}

/// [`baked`], with the back sides of double-sided surfaces written as `double_sided` says
/// (`Shared`: they take no texels, which leaves the others more).
fn baked_with(
    bytes: &[u8],
    name: &str,
    double_sided: penumbra::DoubleSided,
    resolution: u32,
) -> Gltf {
    let dir = scratch(&format!("reference-{name}"));
    let (input, output) = (dir.join("in.glb"), dir.join("out.glb"));
    std::fs::write(&input, bytes).unwrap();
    let options = BakeOptions {
        budget: Some(2000),
        resolution: Some(resolution),
        double_sided,
        ..Default::default()
    };
    penumbra::bake_file(
        &input,
        &penumbra::OutputFiles::glb(&output),
        &options,
        no_progress(),
    )
    .expect("bake succeeds");
    load::read(&output).expect("baked file reads")
}

struct Run {
    scene: Scene,
    layout: TexelLayout,
    map: ReferenceMap,
}

fn run(gltf: &Gltf, options: &ReferenceOptions) -> Run {
    let scene = load::scene(gltf).unwrap();
    let vis = Visibility::new(&scene);
    let layout = reference::texel_layout(gltf, &scene, &vis, options.supersample).unwrap();
    let map = reference::reference_with(&scene, &vis, &layout, options);
    Run { scene, layout, map }
}

/// Per-channel z-scores `|ref - exact| / stderr` of the covered texels (a texel with zero
/// error must match to `1e-9` relative, and then scores 0).
fn z_scores(map: &ReferenceMap, exact: &[Option<DVec3>]) -> Vec<f64> {
    let mut z = Vec::new();
    for (i, e) in exact.iter().enumerate() {
        let Some(e) = e else { continue };
        for c in 0..3 {
            let (got, se) = (map.mean[i][c], map.std_error[i][c]);
            let diff = (got - e[c]).abs();
            let tiny = 1e-9 * e[c].abs().max(1e-12);
            z.push(if diff <= tiny { 0.0 } else { diff / se });
        }
    }
    z
}

fn report(name: &str, z: &[f64]) -> (f64, f64) {
    let within3 = z.iter().filter(|&&z| z <= 3.0).count() as f64 / z.len() as f64;
    let max = z.iter().copied().fold(0.0, f64::max);
    eprintln!(
        "{name}: {} values, fraction within 3 stderr {within3:.4}, max |z| {max:.2}",
        z.len()
    );
    (within3, max)
}

/// A point light over a floor, nothing else: H = I h / r³ at each sub-sample point, and the
/// estimate is exact (the only light is punctual, indirect rays escape), so its standard error
/// is 0 and it must match to rounding.
#[test]
fn point_light_matches_inverse_square_cosine() {
    let gltf = baked(&fixtures::point_light(), "point");
    let r = run(
        &gltf,
        &ReferenceOptions {
            spp: 16,
            ..Default::default()
        },
    );
    let light = DVec3::new(0.0, 2.0, 0.0);
    let exact: Vec<Option<DVec3>> = r
        .layout
        .samples
        .iter()
        .map(|pts| {
            (!pts.is_empty()).then(|| {
                let h: f64 = pts
                    .iter()
                    .map(|sp| {
                        let r = light.distance(sp.p);
                        10.0 * (light.y - sp.p.y) / (r * r * r)
                    })
                    .sum();
                DVec3::splat(h / pts.len() as f64)
            })
        })
        .collect();
    let covered = exact.iter().flatten().count();
    assert!(covered > 500, "only {covered} covered texels");
    let z = z_scores(&r.map, &exact);
    let (within3, max) = report("point light", &z);
    assert_eq!(within3, 1.0, "max |z| {max}");
    assert!(r.map.std_error.iter().all(|e| *e == DVec3::ZERO));
    // Uncovered texels are 0.
    for (i, c) in r.map.coverage.iter().enumerate() {
        if *c == 0.0 {
            assert_eq!(r.map.mean[i], DVec3::ZERO);
        }
    }
}

/// The furnace: a closed box, every face rho = 0.5 and exitance M = 1, so H = M/(1-rho) = 2
/// everywhere: direct 1 by next-event estimation on the faces, the rest by paths that only end
/// by Russian roulette.
#[test]
fn furnace_gives_two_within_standard_error() {
    let gltf = baked(&fixtures::furnace_box_with(0.5, 1.0), "furnace");
    let r = run(
        &gltf,
        &ReferenceOptions {
            spp: 64,
            seed: 7,
            ..Default::default()
        },
    );
    let exact: Vec<Option<DVec3>> = r
        .layout
        .samples
        .iter()
        .map(|pts| (!pts.is_empty()).then_some(DVec3::splat(2.0)))
        .collect();
    let z = z_scores(&r.map, &exact);
    let (within3, max) = report("furnace", &z);
    // Per texel, the standard error comes from 4 paths per sub-sample: a noisy estimate of a
    // skewed distribution, so a few texels score beyond 3 (and Russian roulette makes it skewed).
    assert!(within3 > 0.97, "fraction within 3 stderr {within3}");
    assert!(max < 8.0, "max |z| {max}");
    // Aggregated over all texels: the mean of the means, against its own standard error.
    let (mut sum, mut var, mut n) = (0.0, 0.0, 0.0);
    for (i, c) in r.map.coverage.iter().enumerate() {
        if *c > 0.0 {
            sum += r.map.mean[i].x;
            var += r.map.std_error[i].x.powi(2);
            n += 1.0;
        }
    }
    let (mean, se) = (sum / n, var.sqrt() / n);
    eprintln!("furnace: mean H {mean:.5} +- {se:.5} over {n} texels");
    assert!((mean - 2.0).abs() < 4.0 * se, "mean H {mean} +- {se}");
    assert!(se < 0.01, "standard error {se} too large to test anything");
}

/// The square occluder's floor, direct light only (`bounces_max: Some(0)`): the reference
/// matches the exact (backprojected) direct irradiance of `solve::Direct` averaged over each
/// texel's sub-samples, in the texels along z = 0 (umbra, penumbra and lit floor).
#[test]
fn square_occluder_direct_matches_exact_profile() {
    // The occluder is double-sided: its back takes no texels. A 96 x 96 page, so that the
    // floor has a row or two of texels inside |z| < 0.2 however the packer places its chart.
    let gltf = baked_with(
        &fixtures::square_occluder(),
        "square",
        penumbra::DoubleSided::Shared,
        96,
    );
    let options = ReferenceOptions {
        spp: 64,
        seed: 3,
        bounces_max: Some(0),
        ..Default::default()
    };
    let r = run(&gltf, &options);
    let vis = Visibility::new(&r.scene);
    let direct = Direct::new(&r.scene, &vis, 64);
    let floor = r
        .scene
        .polygons
        .iter()
        .position(|p| r.scene.materials[p.material].name == "floor")
        .unwrap();
    let exact: Vec<Option<DVec3>> = r
        .layout
        .samples
        .iter()
        .map(|pts| {
            let near = !pts.is_empty()
                && pts
                    .iter()
                    .all(|sp| sp.polygon == floor && sp.p.z.abs() < 0.2 && sp.p.x.abs() < 2.5);
            near.then(|| {
                pts.iter().map(|sp| direct.irradiance(sp)).sum::<DVec3>() / pts.len() as f64
            })
        })
        .collect();
    let covered = exact.iter().flatten().count();
    assert!(covered > 30, "only {covered} texels along z = 0");
    let z = z_scores(&r.map, &exact);
    let (within3, max) = report("square occluder", &z);
    assert!(within3 > 0.97, "fraction within 3 stderr {within3}");
    assert!(max < 8.0, "max |z| {max}");

    // Its emitter visibility (the region classifier of `penumbra compare`) against the exact
    // visible fraction of the direct light: exactly 1 in the lit floor, 0 in the umbra, and
    // within the binomial noise of the estimate in the penumbra.
    let (mut lit, mut umbra, mut penumbra) = (0, 0, 0);
    for (i, pts) in r.layout.samples.iter().enumerate() {
        if exact[i].is_none() {
            continue;
        }
        let visible: f64 = pts.iter().map(|sp| direct.irradiance(sp).x).sum();
        let unoccluded: f64 = pts
            .iter()
            .map(|sp| {
                direct
                    .emitters
                    .iter()
                    .map(|e| std::f64::consts::PI * e.radiance.x * e.form_factor(sp.p, sp.n))
                    .sum::<f64>()
            })
            .sum();
        let want = visible / unoccluded;
        let got = r.map.visibility[i].expect("the light faces the floor") as f64;
        if want > 1.0 - 1e-9 {
            lit += 1;
            assert_eq!(got, 1.0, "texel {i}: lit, yet some shadow ray was blocked");
        } else if want < 1e-9 {
            umbra += 1;
            assert_eq!(got, 0.0, "texel {i}: umbra, yet some shadow ray was free");
        } else {
            penumbra += 1;
            let sigma = (want * (1.0 - want) / options.spp as f64).sqrt();
            assert!(
                (got - want).abs() < 5.0 * sigma + 0.02,
                "texel {i}: visibility {got} against {want}"
            );
        }
    }
    println!("visibility: {lit} lit, {penumbra} penumbra, {umbra} umbra texels");
    assert!(lit > 5 && umbra > 5 && penumbra > 5);
}

/// The result depends on the seed and the texel, not on the thread count.
#[test]
fn deterministic_across_thread_counts() {
    let gltf = baked(&fixtures::square_occluder(), "threads");
    let options = ReferenceOptions {
        spp: 4,
        ..Default::default()
    };
    let with = |n: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .unwrap()
            .install(|| reference::reference(&gltf, &options).unwrap())
    };
    let (a, b) = (with(1), with(3));
    assert_eq!(a, b);
    let c = reference::reference(
        &gltf,
        &ReferenceOptions {
            seed: 1,
            ..options.clone()
        },
    )
    .unwrap();
    assert_ne!(a.mean, c.mean);
}

/// A file that was never baked has no lightmap layout: a clear error, not a panic.
#[test]
fn unbaked_file_is_an_error() {
    let gltf = crate::parse(&fixtures::point_light(), "plain.glb");
    let err = reference::reference(&gltf, &ReferenceOptions::default()).unwrap_err();
    assert!(err.to_string().contains("MOZ_lightmap"), "{err}");
}
