//! Bad input through the command line: a clear error naming the file and item, a non-zero exit,
//! no panic, the input untouched, and no output (not even a partial one).

use crate::output::split_glb;
use crate::scratch;
use penumbra::fixtures;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

pub struct Run {
    pub code: Option<i32>,
    pub stderr: String,
}

pub fn penumbra(args: &[&std::ffi::OsStr]) -> Run {
    let out = Command::new(env!("CARGO_BIN_EXE_penumbra"))
        .args(args)
        .output()
        .expect("runs");
    Run {
        code: out.status.code(),
        stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
    }
}

pub fn bake_cli(input: &Path, output: &Path) -> Run {
    penumbra(&[
        "bake".as_ref(),
        input.as_os_str(),
        output.as_os_str(),
        "--quiet".as_ref(),
        "--budget".as_ref(),
        "500".as_ref(),
        "--patches".as_ref(),
        "64".as_ref(),
        "--resolution".as_ref(),
        "64".as_ref(),
    ])
}

/// Bakes `input_bytes` from a scratch dir and expects a clean failure whose message contains
/// every one of `needles`.
pub fn expect_failure(name: &str, input_bytes: Option<&[u8]>, needles: &[&str]) {
    let dir = scratch(name);
    let input = dir.join("in.glb");
    if let Some(b) = input_bytes {
        std::fs::write(&input, b).unwrap();
    }
    let output = dir.join("out.glb");
    let run = bake_cli(&input, &output);
    assert_eq!(
        run.code,
        Some(1),
        "{name}: exit code; stderr: {}",
        run.stderr
    );
    assert!(
        !run.stderr.contains("panicked"),
        "{name}: panicked: {}",
        run.stderr
    );
    for n in needles {
        assert!(
            run.stderr.contains(n),
            "{name}: message lacks {n:?}: {}",
            run.stderr
        );
    }
    assert!(!output.exists(), "{name}: an output was written");
    if let Some(b) = input_bytes {
        assert_eq!(std::fs::read(&input).unwrap(), b, "{name}: input modified");
    }
    let leftovers: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p != &input)
        .collect();
    assert!(
        leftovers.is_empty(),
        "{name}: files left behind: {leftovers:?}"
    );
    let _ = std::fs::remove_dir_all(dir);
}

pub fn edit(bytes: &[u8], f: impl FnOnce(&mut Value, &mut Vec<u8>)) -> Vec<u8> {
    let (mut json, mut bin) = split_glb(bytes);
    f(&mut json, &mut bin);
    penumbra::write::to_glb(&json, bin).unwrap()
}

#[test]
fn missing_file() {
    expect_failure("missing", None, &["in.glb", "cannot read"]);
}

#[test]
fn not_gltf() {
    expect_failure(
        "not-gltf",
        Some(b"hello, this is not a glTF file"),
        &["in.glb", "not a valid glTF"],
    );
    expect_failure("empty", Some(b""), &["in.glb", "empty"]);
}

#[test]
fn truncated_glb() {
    let good = fixtures::cornell_box();
    expect_failure("truncated", Some(&good[..good.len() - 200]), &["in.glb"]);
}

#[test]
fn buffer_shorter_than_declared() {
    let bad = edit(&fixtures::cornell_box(), |_, bin| {
        bin.truncate(bin.len() / 2)
    });
    expect_failure(
        "short-buffer",
        Some(&bad),
        &["in.glb", "buffer 0", "truncated"],
    );
}

#[test]
fn accessor_out_of_range() {
    let bad = edit(&fixtures::cornell_box(), |json, _| {
        json["accessors"][0]["count"] = serde_json::json!(100000);
    });
    expect_failure("accessor-range", Some(&bad), &["in.glb", "accessor 0"]);
}

