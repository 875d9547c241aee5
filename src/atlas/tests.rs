use super::packed::ChartBox;
use super::*;
use std::time::Instant;

/// An owned test mesh.
#[derive(Debug, Clone, Default)]
struct TestMesh {
    positions: Vec<[f32; 3]>,
    indices: Vec<u32>,
}

impl TestMesh {
    fn input(&self) -> AtlasInput<'_> {
        AtlasInput {
            positions: &self.positions,
            indices: &self.indices,
        }
    }
}

fn inputs(meshes: &[TestMesh]) -> Vec<AtlasInput<'_>> {
    meshes.iter().map(TestMesh::input).collect()
}

/// A `w` x `h` quad in the plane z = `z`, lower corner at (`x`, `y`): two triangles.
fn quad(x: f32, y: f32, z: f32, w: f32, h: f32) -> TestMesh {
    TestMesh {
        positions: vec![[x, y, z], [x + w, y, z], [x + w, y + h, z], [x, y + h, z]],
        indices: vec![0, 1, 2, 0, 2, 3],
    }
}

/// A cube of side `size` at `origin`, 8 shared corners, 12 outward triangles.
fn cube(origin: [f32; 3], size: f32) -> TestMesh {
    let positions = (0..8)
        .map(|i| [0, 1, 2].map(|axis| origin[axis] + size * ((i >> axis) & 1) as f32))
        .collect();
    // Corner i has x = bit 0, y = bit 1, z = bit 2, as `BOX_FACES` numbers them.
    let indices = crate::geometry::BOX_FACES
        .iter()
        .flat_map(|q| [q[0], q[1], q[2], q[0], q[2], q[3]])
        .collect();
    TestMesh { positions, indices }
}

/// A connected `n` x `n` grid of quads (2n² triangles) over `size` x `size`, with a height
/// bump of amplitude `bump`.
fn grid(n: u32, size: f32, bump: f32) -> TestMesh {
    let mut positions = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            let x = i as f32 / n as f32 * size;
            let y = j as f32 / n as f32 * size;
            positions.push([x, y, bump * (x * 3.0).sin() * (y * 2.0).cos()]);
        }
    }
    let w = n + 1;
    let mut indices = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let a = j * w + i;
            indices.extend_from_slice(&[a, a + 1, a + w + 1, a, a + w + 1, a + w]);
        }
    }
    TestMesh { positions, indices }
}

fn options(texels_per_unit: Option<f32>, resolution: Option<u32>, padding: u32) -> AtlasOptions {
    AtlasOptions {
        texels_per_unit,
        resolution,
        padding,
        page_size: DEFAULT_PAGE_SIZE,
    }
}

