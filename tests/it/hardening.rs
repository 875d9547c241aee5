//! Regression tests for the hardening issue, each through the command line: outputs that would
//! overwrite the input, inputs that made a parser panic or a stage hang, physical bounds, and
//! signals between writing and renaming.

use crate::bad_input::{bake_cli, edit, expect_failure, penumbra};
use crate::output::split_glb;
use crate::scratch;
use penumbra::fixtures;
use serde_json::{Value, json};
use std::ffi::OsStr;
use std::path::{Path, PathBuf};

/// Files in `dir` other than `keep`.
fn others(dir: &Path, keep: &[&Path]) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| !keep.contains(&p.as_path()))
        .collect();
    v.sort();
    v
}

/// `bake IN OUT extra...` that must be refused with exit 1 before anything is written, the input
/// unchanged and `needle` in the message.
fn refused(dir: &Path, input: &Path, output: &Path, extra: &[&OsStr], needle: &str) {
    let before = std::fs::read(input).unwrap();
    let listing = others(dir, &[]);
    let mut args: Vec<&OsStr> = vec!["bake".as_ref(), input.as_os_str(), output.as_os_str()];
    args.extend_from_slice(extra);
    args.push("--quiet".as_ref());
    let run = penumbra(&args);
    assert_eq!(run.code, Some(1), "{args:?}: {}", run.stderr);
    assert!(run.stderr.contains(needle), "{args:?}: {}", run.stderr);
    assert!(!run.stderr.contains("panicked"), "{}", run.stderr);
    assert_eq!(
        std::fs::read(input).unwrap(),
        before,
        "{args:?}: input changed"
    );
    assert_eq!(
        others(dir, &[]),
        listing,
        "{args:?}: files appeared or vanished"
    );
}