#[test]
fn nan_position() {
    let bad = edit(&fixtures::cornell_box(), |json, bin| {
        let acc = json["meshes"][0]["primitives"][0]["attributes"]["POSITION"]
            .as_u64()
            .unwrap() as usize;
        let view = json["accessors"][acc]["bufferView"].as_u64().unwrap() as usize;
        let off = json["bufferViews"][view]["byteOffset"]
            .as_u64()
            .unwrap_or(0) as usize
            + json["accessors"][acc]["byteOffset"].as_u64().unwrap_or(0) as usize;
        bin[off + 4..off + 8].copy_from_slice(&f32::NAN.to_le_bytes());
    });
    expect_failure("nan", Some(&bad), &["in.glb", "mesh 0", "not finite"]);
}

#[test]
fn unwritable_output() {
    let dir = scratch("unwritable");
    let input = dir.join("in.glb");
    std::fs::write(&input, fixtures::cornell_box()).unwrap();
    let output = dir.join("no-such-dir").join("out.glb");
    let run = bake_cli(&input, &output);
    assert_eq!(run.code, Some(1), "{}", run.stderr);
    assert!(
        run.stderr.contains("cannot write") && run.stderr.contains("out.glb"),
        "{}",
        run.stderr
    );
    assert!(!run.stderr.contains("panicked"));
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn no_emitters_bakes_black_with_a_warning() {
    let dir = scratch("no-emitters");
    let mut b = fixtures::GlbBuilder::new();
    let m = b.add_material(fixtures::Material::diffuse("grey", [0.5; 3]));
    b.add_mesh_node(
        "floor",
        &fixtures::horizontal_rect([-1.0, 1.0], [-1.0, 1.0], 0.0, true),
        m,
    );
    let input = dir.join("in.glb");
    std::fs::write(&input, b.to_glb()).unwrap();
    let output = dir.join("out.glb");
    let run = penumbra(&[
        "bake".as_ref(),
        input.as_os_str(),
        output.as_os_str(),
        "--resolution".as_ref(),
        "64".as_ref(),
    ]);
    assert_eq!(run.code, Some(0), "{}", run.stderr);
    assert!(run.stderr.contains("no emitters"), "{}", run.stderr);
    let (json, _) = split_glb(&std::fs::read(&output).unwrap());
    assert!(json["materials"][0]["extensions"]["MOZ_lightmap"].is_object());
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn zero_area_triangles_are_skipped_with_a_warning() {
    let dir = scratch("zero-area");
    let mut b = fixtures::GlbBuilder::new();
    let m = b.add_material(fixtures::Material::diffuse("grey", [0.5; 3]));
    let mut floor = fixtures::horizontal_rect([-1.0, 1.0], [-1.0, 1.0], 0.0, true);
    // A sliver with three collinear corners.
    let base = floor.positions.len() as u32;
    floor
        .positions
        .extend([[0.0, 0.0, 0.0], [0.5, 0.0, 0.0], [1.0, 0.0, 0.0]]);
    if let Some(n) = floor.normals.as_mut() {
        n.extend([[0.0, 1.0, 0.0]; 3]);
    }
    floor.indices.extend([base, base + 1, base + 2]);
    b.add_mesh_node("floor", &floor, m);
    let sun = b.add_light(fixtures::Light::directional("sun", 1.0));
    b.add_node(fixtures::Node::new("sun").with_light(sun).with_transform(
        fixtures::Transform::look_to([0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]),
    ));
    let input = dir.join("in.glb");
    std::fs::write(&input, b.to_glb()).unwrap();
    let output = dir.join("out.glb");
    let run = penumbra(&[
        "bake".as_ref(),
        input.as_os_str(),
        output.as_os_str(),
        "--resolution".as_ref(),
        "64".as_ref(),
    ]);
    assert_eq!(run.code, Some(0), "{}", run.stderr);
    assert!(run.stderr.contains("zero-area"), "{}", run.stderr);
    gltf::Gltf::from_slice(&std::fs::read(&output).unwrap()).expect("valid output");
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn node_graph_that_is_not_a_tree() {
    // Node 0 lists the same child twice: each is reached twice (exponential blow-up otherwise).
    let bad = edit(&fixtures::box_on_floor(), |json, _| {
        let nodes = json["nodes"].as_array_mut().unwrap();
        let n = nodes.len();
        nodes.push(serde_json::json!({"name": "twice", "children": [0, 0]}));
        json["scenes"][0]["nodes"] = serde_json::json!([n]);
    });
    expect_failure("not-a-tree", Some(&bad), &["in.glb", "not a tree"]);
}

#[test]
fn attribute_shorter_than_positions() {
    let bad = edit(&fixtures::cornell_box(), |json, _| {
        let normal = json["meshes"][0]["primitives"][0]["attributes"]["NORMAL"]
            .as_u64()
            .unwrap() as usize;
        json["accessors"][normal]["count"] = serde_json::json!(1);
    });
    expect_failure(
        "attribute-count",
        Some(&bad),
        &["in.glb", "mesh 0", "NORMAL"],
    );
}

#[test]
fn required_compression_extension() {
    let bad = edit(&fixtures::cornell_box(), |json, _| {
        json["extensionsUsed"] = serde_json::json!(["KHR_draco_mesh_compression"]);
        json["extensionsRequired"] = serde_json::json!(["KHR_draco_mesh_compression"]);
    });
    expect_failure(
        "draco",
        Some(&bad),
        &["in.glb", "KHR_draco_mesh_compression"],
    );
}

/// `render --camera NAME` picks the glTF camera of that name; an unknown name is an error that
/// names the file and lists the cameras, with nothing written.
#[test]
fn render_camera_by_name() {
    let dir = scratch("render-camera");
    let (input, baked) = (dir.join("cornell.glb"), dir.join("baked.glb"));
    std::fs::write(&input, fixtures::cornell_box()).unwrap();
    assert_eq!(bake_cli(&input, &baked).code, Some(0));
    let render = |camera: &str, out: &Path| {
        penumbra(&[
            "render".as_ref(),
            baked.as_os_str(),
            "--out".as_ref(),
            out.as_os_str(),
            "--camera".as_ref(),
            camera.as_ref(),
            "--width".as_ref(),
            "32".as_ref(),
        ])
    };
    let (named, first) = (dir.join("named.png"), dir.join("first.png"));
    assert_eq!(render("camera", &named).code, Some(0));
    assert_eq!(render("gltf", &first).code, Some(0));
    assert_eq!(
        std::fs::read(&named).unwrap(),
        std::fs::read(&first).unwrap()
    );
    let missing = dir.join("missing.png");
    let run = render("nope", &missing);
    assert_eq!(run.code, Some(1), "{}", run.stderr);
    assert!(
        run.stderr.contains("baked.glb")
            && run.stderr.contains("\"nope\"")
            && run.stderr.contains("\"camera\""),
        "{}",
        run.stderr
    );
    assert!(!missing.exists());
}

/// `compare` on a missing file fails naming it, before baking anything; an unknown method is
/// a usage error.
#[test]
fn compare_bad_input() {
    let dir = scratch("compare-bad");
    let out = dir.join("out");
    let run = penumbra(&[
        "compare".as_ref(),
        dir.join("nothing.glb").as_os_str(),
        "--out".as_ref(),
        out.as_os_str(),
        "--quiet".as_ref(),
    ]);
    assert_eq!(run.code, Some(1), "{}", run.stderr);
    assert!(run.stderr.contains("nothing.glb"), "{}", run.stderr);
    assert!(!out.join("report.json").exists());
    let run = penumbra(&[
        "compare".as_ref(),
        dir.join("nothing.glb").as_os_str(),
        "--out".as_ref(),
        out.as_os_str(),
        "--methods".as_ref(),
        "uniform-magic".as_ref(),
    ]);
    assert_eq!(run.code, Some(2), "{}", run.stderr);
    assert!(run.stderr.contains("uniform-magic"), "{}", run.stderr);
}