/// Checks the mapping back to the inputs and the bounds: output triangle k comes from input
/// triangle k, corner by corner; every UV is inside the page.
fn check_mapping(inputs: &[AtlasInput<'_>], atlas: &Atlas) {
    assert_eq!(atlas.meshes.len(), inputs.len());
    for (m, (input, mesh)) in inputs.iter().zip(&atlas.meshes).enumerate() {
        assert_eq!(mesh.xref.len(), mesh.uv.len(), "mesh {m}");
        assert_eq!(mesh.indices.len(), input.indices.len(), "mesh {m}");
        for (k, (o, i)) in mesh.indices.iter().zip(input.indices).enumerate() {
            assert_eq!(mesh.xref[*o as usize], *i, "mesh {m} index {k}");
        }
        for uv in &mesh.uv {
            assert!(
                (0.0..=atlas.width as f32).contains(&uv[0])
                    && (0.0..=atlas.height as f32).contains(&uv[1]),
                "mesh {m}: UV {uv:?} outside {}x{}",
                atlas.width,
                atlas.height
            );
        }
    }
}

type Uv = [f32; 2];

fn cross(o: Uv, a: Uv, b: Uv) -> f32 {
    (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
}

fn tri_area(t: &[Uv; 3]) -> f32 {
    0.5 * cross(t[0], t[1], t[2])
}

fn point_segment_distance(p: Uv, a: Uv, b: Uv) -> f32 {
    let ab = [b[0] - a[0], b[1] - a[1]];
    let ap = [p[0] - a[0], p[1] - a[1]];
    let len2 = ab[0] * ab[0] + ab[1] * ab[1];
    let t = if len2 > 0.0 {
        ((ap[0] * ab[0] + ap[1] * ab[1]) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let d = [ap[0] - t * ab[0], ap[1] - t * ab[1]];
    (d[0] * d[0] + d[1] * d[1]).sqrt()
}

fn segment_distance(p: [Uv; 2], q: [Uv; 2]) -> f32 {
    let d1 = cross(q[0], q[1], p[0]);
    let d2 = cross(q[0], q[1], p[1]);
    let d3 = cross(p[0], p[1], q[0]);
    let d4 = cross(p[0], p[1], q[1]);
    if d1 * d2 < 0.0 && d3 * d4 < 0.0 {
        return 0.0;
    }
    point_segment_distance(p[0], q[0], q[1])
        .min(point_segment_distance(p[1], q[0], q[1]))
        .min(point_segment_distance(q[0], p[0], p[1]))
        .min(point_segment_distance(q[1], p[0], p[1]))
}

fn inside(p: Uv, t: &[Uv; 3]) -> bool {
    let s = [0, 1, 2].map(|k| cross(t[k], t[(k + 1) % 3], p));
    s.iter().all(|&c| c >= 0.0) || s.iter().all(|&c| c <= 0.0)
}

/// Distance between two UV triangles: 0 if they overlap.
fn triangle_distance(a: &[Uv; 3], b: &[Uv; 3]) -> f32 {
    if a.iter().any(|&p| inside(p, b)) || b.iter().any(|&p| inside(p, a)) {
        return 0.0;
    }
    let mut d = f32::INFINITY;
    for i in 0..3 {
        for j in 0..3 {
            d = d.min(segment_distance(
                [a[i], a[(i + 1) % 3]],
                [b[j], b[(j + 1) % 3]],
            ));
        }
    }
    d
}

/// The UV triangles of the atlas that cover area, each with its chart (charts are the
/// connected components of output vertices; output vertices are never shared across charts).
fn charted_triangles(atlas: &Atlas) -> Vec<(usize, [Uv; 3])> {
    let mut out = Vec::new();
    let mut chart_base = 0;
    for mesh in &atlas.meshes {
        let n = mesh.uv.len();
        let mut parent: Vec<usize> = (0..n).collect();
        fn find(parent: &mut [usize], mut i: usize) -> usize {
            while parent[i] != i {
                parent[i] = parent[parent[i]];
                i = parent[i];
            }
            i
        }
        for t in mesh.indices.chunks_exact(3) {
            let r0 = find(&mut parent, t[0] as usize);
            for &v in &t[1..] {
                let r = find(&mut parent, v as usize);
                parent[r] = r0;
            }
        }
        for t in mesh.indices.chunks_exact(3) {
            let uv = [0, 1, 2].map(|k| mesh.uv[t[k] as usize]);
            if tri_area(&uv).abs() > 1e-6 {
                out.push((chart_base + find(&mut parent, t[0] as usize), uv));
            }
        }
        chart_base += n;
    }
    out
}

/// Checks that no two charts overlap and that triangles within a chart keep one winding (no
/// flipped triangles); returns the smallest UV distance between triangles of different
/// charts, in texels, and the number of charts.
fn check_charts(atlas: &Atlas) -> (f32, usize) {
    let tris = charted_triangles(atlas);
    let mut winding = std::collections::HashMap::new();
    for (chart, t) in &tris {
        let sign = tri_area(t) > 0.0;
        assert_eq!(
            *winding.entry(*chart).or_insert(sign),
            sign,
            "flipped triangle in chart"
        );
    }
    let mut min = f32::INFINITY;
    for (i, (ca, a)) in tris.iter().enumerate() {
        for (cb, b) in &tris[i + 1..] {
            if ca != cb {
                min = min.min(triangle_distance(a, b));
            }
        }
    }
    assert!(min > 0.0, "charts overlap");
    (min, winding.len())
}

/// The UV area, in texels², of one output mesh.
fn uv_area(mesh: &AtlasMesh) -> f32 {
    mesh.indices
        .chunks_exact(3)
        .map(|t| tri_area(&[0, 1, 2].map(|k| mesh.uv[t[k] as usize])).abs())
        .sum()
}

#[test]
fn quads_and_cube_are_charted_without_overlap_and_with_padding() {
    let meshes = [
        quad(0.0, 0.0, 0.0, 1.0, 1.0),
        quad(5.0, 0.0, 1.0, 1.0, 1.0),
        cube([2.0, 2.0, 2.0], 1.0),
    ];
    let inputs = inputs(&meshes);
    for padding in [2, 4] {
        let atlas = pack(&inputs, &options(Some(16.0), None, padding)).unwrap();
        check_mapping(&inputs, &atlas);
        let (min, charts) = check_charts(&atlas);
        println!(
            "padding {padding}: {}x{} texels, {charts} charts, smallest gap between charts \
             {min:.3} texels",
            atlas.width, atlas.height
        );
        // Observed: exactly padding + 1 texels (xatlas dilates each chart by `padding`).
        assert!(min >= padding as f32, "gap {min} for padding {padding}");
        assert_eq!(atlas.texels_per_unit, 16.0);
        // Every input vertex is used by some output vertex; seams only add vertices.
        for (mesh, input) in atlas.meshes.iter().zip(&inputs) {
            assert!(mesh.xref.len() >= input.positions.len());
        }
    }
}

#[test]
fn fitting_density_solves_for_the_box_area_a_full_page_held() {
    // 100 charts of 10 x 10 texels, half of them on the first page: with 2 texels of
    // padding each takes (10 s + 3.5)² texels² at s times the density, and all of them
    // must take what 50 took at s = 1: 100 (10 s + 3.5)² = 50 × 13.5², s = 0.6046.
    let boxes: Vec<ChartBox> = (0..100)
        .map(|i| ChartBox {
            page: i / 50,
            width: 10.0,
            height: 10.0,
        })
        .collect();
    let full = boxes_area(boxes.iter().filter(|b| b.page == 0), 2);
    let s = fitting_density(&boxes, 20.0, 2, full).unwrap() / 20.0;
    let expected = ((50.0f64 * 13.5 * 13.5 / 100.0).sqrt() - 3.5) / 10.0;
    assert!(
        (f64::from(s) - expected).abs() < 1e-5,
        "{s} against {expected}"
    );
    // Charts so small that their padding alone overflows: no estimate.
    let specks: Vec<ChartBox> = (0..100)
        .map(|i| ChartBox {
            page: u32::from(i >= 30),
            width: 0.1,
            height: 0.1,
        })
        .collect();
    let full = boxes_area(specks.iter().filter(|b| b.page == 0), 2);
    assert_eq!(fitting_density(&specks, 20.0, 2, full), None);
}

#[test]
fn unit_quad_at_32_texels_per_unit_covers_about_32_by_32_texels() {
    let meshes = [quad(0.0, 0.0, 0.0, 1.0, 1.0)];
    let atlas = pack(&inputs(&meshes), &options(Some(32.0), None, 2)).unwrap();
    let area = uv_area(&atlas.meshes[0]);
    println!(
        "unit quad: {area} texels², atlas {}x{}",
        atlas.width, atlas.height
    );
    assert!((area - 1024.0).abs() <= 102.4, "{area}");
    assert_eq!(atlas.texels_per_unit, 32.0);
}

#[test]
fn a_chart_longer_than_1024_texels_keeps_its_density() {
    // xatlas's default maxChartSize (1024) would silently scale this 1280-texel wall down.
    let meshes = [quad(0.0, 0.0, 0.0, 40.0, 1.0)];
    let atlas = pack(&inputs(&meshes), &options(Some(32.0), None, 2)).unwrap();
    check_mapping(&inputs(&meshes), &atlas);
    let area = uv_area(&atlas.meshes[0]);
    assert!(
        atlas.width.max(atlas.height) >= 1280,
        "{}x{}",
        atlas.width,
        atlas.height
    );
    assert!((area / (40.0 * 1024.0) - 1.0).abs() < 0.05, "{area}");
}

#[test]
fn default_options_give_one_1024_page() {
    let meshes = [quad(0.0, 0.0, 0.0, 1.0, 1.0), cube([3.0, 0.0, 0.0], 2.0)];
    let inputs = inputs(&meshes);
    let atlas = pack(&inputs, &AtlasOptions::default()).unwrap();
    assert_eq!((atlas.width, atlas.height), (1024, 1024));
    check_mapping(&inputs, &atlas);
    check_charts(&atlas);
    println!("default options: {} texels per unit", atlas.texels_per_unit);
}

#[test]
fn too_many_charts_for_the_page_lower_the_density_until_one_page_holds_them() {
    let meshes: Vec<_> = (0..10)
        .map(|i| quad(2.0 * i as f32, 0.0, 0.0, 1.0, 1.0))
        .collect();
    let inputs = inputs(&meshes);
    let atlas = pack(&inputs, &options(Some(64.0), Some(128), 2)).unwrap();
    println!(
        "10 unit quads on 128²: {} texels per unit",
        atlas.texels_per_unit
    );
    assert_eq!((atlas.width, atlas.height), (128, 128));
    assert!(atlas.texels_per_unit < 64.0);
    check_mapping(&inputs, &atlas);
    check_charts(&atlas);
    // Density stays uniform: xatlas only rounds each chart up to whole texels.
    let tpu = atlas.texels_per_unit;
    for mesh in &atlas.meshes {
        let area = uv_area(mesh);
        assert!(
            area >= tpu * tpu * 0.999 && area <= (tpu + 1.0) * (tpu + 1.0),
            "{area}"
        );
    }
}

#[test]
fn with_a_fixed_density_charts_spill_onto_more_pages() {
    let meshes: Vec<_> = (0..10)
        .map(|i| quad(2.0 * i as f32, 0.0, 0.0, 1.0, 1.0))
        .collect();
    let inputs = inputs(&meshes);
    let opts = AtlasOptions {
        page_size: 128,
        ..options(Some(64.0), None, 2)
    };
    let atlas = pack(&inputs, &opts).unwrap();
    println!(
        "10 unit quads at 64 texels per unit on 128² pages: {} pages of {}x{}",
        atlas.pages, atlas.width, atlas.height
    );
    assert!(atlas.pages > 1);
    assert!(atlas.width <= 128 && atlas.height <= 128);
    assert_eq!(atlas.texels_per_unit, 64.0);
    check_mapping(&inputs, &atlas);
    let mut used = std::collections::BTreeSet::new();
    for mesh in &atlas.meshes {
        assert_eq!(mesh.page.len(), mesh.indices.len() / 3);
        assert!(mesh.page.iter().all(|&p| p < atlas.pages));
        used.extend(mesh.page.iter().copied());
        // Density kept: each unit quad covers about 64² texels.
        let area = uv_area(mesh);
        assert!((area / 4096.0 - 1.0).abs() < 0.05, "{area}");
    }
    assert_eq!(used.len(), atlas.pages as usize, "every page is used");
    // The same charts with a large page: one page.
    let one = pack(&inputs, &options(Some(64.0), None, 2)).unwrap();
    assert_eq!(one.pages, 1);
}

/// Charts that cannot fit a page at any density fail fast: at once when their padding
/// alone overflows it, else once every chart is at its smallest (not after halving the
/// density [`MAX_PACK_ATTEMPTS`] times).
#[test]
fn charts_that_fit_at_no_density_fail_within_a_few_packings() {
    // `n` separate 1 x 1 quads on a 32² page with 2 texels of padding: each takes at least
    // 3² texels² (200: 1 800, more than the page's 1 024), and at its smallest 4² (80:
    // 1 280, also more, though 80 x 3² = 720 is not).
    for (n, most) in [(200, 1), (80, 12)] {
        let meshes: Vec<TestMesh> = (0..n)
            .map(|i| quad(3.0 * (i % 20) as f32, 3.0 * (i / 20) as f32, 0.0, 1.0, 1.0))
            .collect();
        let err = pack(&inputs(&meshes), &options(None, Some(32), 2)).unwrap_err();
        println!("{n} quads: {err}");
        match err {
            AtlasError::DoesNotFit {
                resolution: 32,
                attempts,
                ..
            } => assert!(attempts <= most, "{attempts} packings for {n} quads"),
            err => panic!("{err}"),
        }
    }
    // 50 of them take 4² texels² each at their smallest (800 of the page's 1 024): they
    // fit, though not with 2-texel-wide charts (5² each, 1 250).
    let meshes: Vec<TestMesh> = (0..50)
        .map(|i| quad(3.0 * (i % 20) as f32, 3.0 * (i / 20) as f32, 0.0, 1.0, 1.0))
        .collect();
    let atlas = pack(&inputs(&meshes), &options(None, Some(32), 2)).unwrap();
    println!("50 quads: {} texels per unit", atlas.texels_per_unit);
}

#[test]
fn with_a_fixed_density_a_chart_larger_than_the_page_is_an_error() {
    let meshes = [quad(0.0, 0.0, 0.0, 4.0, 1.0)];
    let opts = AtlasOptions {
        page_size: 64,
        ..options(Some(32.0), None, 2)
    };
    let err = pack(&inputs(&meshes), &opts).unwrap_err();
    println!("{err}");
    assert!(
        matches!(err, AtlasError::ChartTooLarge { page_size: 64, .. }),
        "{err}"
    );
    assert!(err.to_string().contains("64x64"), "{err}");
}

#[test]
fn a_chart_larger_than_the_page_lowers_the_density() {
    let meshes = [quad(0.0, 0.0, 0.0, 4.0, 1.0)];
    let inputs = inputs(&meshes);
    let atlas = pack(&inputs, &options(Some(32.0), Some(64), 2)).unwrap();
    let tpu = atlas.texels_per_unit;
    println!("4x1 quad on 64²: {tpu} texels per unit");
    assert_eq!((atlas.width, atlas.height), (64, 64));
    assert!(4.0 * tpu <= 64.0);
    check_mapping(&inputs, &atlas);
    let area = uv_area(&atlas.meshes[0]);
    assert!(area >= 4.0 * tpu * tpu * 0.999 && area <= (4.0 * tpu + 1.0) * (tpu + 1.0));
}

#[test]
fn bad_inputs_are_errors() {
    let good = quad(0.0, 0.0, 0.0, 1.0, 1.0);
    let opts = AtlasOptions::default();

    let mut nan = good.clone();
    nan.positions[2][1] = f32::NAN;
    let err = pack(&[good.input(), nan.input()], &opts).unwrap_err();
    assert!(
        matches!(err, AtlasError::InvalidInput { mesh: 1, .. }),
        "{err}"
    );
    println!("{err}");

    let mut inf = good.clone();
    inf.positions[0][0] = f32::INFINITY;
    let err = pack(&[inf.input()], &opts).unwrap_err();
    assert!(
        matches!(err, AtlasError::InvalidInput { mesh: 0, .. }),
        "{err}"
    );

    let mut out_of_range = good.clone();
    out_of_range.indices[4] = 4;
    let err = pack(&[out_of_range.input()], &opts).unwrap_err();
    assert!(
        matches!(err, AtlasError::InvalidInput { mesh: 0, .. }),
        "{err}"
    );
    println!("{err}");

    let mut not_triangles = good.clone();
    not_triangles.indices.pop();
    let err = pack(&[not_triangles.input()], &opts).unwrap_err();
    assert!(
        matches!(err, AtlasError::InvalidInput { mesh: 0, .. }),
        "{err}"
    );
    println!("{err}");

    assert!(matches!(pack(&[], &opts), Err(AtlasError::Empty)));
    let empty = TestMesh::default();
    assert!(matches!(
        pack(&[empty.input()], &opts),
        Err(AtlasError::Empty)
    ));
    let degenerate = TestMesh {
        positions: vec![[0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]],
        indices: vec![0, 1, 2, 0, 0, 1],
    };
    assert!(matches!(
        pack(&[degenerate.input()], &opts),
        Err(AtlasError::Empty)
    ));

    for bad in [
        options(None, None, 1),
        options(Some(f32::NAN), None, 2),
        options(Some(0.0), None, 2),
        options(Some(-1.0), None, 2),
        options(None, Some(0), 2),
        options(None, Some(MAX_RESOLUTION + 1), 2),
        options(None, Some(4), 3),
    ] {
        let err = pack(&[good.input()], &bad).unwrap_err();
        assert!(
            matches!(err, AtlasError::InvalidOptions { .. }),
            "{bad:?}: {err}"
        );
    }
    let err = pack(&[good.input()], &options(Some(1e5), None, 2)).unwrap_err();
    assert!(matches!(err, AtlasError::TooLarge { .. }), "{err}");
    println!("{err}");
}

#[test]
fn empty_and_degenerate_parts_are_kept_in_place() {
    let empty = TestMesh {
        positions: vec![[0.0; 3]],
        indices: vec![],
    };
    let mut with_degenerate = quad(0.0, 0.0, 0.0, 1.0, 1.0);
    with_degenerate.indices.extend_from_slice(&[0, 1, 1]);
    let only_degenerate = TestMesh {
        positions: vec![[0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]],
        indices: vec![0, 1, 2, 2, 2, 0],
    };
    let meshes = [
        empty,
        with_degenerate,
        quad(3.0, 0.0, 0.0, 1.0, 1.0),
        only_degenerate,
    ];
    let inputs = inputs(&meshes);
    let atlas = pack(&inputs, &options(Some(16.0), None, 2)).unwrap();
    assert_eq!(atlas.meshes[0], AtlasMesh::default());
    check_mapping(&inputs, &atlas);
    check_charts(&atlas);
    let mesh = &atlas.meshes[1];
    let degenerate = &mesh.indices[6..9];
    assert!(
        degenerate
            .iter()
            .all(|&v| mesh.uv[v as usize] == [0.0, 0.0])
    );
    assert!(atlas.meshes[3].uv.iter().all(|&uv| uv == [0.0, 0.0]));
    assert_eq!(atlas.meshes[3].indices.len(), 6);
}

/// A speck (here one of a real city's 0.1 mm needles, in the units the bake hands the atlas:
/// the scene scaled to 1000 units²) is left out of the charts with UV (0, 0); charted,
/// xatlas drew it as a line a page long and the atlas refused the scene.
#[test]
fn specks_are_left_out_of_the_charts() {
    let mut meshes = vec![quad(-15.0, 0.0, -15.0, 31.6, 31.6)];
    meshes.push(TestMesh {
        positions: vec![
            [2.6446366, -0.43683144, 1.4284033],
            [2.6437597, -0.4320338, 1.4275247],
            [2.6436608, -0.4320338, 1.4276116],
        ],
        indices: vec![0, 1, 2],
    });
    let inputs = inputs(&meshes);
    let speck = triangle_areas(&inputs[1]).sum::<f64>();
    let total = check_inputs(&inputs).unwrap().area;
    assert!(speck > f64::from(f32::EPSILON) && speck < SPECK_AREA * total);
    let atlas = pack(&inputs, &options(Some(10.0), None, 4)).unwrap();
    check_mapping(&inputs, &atlas);
    check_charts(&atlas);
    assert!(atlas.meshes[1].uv.iter().all(|&uv| uv == [0.0, 0.0]));
    assert!(atlas.meshes[0].uv.iter().any(|&uv| uv != [0.0, 0.0]));
}

#[test]
fn add_mesh_errors_reach_the_caller() {
    let positions = [[0.0f32; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    let mut xatlas = ffi::Xatlas::new().unwrap();
    for (indices, expected) in [
        (vec![0u32, 1, 3], 1),
        (vec![0, 1, 2, 0], 2),
        (vec![0, 1, 2], 0),
    ] {
        assert_eq!(
            xatlas.add_mesh(&positions, &indices, &[]),
            expected,
            "{indices:?}"
        );
    }
    assert!(add_mesh_error_text(1).starts_with("IndexOutOfRange"));
}

/// The Rust mirrors of xatlas's structs have the C++ compiler's sizes (a field missing or out
/// of place would change most of them), and xatlas is built without its worker threads, whose
/// shutdown can hang (see the module doc).
#[test]
fn xatlas_is_built_as_the_ffi_expects() {
    for (name, cpp, rust) in ffi::layouts() {
        assert_eq!(cpp, rust, "sizeof xatlas::{name}");
    }
    assert!(!ffi::multithreaded());
}

/// Every bit of an atlas, for exact comparison.
fn bits(atlas: &Atlas) -> Vec<u32> {
    let mut out = vec![
        atlas.width,
        atlas.height,
        atlas.pages,
        atlas.texels_per_unit.to_bits(),
    ];
    for mesh in &atlas.meshes {
        out.push(mesh.xref.len() as u32);
        out.extend(&mesh.xref);
        out.extend(&mesh.page);
        out.extend(mesh.uv.iter().flat_map(|uv| uv.map(f32::to_bits)));
        out.extend(&mesh.indices);
    }
    out
}

#[test]
fn output_is_deterministic_also_across_threads() {
    let meshes = [
        quad(0.0, 0.0, 0.0, 1.0, 1.0),
        cube([2.0, 0.0, 0.0], 1.0),
        grid(24, 2.0, 0.3),
        quad(0.0, 3.0, 1.0, 2.0, 0.5),
    ];
    let inputs = inputs(&meshes);
    let opts = options(None, Some(256), 2);
    let first = bits(&pack(&inputs, &opts).unwrap());
    let second = bits(&pack(&inputs, &opts).unwrap());
    assert!(first == second, "two runs differ");
    let (a, b) = std::thread::scope(|s| {
        let a = s.spawn(|| pack(&inputs, &opts).map(|atlas| bits(&atlas)));
        let b = s.spawn(|| pack(&inputs, &opts).map(|atlas| bits(&atlas)));
        (a.join().unwrap(), b.join().unwrap())
    });
    assert!(a.unwrap() == first, "thread 1 differs");
    assert!(b.unwrap() == first, "thread 2 differs");
}

#[test]
fn a_20k_triangle_connected_grid_packs_into_a_valid_mapping() {
    let meshes = [grid(100, 10.0, 0.0)];
    let inputs = inputs(&meshes);
    let start = Instant::now();
    let atlas = pack(&inputs, &AtlasOptions::default()).unwrap();
    println!(
        "20k-triangle grid: {:.2} s, {} output vertices, {} texels per unit",
        start.elapsed().as_secs_f64(),
        atlas.meshes[0].xref.len(),
        atlas.texels_per_unit
    );
    check_mapping(&inputs, &atlas);
}

/// The meshes' triangles on page `p` only (the others dropped), for per-page checks.
fn on_page(atlas: &Atlas, p: u32) -> Atlas {
    let meshes = atlas
        .meshes
        .iter()
        .map(|m| AtlasMesh {
            indices: m
                .indices
                .chunks_exact(3)
                .zip(&m.page)
                .filter(|(_, page)| **page == p)
                .flat_map(|(t, _)| t.iter().copied())
                .collect(),
            ..m.clone()
        })
        .collect();
    Atlas {
        meshes,
        ..atlas.clone()
    }
}

#[test]
fn a_scene_of_many_pages_packs_in_groups_into_a_valid_atlas() {
    // 170 unit quads at 64 texels per unit on 192² pages: four a page (67 texels a side with
    // their padding), sixteen pages' worth of surface (108 quads at xatlas's 75%) a group.
    let meshes: Vec<_> = (0..170)
        .map(|i| quad(2.0 * (i % 16) as f32, 2.0 * (i / 16) as f32, 0.0, 1.0, 1.0))
        .collect();
    let inputs = inputs(&meshes);
    let opts = AtlasOptions {
        page_size: 192,
        ..options(Some(64.0), None, 2)
    };
    let groups = page_groups(&inputs, 64.0, 192);
    assert_eq!(groups, [0..108, 108..170]);
    assert_eq!(groups[0].start, 0);
    assert_eq!(groups.last().map(|g| g.end), Some(inputs.len()));
    assert!(groups.windows(2).all(|w| w[0].end == w[1].start));
    let atlas = pack(&inputs, &opts).unwrap();
    check_mapping(&inputs, &atlas);
    assert_eq!(atlas.texels_per_unit, 64.0);
    assert!(atlas.width <= 192 && atlas.height <= 192);
    let mut used = std::collections::BTreeSet::new();
    for mesh in &atlas.meshes {
        assert!(mesh.page.iter().all(|&p| p < atlas.pages));
        used.extend(mesh.page.iter().copied());
        let area = uv_area(mesh);
        assert!((area / 4096.0 - 1.0).abs() < 0.05, "density kept: {area}");
    }
    assert_eq!(used.len(), atlas.pages as usize, "every page is used");
    for p in 0..atlas.pages {
        let (gap, _) = check_charts(&on_page(&atlas, p));
        assert!(gap >= 2.0, "page {p}: charts {gap} texels apart");
    }
    // The groups' partly filled last pages cost at most one page a group over one atlas.
    let stats = check_inputs(&inputs).unwrap();
    let sizing = Sizing::from_options(&opts).unwrap();
    let one = pack_group(&inputs, &opts, sizing, &stats, &mut |_| {}).unwrap();
    println!(
        "grouped: {} pages, one atlas: {} pages",
        atlas.pages, one.pages
    );
    assert!(atlas.pages <= one.pages + groups.len() as u32);
    // The same bytes again (the groups run in parallel).
    assert_eq!(pack(&inputs, &opts).unwrap(), atlas);
}

#[test]
fn a_group_error_names_the_mesh_in_the_whole_input() {
    let error = AtlasError::Internal {
        mesh: 3,
        reason: "x".into(),
    }
    .offset_mesh(10);
    assert!(matches!(error, AtlasError::Internal { mesh: 13, .. }));
}

/// Generated worst cases with a fixed density on small pages: each packs, with a valid
/// mapping, the density kept, and no two charts overlapping on any page.
#[test]
fn worst_case_scenes_fit_with_a_fixed_density() {
    // A fan of 2 000 slivers around one vertex (a disc of radius 4).
    let n = 2000;
    let mut fan = TestMesh {
        positions: vec![[0.0, 0.0, 0.0]],
        indices: Vec::new(),
    };
    for k in 0..=n {
        let a = std::f32::consts::TAU * k as f32 / n as f32;
        fan.positions.push([4.0 * a.cos(), 4.0 * a.sin(), 0.0]);
        if k > 0 {
            fan.indices.extend([0, k as u32, k as u32 + 1]);
        }
    }
    // Long thin triangles: 200 needles 6 units long and 1 mm wide, side by side.
    let needles = TestMesh {
        positions: (0..200)
            .flat_map(|i| {
                let x = 0.01 * i as f32;
                [[x, 0.0, 1.0], [x + 0.001, 0.0, 1.0], [x, 6.0, 1.0]]
            })
            .collect(),
        indices: (0..600).collect(),
    };
    // A large ground beside 3 000 disconnected specks of a few texels each.
    let ground = quad(-6.0, -6.0, -1.0, 5.0, 5.0);
    let specks: Vec<TestMesh> = (0..3000)
        .map(|i| {
            let (x, y) = ((i % 60) as f32 * 0.2, (i / 60) as f32 * 0.2);
            quad(x, y, 2.0, 0.05, 0.05)
        })
        .collect();
    let cases: Vec<(&str, Vec<&TestMesh>)> = vec![
        ("fan", vec![&fan]),
        ("needles", vec![&needles]),
        (
            "ground and specks",
            std::iter::once(&ground).chain(&specks).collect(),
        ),
    ];
    for (name, meshes) in cases {
        let inputs: Vec<AtlasInput<'_>> = meshes.iter().map(|m| m.input()).collect();
        let opts = AtlasOptions {
            page_size: 512,
            ..options(Some(64.0), None, 2)
        };
        let atlas = pack(&inputs, &opts).unwrap_or_else(|e| panic!("{name}: {e}"));
        check_mapping(&inputs, &atlas);
        assert_eq!(atlas.texels_per_unit, 64.0, "{name}");
        if name == "needles" {
            // A needle is a fraction of a texel wide, and xatlas gives its chart at least a
            // texel across: its length keeps the density (6 units, 384 texels).
            for t in atlas.meshes[0].indices.chunks_exact(3) {
                let uv = [0, 1, 2].map(|k| atlas.meshes[0].uv[t[k] as usize]);
                let longest = (0..3)
                    .map(|k| {
                        let (a, b) = (uv[k], uv[(k + 1) % 3]);
                        ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt()
                    })
                    .fold(0.0, f32::max);
                assert!(
                    (longest / 384.0 - 1.0).abs() < 0.05,
                    "needle {longest} texels long"
                );
            }
        } else {
            // The first mesh (the fan, the ground) keeps the density; the specks, a few texels
            // each, are rounded up to whole texels by xatlas.
            let uv = uv_area(&atlas.meshes[0]);
            let area: f64 = triangle_areas(&inputs[0]).sum();
            let ratio = f64::from(uv) / (area * 64.0 * 64.0);
            assert!(
                (ratio - 1.0).abs() < 0.05,
                "{name}: texels/area ratio {ratio}"
            );
        }
        for p in 0..atlas.pages {
            check_charts(&on_page(&atlas, p));
        }
        println!(
            "{name}: {} pages of {}x{}",
            atlas.pages, atlas.width, atlas.height
        );
    }
}