#[cfg(unix)]
#[test]
fn the_input_is_never_an_output() {
    let dir = scratch("in-is-out");
    let input = dir.join("in.glb");
    std::fs::write(&input, fixtures::box_on_floor()).unwrap();
    std::fs::create_dir(dir.join("a")).unwrap();
    let never = "never overwrites its input";
    refused(&dir, &input, &input, &[], never);
    refused(&dir, &input, &dir.join("a/../in.glb"), &[], never);
    let out = dir.join("out.glb");
    refused(
        &dir,
        &input,
        &out,
        &["--exr".as_ref(), input.as_os_str()],
        never,
    );
    refused(
        &dir,
        &input,
        &out,
        &["--stats".as_ref(), input.as_os_str()],
        never,
    );
    // Two outputs naming one file.
    refused(
        &dir,
        &input,
        &out,
        &["--exr".as_ref(), out.as_os_str()],
        "also the OUT output",
    );
    let stats = dir.join("s.json");
    let exr: &OsStr = stats.as_os_str();
    refused(
        &dir,
        &input,
        &out,
        &["--exr".as_ref(), exr, "--stats".as_ref(), exr],
        "also",
    );
    // Links to the input.
    let link = dir.join("link.glb");
    std::os::unix::fs::symlink(&input, &link).unwrap();
    refused(&dir, &input, &link, &[], never);
    let hard = dir.join("hard.glb");
    std::fs::hard_link(&input, &hard).unwrap();
    refused(&dir, &input, &hard, &[], never);
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn a_gltf_s_own_buffers_are_inputs_too() {
    let dir = scratch("gltf-buffer");
    let (json, bin) = split_glb(&fixtures::box_on_floor());
    let mut json = json;
    json["buffers"] = json!([{"uri": "scene.bin", "byteLength": bin.len()}]);
    std::fs::write(dir.join("scene.bin"), &bin).unwrap();
    let input = dir.join("scene.gltf");
    std::fs::write(&input, serde_json::to_vec(&json).unwrap()).unwrap();
    refused(
        &dir,
        &input,
        &dir.join("scene.bin"),
        &[],
        "never overwrites",
    );
    assert_eq!(std::fs::read(dir.join("scene.bin")).unwrap(), bin);
    let _ = std::fs::remove_dir_all(dir);
}

#[cfg(unix)]
#[test]
fn an_output_link_is_written_through() {
    let dir = scratch("out-link");
    let input = dir.join("in.glb");
    std::fs::write(&input, fixtures::box_on_floor()).unwrap();
    let target = dir.join("target.glb");
    std::fs::write(&target, b"old").unwrap();
    let link = dir.join("link.glb");
    std::os::unix::fs::symlink(&target, &link).unwrap();
    let run = bake_cli(&input, &link);
    assert_eq!(run.code, Some(0), "{}", run.stderr);
    assert!(
        std::fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink()
    );
    assert!(std::fs::read(&target).unwrap().starts_with(b"glTF"));
    let _ = std::fs::remove_dir_all(dir);
}

/// The byte offset of accessor `acc`'s first element in the binary chunk.
fn accessor_offset(json: &Value, acc: usize) -> usize {
    let view = json["accessors"][acc]["bufferView"].as_u64().unwrap() as usize;
    json["bufferViews"][view]["byteOffset"]
        .as_u64()
        .unwrap_or(0) as usize
        + json["accessors"][acc]["byteOffset"].as_u64().unwrap_or(0) as usize
}

/// Accessor index of the POSITION of mesh `m`'s first primitive.
fn position(json: &Value, m: usize) -> usize {
    json["meshes"][m]["primitives"][0]["attributes"]["POSITION"]
        .as_u64()
        .unwrap() as usize
}

#[test]
fn indices_the_parser_would_panic_on() {
    let base = fixtures::box_on_floor();
    let bad = edit(&base, |j, _| {
        j["meshes"][0]["primitives"][0]["attributes"]["POSITION"] = json!(99);
    });
    let item = "meshes[0].primitives[0].attributes.POSITION";
    expect_failure(
        "position-oob",
        Some(&bad),
        &["in.glb", item, "out of range"],
    );
    let bad = edit(&base, |j, _| {
        j.as_object_mut().unwrap().remove("accessors");
    });
    expect_failure("no-accessors", Some(&bad), &["in.glb", item, "0 accessors"]);
    for huge in [1u64 << 32, 1 << 63] {
        let bad = edit(&base, |j, _| {
            j["meshes"][0]["primitives"][0]["material"] = json!(huge);
        });
        let needles = ["in.glb", "meshes[0].primitives[0].material", "larger than"];
        expect_failure("material-huge", Some(&bad), &needles);
    }
    let bad = edit(&base, |j, _| {
        j["nodes"][0]["children"] = json!([7]);
    });
    expect_failure("child-oob", Some(&bad), &["in.glb", "nodes[0].children[0]"]);
}

#[test]
fn an_embedded_image_without_a_mime_type_is_refused() {
    // The gltf crate unwraps `mimeType` for an image in a bufferView (found by the mutation
    // test on a real scene).
    let bad = edit(&fixtures::box_on_floor(), |j, bin| {
        let at = bin.len();
        bin.extend_from_slice(&[0u8; 8]);
        let views = j["bufferViews"].as_array_mut().unwrap();
        views.push(json!({"buffer": 0, "byteOffset": at, "byteLength": 8}));
        let view = views.len() - 1;
        j["buffers"][0]["byteLength"] = json!(bin.len());
        j["images"] = json!([{"bufferView": view}]);
    });
    expect_failure("mime", Some(&bad), &["in.glb", "images[0]", "mimeType"]);
}

#[test]
fn overlapping_stride_is_refused() {
    let bad = edit(&fixtures::box_on_floor(), |j, _| {
        let view = j["accessors"][position(j, 1)]["bufferView"]
            .as_u64()
            .unwrap() as usize;
        j["bufferViews"][view]["byteStride"] = json!(8);
    });
    let needles = ["in.glb", "mesh 1 \"box\" primitive 0", "byteStride 8"];
    expect_failure("stride", Some(&bad), &needles);
}

#[test]
fn a_stray_vertex_far_away_is_named() {
    for x in [3.4e38_f32, 1e12] {
        let bad = edit(&fixtures::box_on_floor(), |j, bin| {
            let acc = position(j, 1);
            let off = accessor_offset(j, acc);
            bin[off..off + 4].copy_from_slice(&x.to_le_bytes());
            // Keep the accessor's declared bounds true, as a careful exporter would.
            j["accessors"][acc]["max"][0] = json!(x);
        });
        let needles = ["in.glb", "mesh 1 \"box\" primitive 0 (node 1)", "vertex 0"];
        expect_failure("stray-vertex", Some(&bad), &needles);
    }
}

#[test]
fn a_transform_that_overflows_names_the_node() {
    let bad = edit(&fixtures::box_on_floor(), |j, _| {
        j["nodes"][1]["scale"] = json!([3e38, 3e38, 3e38]);
    });
    let run_needles = ["in.glb", "node 1"];
    expect_failure("scale-overflow", Some(&bad), &run_needles);
    // Twice more: a finite scale whose product with a child's overflows.
    let bad = edit(&fixtures::box_on_floor(), |j, _| {
        let n = j["nodes"].as_array().unwrap().len();
        j["nodes"][1]["scale"] = json!([1e30, 1e30, 1e30]);
        j["nodes"]
            .as_array_mut()
            .unwrap()
            .push(json!({"scale": [1e30, 1e30, 1e30], "children": [1]}));
        j["scenes"][0]["nodes"] = json!([0, n, 2]);
    });
    expect_failure("scale-product", Some(&bad), &["in.glb", "node 1"]);
}

/// A message names the file once and says each thing once.
#[test]
fn errors_say_things_once() {
    let dir = scratch("once");
    let input = dir.join("in.glb");
    std::fs::write(&input, fixtures::box_on_floor()).unwrap();
    let out = dir.join("out.glb");
    let run = penumbra(&[
        "bake".as_ref(),
        input.as_os_str(),
        out.as_os_str(),
        "--resolution".as_ref(),
        "16".as_ref(),
        "--padding".as_ref(),
        "20".as_ref(),
        "--quiet".as_ref(),
    ]);
    assert_eq!(run.code, Some(1), "{}", run.stderr);
    assert_eq!(run.stderr.matches("in.glb").count(), 1, "{}", run.stderr);
    assert_eq!(run.stderr.matches("no room").count(), 1, "{}", run.stderr);
    let bad = edit(&fixtures::box_on_floor(), |j, _| {
        let view = j["accessors"][position(j, 1)]["bufferView"]
            .as_u64()
            .unwrap() as usize;
        j["bufferViews"][view]["byteStride"] = json!(8);
    });
    std::fs::write(&input, bad).unwrap();
    let run = bake_cli(&input, &out);
    assert_eq!(run.code, Some(1), "{}", run.stderr);
    assert_eq!(run.stderr.matches("in.glb").count(), 1, "{}", run.stderr);
    let _ = std::fs::remove_dir_all(dir);
}

/// A page too small for a scene's charts at any density is an error that says so, found in
/// the first packings (the atlas packs alongside the mesh and the solve; it used to halve the
/// density 40 times first), and nothing is written.
#[test]
fn charts_that_fit_no_page_are_an_error() {
    // 36 boxes on a floor: about 200 charts, which their 2 texels of padding alone do not
    // let fit on the 32² page `bake_with_stats` asks for.
    let (code, stderr, stats) = bake_with_stats("no-fit", &fixtures::box_grid(6), &[]);
    assert_eq!(code, Some(1), "{stderr}");
    assert!(stderr.contains("in.glb"), "{stderr}");
    assert!(stderr.contains("do not fit on one 32x32 page"), "{stderr}");
    let attempts: u32 = stderr
        .split("after ")
        .nth(1)
        .and_then(|s| s.split_whitespace().next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no attempt count in {stderr}"));
    assert!(attempts <= 3, "{stderr}");
    // Nothing is written (the outputs are renamed into place together, after the bake).
    assert_eq!(stats, Value::Null);
}

/// Bakes `bytes` with `--stats` and returns (exit code, stderr, stats JSON).
fn bake_with_stats(name: &str, bytes: &[u8], extra: &[&str]) -> (Option<i32>, String, Value) {
    let dir = scratch(name);
    let input = dir.join("in.glb");
    std::fs::write(&input, bytes).unwrap();
    let (out, stats) = (dir.join("out.glb"), dir.join("stats.json"));
    let mut args: Vec<&OsStr> = vec![
        "bake".as_ref(),
        input.as_os_str(),
        out.as_os_str(),
        "--stats".as_ref(),
        stats.as_os_str(),
        "--resolution".as_ref(),
        "32".as_ref(),
        "--budget".as_ref(),
        "300".as_ref(),
    ];
    args.extend(extra.iter().map(OsStr::new));
    let run = penumbra(&args);
    let json = std::fs::read(&stats)
        .map(|b| serde_json::from_slice(&b).unwrap())
        .unwrap_or(Value::Null);
    let _ = std::fs::remove_dir_all(dir);
    (run.code, run.stderr, json)
}

#[test]
fn albedo_is_clamped_with_a_warning() {
    // No pbrMetallicRoughness: glTF's default base colour is 1.
    let white = edit(&fixtures::box_on_floor(), |j, _| {
        j["materials"][0]
            .as_object_mut()
            .unwrap()
            .remove("pbrMetallicRoughness");
    });
    let (code, stderr, stats) = bake_with_stats("albedo-1", &white, &["--patches", "64"]);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(
        stderr.contains("material grey: albedo (1, 1, 1)"),
        "{stderr}"
    );
    assert!(stderr.contains("clamped to (0.99, 0.99, 0.99)"), "{stderr}");
    assert_eq!(stats["converged"], json!(true), "{stderr}");
    let negative = edit(&fixtures::box_on_floor(), |j, _| {
        j["materials"][0]["pbrMetallicRoughness"]["baseColorFactor"] = json!([-1e30, 0.5, 0.5, 1]);
    });
    let (code, stderr, _) = bake_with_stats("albedo-neg", &negative, &[]);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(stderr.contains("clamped to (0, 0.5, 0.5)"), "{stderr}");
}

#[test]
fn a_solve_stopped_on_its_cap_says_so() {
    // A closed box of albedo 0.99 needs about 690 sweeps for a 0.1% tolerance: far past the
    // shot limit of 100 per patch.
    let glb = fixtures::furnace_box_with(0.99, 1.0);
    let args = ["--solver", "progressive", "--patches", "16"];
    let (code, stderr, stats) = bake_with_stats("cap", &glb, &args);
    assert_eq!(code, Some(0), "{stderr}");
    assert_eq!(stats["converged"], json!(false));
    assert!(stderr.contains("stopped on its shot limit"), "{stderr}");
    let warned = stats["warnings"].as_array().unwrap();
    assert!(
        warned
            .iter()
            .any(|w| w.as_str().unwrap().contains("shot limit"))
    );
}

#[test]
fn duplicated_geometry_that_makes_the_solve_diverge_is_an_error() {
    // Every primitive of a closed box twice: each point sees every wall twice (form factors
    // summing to 2), so with albedo 0.8 the bounces grow without end. Found by the mutation test
    // on a real scene (a duplicated primitive): it ran to the shot limit and wrote a NaN
    // lightmap with exit 0. An exact copy (the same accessors and material) is placed once
    // (`untrusted::copies_of_a_primitive_at_one_place_are_baked_once_with_a_warning`), so the
    // copies here use a copy of their material.
    let furnace = fixtures::furnace_box_with(0.8, 1.0);
    let copied = |new_material: bool| {
        edit(&furnace, |j, _| {
            let materials = j["materials"].as_array().map_or(0, Vec::len);
            if new_material {
                let copies = j["materials"].as_array().unwrap().clone();
                j["materials"].as_array_mut().unwrap().extend(copies);
            }
            for mesh in j["meshes"].as_array_mut().unwrap() {
                let prims = mesh["primitives"].as_array_mut().unwrap();
                let mut copy = prims.clone();
                for p in copy.iter_mut().filter(|_| new_material) {
                    let m = p["material"].as_u64().unwrap() as usize;
                    p["material"] = json!(m + materials);
                }
                prims.extend(copy);
            }
        })
    };
    let (code, stderr, _) = bake_with_stats("copied", &copied(false), &[]);
    assert_eq!(code, Some(0), "{stderr}");
    let twice = copied(true);
    for args in [
        &["--solver", "progressive", "--patches", "64"][..],
        &["--solver", "hierarchical"],
    ] {
        let (code, stderr, _) = bake_with_stats("diverge", &twice, args);
        assert_eq!(code, Some(1), "{args:?}: {stderr}");
        assert!(
            stderr.contains("in.glb: scene: the indirect light diverges"),
            "{args:?}: {stderr}"
        );
        assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
    }
}

#[test]
fn a_scene_that_receives_no_light_warns() {
    // The box-on-floor's light, moved under the floor: it faces down, at nothing.
    let away = edit(&fixtures::box_on_floor(), |j, _| {
        j["nodes"][2]["translation"] = json!([0.0, -100.0, 0.0]);
    });
    let (code, stderr, _) = bake_with_stats("dark", &away, &[]);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(stderr.contains("no surface receives any light"), "{stderr}");
}

/// A SIGTERM after the first output is written but before any is renamed leaves neither the
/// outputs nor temporary files.
#[cfg(unix)]
#[test]
fn a_signal_between_writing_and_renaming_leaves_nothing() {
    let dir = scratch("sigterm");
    let input = dir.join("in.glb");
    std::fs::write(&input, fixtures::box_on_floor()).unwrap();
    let (out, exr) = (dir.join("out.glb"), dir.join("out.exr"));
    // A large lightmap, so encoding the EXR (after the glb's temporary file is written) takes a
    // while.
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_penumbra"))
        .args([
            "bake".as_ref(),
            input.as_os_str(),
            out.as_os_str(),
            "--exr".as_ref(),
        ])
        .arg(&exr)
        .args([
            "--resolution",
            "2048",
            "--supersample",
            "1",
            "--budget",
            "300",
        ])
        .args(["--bounces", "0", "--quiet"])
        .spawn()
        .unwrap();
    let start = std::time::Instant::now();
    let seen = loop {
        let tmp = others(&dir, &[&input])
            .into_iter()
            .any(|p| p.to_string_lossy().ends_with(".tmp"));
        if tmp || start.elapsed().as_secs() > 120 {
            break tmp;
        }
        if child.try_wait().unwrap().is_some() {
            break false;
        }
        std::thread::sleep(std::time::Duration::from_micros(200));
    };
    assert!(seen, "never saw the temporary file");
    // SAFETY: plain kill(2) on our own child.
    unsafe {
        kill(child.id() as i32, 15);
    }
    let status = child.wait().unwrap();
    use std::os::unix::process::ExitStatusExt;
    assert_eq!(status.signal(), Some(15), "{status:?}");
    assert_eq!(others(&dir, &[&input]), Vec::<PathBuf>::new());
    let _ = std::fs::remove_dir_all(dir);
}

#[cfg(unix)]
unsafe extern "C" {
    fn kill(pid: i32, sig: i32) -> i32;
}
