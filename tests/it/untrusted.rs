//! Untrusted input through the command line: a glTF may read files only in its own folder (and
//! the `--allow-outside` ones), only regular files, and within the size limits; nothing in it
//! may panic, hang or exhaust memory; outputs are regular files; a stderr that cannot be
//! written never turns a good bake into a failure. See docs/security.md.

use crate::bad_input::{Run, edit};
use crate::scratch;
use penumbra::fixtures;
use serde_json::{Value, json};
use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The longest any command here may run before it counts as hung: generous, the bakes are
/// small.
const HANG_GUARD: Duration = Duration::from_secs(120);

/// Runs `penumbra args...` under [`HANG_GUARD`] (killed past it, and the test fails).
pub fn run_guarded(args: &[&OsStr]) -> Run {
    let mut child = Command::new(env!("CARGO_BIN_EXE_penumbra"))
        .args(args)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("runs");
    let mut stderr = child.stderr.take().expect("piped");
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        use std::io::Read;
        let _ = stderr.read_to_string(&mut s);
        s
    });
    let start = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().expect("waits") {
            break s;
        }
        if start.elapsed() > HANG_GUARD {
            let _ = child.kill();
            let _ = child.wait();
            panic!("{args:?}: still running after {HANG_GUARD:?}");
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    Run {
        code: status.code(),
        stderr: reader.join().expect("reads stderr"),
    }
}

/// `bake IN OUT` with small settings and `extra` options.
fn bake(input: &Path, output: &Path, extra: &[&str]) -> Run {
    let mut args: Vec<&OsStr> = vec!["bake".as_ref(), input.as_os_str(), output.as_os_str()];
    for a in [
        "--quiet",
        "--budget",
        "500",
        "--patches",
        "64",
        "--resolution",
        "64",
        "--threads",
        "1",
    ] {
        args.push(a.as_ref());
    }
    args.extend(extra.iter().map(|a| OsStr::new(*a)));
    run_guarded(&args)
}

/// A bake that must fail with exit 1, no panic, no output, and every one of `needles` in the
/// message.
fn refused(input: &Path, extra: &[&str], needles: &[&str]) -> String {
    let output = input.with_file_name("out.glb");
    let run = bake(input, &output, extra);
    assert_eq!(run.code, Some(1), "exit code; stderr: {}", run.stderr);
    assert!(!run.stderr.contains("panicked"), "{}", run.stderr);
    for n in needles {
        assert!(run.stderr.contains(n), "lacks {n:?}: {}", run.stderr);
    }
    assert!(!output.exists(), "an output was written");
    run.stderr
}

/// A marker string no file has by chance.
fn marker() -> String {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos());
    format!("PENUMBRA-MARKER-{}-{nanos:x}", std::process::id())
}

/// The box on the floor whose material's base colour texture is an image at `uri`.
fn with_image_uri(uri: &str) -> Vec<u8> {
    edit(&fixtures::box_on_floor(), |json, _| {
        json["images"] = json!([{"uri": uri}]);
        json["textures"] = json!([{"source": 0}]);
        json["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = json!({"index": 0});
    })
}

/// The box on the floor with a second buffer at `uri` (one byte long, used by nothing).
fn with_buffer_uri(uri: &str) -> Vec<u8> {
    edit(&fixtures::box_on_floor(), |json, _| {
        let buffers = json["buffers"].as_array_mut().expect("buffers");
        buffers.push(json!({"uri": uri, "byteLength": 1}));
    })
}

/// A folder `in/` holding the input, and beside it `outside/secret.txt` holding a marker.
struct Layout {
    root: PathBuf,
    input_dir: PathBuf,
    secret: PathBuf,
    marker: String,
}

fn layout(name: &str) -> Layout {
    let root = scratch(name);
    let input_dir = root.join("in");
    let outside = root.join("outside");
    std::fs::create_dir_all(&input_dir).unwrap();
    std::fs::create_dir_all(&outside).unwrap();
    let marker = marker();
    let secret = outside.join("secret.txt");
    std::fs::write(&secret, &marker).unwrap();
    Layout {
        root,
        input_dir,
        secret,
        marker,
    }
}

#[test]
fn a_uri_that_climbs_out_of_the_folder_is_refused() {
    let l = layout("uri-dotdot");
    let input = l.input_dir.join("in.glb");
    std::fs::write(&input, with_image_uri("../outside/secret.txt")).unwrap();
    refused(
        &input,
        &[],
        &["in.glb", "image 0", "../outside/secret.txt", "climbs out"],
    );
    // Percent-encoded dots are the same path.
    std::fs::write(&input, with_buffer_uri("%2E%2E/outside/secret.txt")).unwrap();
    refused(&input, &[], &["in.glb", "buffer 1", "climbs out"]);
    // The deep escape of the report.
    std::fs::write(&input, with_image_uri("../../../../../../etc/passwd")).unwrap();
    refused(&input, &[], &["in.glb", "image 0", "etc/passwd"]);
    let _ = std::fs::remove_dir_all(&l.root);
}

#[test]
fn an_absolute_uri_is_refused_unless_allowed() {
    let l = layout("uri-absolute");
    let input = l.input_dir.join("in.glb");
    let secret = l.secret.to_str().unwrap();
    std::fs::write(&input, with_buffer_uri(secret)).unwrap();
    refused(
        &input,
        &[],
        &[
            "in.glb",
            "buffer 1",
            secret,
            "absolute path",
            "--allow-outside",
        ],
    );
    std::fs::write(&input, with_buffer_uri("/proc/self/environ")).unwrap();
    refused(&input, &[], &["in.glb", "buffer 1", "/proc/self/environ"]);
    // Allowed on purpose: the file is read, and embedded in the output.
    std::fs::write(&input, with_buffer_uri(secret)).unwrap();
    let outside = l.secret.parent().unwrap().to_str().unwrap();
    let output = l.input_dir.join("out.glb");
    let run = bake(&input, &output, &["--allow-outside", outside]);
    assert_eq!(run.code, Some(0), "{}", run.stderr);
    let baked = std::fs::read(&output).unwrap();
    assert!(
        baked
            .windows(l.marker.len())
            .any(|w| w == l.marker.as_bytes()),
        "the allowed file is not in the output"
    );
    let _ = std::fs::remove_dir_all(&l.root);
}

#[cfg(unix)]
#[test]
fn a_symbolic_link_out_of_the_folder_is_refused() {
    let l = layout("uri-symlink");
    let input = l.input_dir.join("in.glb");
    std::os::unix::fs::symlink(&l.secret, l.input_dir.join("texture.png")).unwrap();
    std::fs::write(&input, with_image_uri("texture.png")).unwrap();
    refused(
        &input,
        &[],
        &["in.glb", "image 0", "texture.png", "symbolic link"],
    );
    // A link to a folder outside, then a file in it.
    std::os::unix::fs::symlink(l.secret.parent().unwrap(), l.input_dir.join("sub")).unwrap();
    std::fs::write(&input, with_buffer_uri("sub/secret.txt")).unwrap();
    refused(&input, &[], &["in.glb", "buffer 1", "symbolic link"]);
    // A link that stays inside is followed.
    std::fs::write(l.input_dir.join("real.bin"), [0u8; 4]).unwrap();
    std::os::unix::fs::symlink("real.bin", l.input_dir.join("alias.bin")).unwrap();
    std::fs::write(&input, with_buffer_uri("alias.bin")).unwrap();
    let run = bake(&input, &l.input_dir.join("out.glb"), &[]);
    assert_eq!(run.code, Some(0), "{}", run.stderr);
    let _ = std::fs::remove_dir_all(&l.root);
}

#[cfg(unix)]
#[test]
fn a_fifo_uri_is_refused_without_blocking() {
    let l = layout("uri-fifo");
    let input = l.input_dir.join("in.glb");
    let fifo = l.input_dir.join("fifo.png");
    let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
    // SAFETY: a valid NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o644) }, 0, "mkfifo");
    std::fs::write(&input, with_image_uri("fifo.png")).unwrap();
    refused(&input, &[], &["in.glb", "image 0", "fifo.png", "FIFO"]);
    std::fs::write(&input, with_buffer_uri("fifo.png")).unwrap();
    refused(&input, &[], &["in.glb", "buffer 1", "FIFO"]);
    let _ = std::fs::remove_dir_all(&l.root);
}

#[cfg(unix)]
#[test]
fn devices_are_refused_even_when_allowed() {
    let l = layout("uri-device");
    let input = l.input_dir.join("in.glb");
    std::os::unix::fs::symlink("/dev/urandom", l.input_dir.join("noise.bin")).unwrap();
    std::fs::write(&input, with_buffer_uri("noise.bin")).unwrap();
    refused(&input, &[], &["in.glb", "buffer 1", "noise.bin"]);
    for dev in ["/dev/urandom", "/dev/zero"] {
        std::fs::write(&input, with_image_uri(dev)).unwrap();
        refused(
            &input,
            &["--allow-outside", "/dev"],
            &["in.glb", "image 0", dev, "a device, not a regular file"],
        );
    }
    let _ = std::fs::remove_dir_all(&l.root);
}

#[test]
fn files_past_the_size_limit_are_refused() {
    let l = layout("uri-size");
    let input = l.input_dir.join("in.glb");
    std::fs::write(l.input_dir.join("big.bin"), vec![0u8; 3 << 20]).unwrap();
    std::fs::write(&input, with_buffer_uri("big.bin")).unwrap();
    refused(
        &input,
        &["--max-input-mib", "2"],
        &["in.glb", "buffer 1", "big.bin", "--max-input-mib"],
    );
    let run = bake(
        &input,
        &l.input_dir.join("out.glb"),
        &["--max-input-mib", "4"],
    );
    assert_eq!(run.code, Some(0), "{}", run.stderr);
    let _ = std::fs::remove_dir_all(&l.root);
}

/// A PNG whose header declares `width` x `height` RGBA pixels, with one row of data.
pub fn png_bomb(width: u32, height: u32) -> Vec<u8> {
    fn chunk(out: &mut Vec<u8>, kind: &[u8; 4], data: &[u8]) {
        out.extend_from_slice(&(data.len() as u32).to_be_bytes());
        let start = out.len();
        out.extend_from_slice(kind);
        out.extend_from_slice(data);
        let crc = crc32(&out[start..]);
        out.extend_from_slice(&crc.to_be_bytes());
    }
    fn crc32(bytes: &[u8]) -> u32 {
        let mut c = !0u32;
        for &b in bytes {
            c ^= u32::from(b);
            for _ in 0..8 {
                c = if c & 1 != 0 {
                    0xEDB8_8320 ^ (c >> 1)
                } else {
                    c >> 1
                };
            }
        }
        !c
    }
    let mut ihdr = Vec::new();
    ihdr.extend_from_slice(&width.to_be_bytes());
    ihdr.extend_from_slice(&height.to_be_bytes());
    ihdr.extend_from_slice(&[8, 6, 0, 0, 0]);
    // A stored (uncompressed) zlib stream of one empty row is enough for a header.
    let idat = [
        0x78, 0x01, 0x01, 0x01, 0x00, 0xFE, 0xFF, 0x00, 0x00, 0x01, 0x00, 0x01,
    ];
    let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
    chunk(&mut png, b"IHDR", &ihdr);
    chunk(&mut png, b"IDAT", &idat);
    chunk(&mut png, b"IEND", &[]);
    png
}

#[test]
fn an_image_bomb_is_refused_before_decoding() {
    let dir = scratch("png-bomb");
    let input = dir.join("in.glb");
    std::fs::write(dir.join("bomb.png"), png_bomb(23170, 23170)).unwrap();
    std::fs::write(&input, with_image_uri("bomb.png")).unwrap();
    refused(
        &input,
        &[],
        &["in.glb", "image 0", "23170 x 23170", "--max-image-size"],
    );
    // Within the side limit but past the memory limit.
    refused(
        &input,
        &["--max-image-size", "30000", "--max-image-mib", "64"],
        &["in.glb", "image 0", "--max-image-mib"],
    );
    // The same bomb inside the glb (a bufferView image).
    let glb = edit(&fixtures::box_on_floor(), |json, bin| {
        let png = png_bomb(40000, 10);
        let offset = bin.len();
        bin.extend_from_slice(&png);
        let views = json["bufferViews"].as_array_mut().unwrap();
        views.push(json!({"buffer": 0, "byteOffset": offset, "byteLength": png.len()}));
        let view = views.len() - 1;
        json["buffers"][0]["byteLength"] = json!(bin.len());
        json["images"] = json!([{"bufferView": view, "mimeType": "image/png"}]);
        json["textures"] = json!([{"source": 0}]);
        json["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = json!({"index": 0});
    });
    std::fs::write(&input, glb).unwrap();
    refused(&input, &[], &["in.glb", "image 0", "--max-image-size"]);
    let _ = std::fs::remove_dir_all(&dir);
}

/// The box on the floor under a root node scaled by `scale`.
pub fn scaled(bytes: &[u8], scale: f64) -> Vec<u8> {
    edit(bytes, |json, _| {
        let roots = json["scenes"][0]["nodes"].clone();
        let nodes = json["nodes"].as_array_mut().unwrap();
        nodes.push(json!({"name": "scale", "children": roots, "scale": [scale, scale, scale]}));
        let root = nodes.len() - 1;
        json["scenes"][0]["nodes"] = json!([root]);
    })
}

#[test]
fn micrometre_and_kilometre_scenes_bake() {
    let dir = scratch("scales");
    let input = dir.join("in.glb");
    for scale in [1e-6, 1e4] {
        for base in [fixtures::box_on_floor(), fixtures::spot_light()] {
            std::fs::write(&input, scaled(&base, scale)).unwrap();
            let output = dir.join("out.glb");
            let run = bake(&input, &output, &[]);
            assert_eq!(run.code, Some(0), "scale {scale}: {}", run.stderr);
            let _ = std::fs::remove_file(&output);
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_scene_too_small_for_f64_meshing_is_refused() {
    let dir = scratch("scale-tiny");
    let input = dir.join("in.glb");
    for scale in [1e-30, 1e-12] {
        std::fs::write(&input, scaled(&fixtures::cornell_box(), scale)).unwrap();
        refused(
            &input,
            &[],
            &["in.glb", "scenes[0]", "units", "practical units"],
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// The box on the floor with `n` more nodes instancing the box's mesh in a grid.
pub fn instances(n: usize) -> Vec<u8> {
    edit(&fixtures::box_on_floor(), |json, _| {
        let side = (n as f64).sqrt().ceil() as usize;
        let nodes = json["nodes"].as_array_mut().unwrap();
        let first = nodes.len();
        for k in 0..n {
            let (x, z) = ((k % side) as f64 * 3.0, (k / side) as f64 * 3.0);
            nodes.push(json!({"mesh": 1, "translation": [x, 0.0, z], "scale": [0.5, 0.5, 0.5]}));
        }
        let roots = json["scenes"][0]["nodes"].as_array_mut().unwrap();
        roots.extend((first..first + n).map(|i| json!(i)));
    })
}

/// The box on the floor whose box mesh has `n` copies of its primitive.
pub fn primitives(n: usize) -> Vec<u8> {
    edit(&fixtures::box_on_floor(), |json, _| {
        let prim = json["meshes"][1]["primitives"][0].clone();
        json["meshes"][1]["primitives"] = Value::Array(vec![prim; n]);
    })
}

#[test]
fn a_hundred_thousand_instances_are_refused_early() {
    let dir = scratch("instances");
    let input = dir.join("in.glb");
    std::fs::write(&input, instances(100_000)).unwrap();
    let start = Instant::now();
    refused(&input, &[], &["in.glb", "node", "--max-instances"]);
    eprintln!(
        "100000 instances refused in {:.2} s",
        start.elapsed().as_secs_f64()
    );
    // The limit is an option, both ways.
    std::fs::write(&input, instances(20)).unwrap();
    refused(
        &input,
        &["--max-instances", "10"],
        &["in.glb", "more than 10 mesh instances"],
    );
    let output = dir.join("out.glb");
    let run = run_guarded(&[
        "bake".as_ref(),
        input.as_os_str(),
        output.as_os_str(),
        "--quiet".as_ref(),
        "--budget".as_ref(),
        "2000".as_ref(),
        "--max-instances".as_ref(),
        "30".as_ref(),
    ]);
    assert_eq!(run.code, Some(0), "{}", run.stderr);
    let _ = std::fs::remove_dir_all(&dir);
}

/// Copies of one primitive at one place (a duplicated node or primitive, as the mutants make
/// them) are placed once: each copy would cost a chart and an occluder, and 5 000 of them took
/// over 6 GB before. They are counted against `--max-instances` all the same.
#[test]
fn copies_of_a_primitive_at_one_place_are_baked_once_with_a_warning() {
    let dir = scratch("copies");
    let input = dir.join("in.glb");
    std::fs::write(&input, primitives(5_000)).unwrap();
    let output = dir.join("out.glb");
    let run = bake(&input, &output, &[]);
    assert_eq!(run.code, Some(0), "{}", run.stderr);
    let scene = |path: &Path| {
        let gltf = penumbra::load::read(path).unwrap();
        penumbra::load::scene(&gltf).unwrap()
    };
    let copied = scene(&input);
    assert!(
        copied
            .warnings
            .iter()
            .any(|w| w.contains("4999 primitive placement(s) repeat an earlier one")),
        "{:?}",
        copied.warnings
    );
    std::fs::write(&input, primitives(1)).unwrap();
    assert_eq!(copied.triangles.len(), scene(&input).triangles.len());
    std::fs::write(&input, primitives(5_000)).unwrap();
    std::fs::remove_file(&output).unwrap();
    refused(
        &input,
        &["--max-instances", "4000"],
        &["in.glb", "more than 4000 mesh instances"],
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_hundred_thousand_primitives_are_refused_early() {
    let dir = scratch("primitives");
    let input = dir.join("in.glb");
    std::fs::write(&input, primitives(100_000)).unwrap();
    refused(&input, &[], &["in.glb", "meshes", "--max-primitives"]);
    // Past the instance limit too, the primitive count is the first said.
    refused(
        &input,
        &["--max-primitives", "200000"],
        &["in.glb", "--max-instances"],
    );
    std::fs::write(&input, primitives(10)).unwrap();
    refused(
        &input,
        &["--max-triangles", "50"],
        &["in.glb", "mesh 1", "--max-triangles"],
    );
    // The ten copies are placed once: the box's five faces and the floor.
    refused(
        &input,
        &["--max-polygons", "5"],
        &["in.glb", "scene", "receiver polygons", "--max-polygons"],
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_node_count_is_limited() {
    let dir = scratch("nodes");
    let input = dir.join("in.glb");
    std::fs::write(&input, instances(20)).unwrap();
    refused(
        &input,
        &["--max-nodes", "10"],
        &["in.glb", "nodes", "23 nodes, more than 10", "--max-nodes"],
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[cfg(unix)]
#[test]
fn outputs_that_are_not_regular_files_are_refused() {
    let dir = scratch("out-special");
    let input = dir.join("in.glb");
    std::fs::write(&input, fixtures::box_on_floor()).unwrap();
    let fifo = dir.join("out.fifo");
    let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
    // SAFETY: a valid NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o644) }, 0, "mkfifo");
    for (out, kind) in [
        (fifo.as_path(), "a FIFO"),
        (Path::new("/dev/null"), "a device"),
    ] {
        let run = bake(&input, out, &[]);
        assert_eq!(run.code, Some(1), "{}", run.stderr);
        assert!(run.stderr.contains("OUT"), "{}", run.stderr);
        assert!(run.stderr.contains(kind), "{}", run.stderr);
    }
    let meta = std::fs::symlink_metadata(&fifo).unwrap();
    use std::os::unix::fs::FileTypeExt;
    assert!(meta.file_type().is_fifo(), "the FIFO was replaced");
    // The same for the other outputs.
    let run = bake(&input, &dir.join("out.glb"), &["--exr", "/dev/null"]);
    assert_eq!(run.code, Some(1), "{}", run.stderr);
    assert!(run.stderr.contains("--exr"), "{}", run.stderr);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_long_output_name_is_written() {
    let dir = scratch("out-long");
    let input = dir.join("in.glb");
    std::fs::write(&input, fixtures::box_on_floor()).unwrap();
    for len in [234, 250, 255] {
        let name = format!("{}.glb", "x".repeat(len - 4));
        let output = dir.join(&name);
        let run = bake(&input, &output, &[]);
        assert_eq!(run.code, Some(0), "{len} bytes: {}", run.stderr);
        assert!(output.is_file());
        std::fs::remove_file(&output).unwrap();
    }
    let left: Vec<_> = std::fs::read_dir(&dir).unwrap().collect();
    assert_eq!(left.len(), 1, "temporary files left behind");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn an_unwritable_stderr_does_not_fail_a_good_bake() {
    let dir = scratch("stderr-full");
    let input = dir.join("in.glb");
    std::fs::write(&input, fixtures::box_on_floor()).unwrap();
    let output = dir.join("out.glb");
    let full = std::fs::OpenOptions::new()
        .write(true)
        .open("/dev/full")
        .unwrap();
    let status = Command::new(env!("CARGO_BIN_EXE_penumbra"))
        .arg("bake")
        .args([&input, &output])
        .args(["--budget", "500", "--resolution", "64", "--patches", "64"])
        .stdout(Stdio::null())
        .stderr(full)
        .status()
        .unwrap();
    assert_eq!(status.code(), Some(0));
    assert!(output.is_file());
    // A failure is still exit 1, its message lost.
    let full = std::fs::OpenOptions::new()
        .write(true)
        .open("/dev/full")
        .unwrap();
    let status = Command::new(env!("CARGO_BIN_EXE_penumbra"))
        .arg("bake")
        .args([&dir.join("missing.glb"), &dir.join("out2.glb")])
        .stdout(Stdio::null())
        .stderr(full)
        .status()
        .unwrap();
    assert_eq!(status.code(), Some(1));
    let _ = std::fs::remove_dir_all(&dir);
}

/// The point light fixture with `field` of its light set to `value`.
fn light_with(field: &str, value: Value) -> Vec<u8> {
    edit(&fixtures::point_light(), |json, _| {
        json["extensions"]["KHR_lights_punctual"]["lights"][0][field] = value;
    })
}

#[test]
fn out_of_spec_lights_are_refused() {
    let dir = scratch("lights");
    let input = dir.join("in.glb");
    let cases = [
        (light_with("intensity", json!(-5.0)), "intensity -5"),
        // 1e39 is past f32: the light is infinite.
        (light_with("intensity", json!(1e39)), "intensity inf"),
        (light_with("color", json!([1.0, -1.0, 1.0])), "color"),
        (light_with("range", json!(0.0)), "range 0"),
        (light_with("range", json!(-2.0)), "range -2"),
    ];
    for (glb, needle) in cases {
        std::fs::write(&input, glb).unwrap();
        refused(
            &input,
            &[],
            &["in.glb", "KHR_lights_punctual.lights[0]", needle],
        );
    }
    let spot = edit(&fixtures::spot_light(), |json, _| {
        json["extensions"]["KHR_lights_punctual"]["lights"][0]["spot"] =
            json!({"innerConeAngle": 0.8, "outerConeAngle": 0.6});
    });
    std::fs::write(&input, spot).unwrap();
    refused(
        &input,
        &[],
        &["in.glb", "KHR_lights_punctual.lights[0]", "outerConeAngle"],
    );
    let emissive = edit(&fixtures::box_on_floor(), |json, _| {
        json["materials"][1]["extensions"]["KHR_materials_emissive_strength"]["emissiveStrength"] =
            json!(-10.0);
    });
    std::fs::write(&input, emissive).unwrap();
    refused(&input, &[], &["in.glb", "materials[1]", "emissiveStrength"]);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_limits_and_allow_outside_are_in_the_help() {
    let help = {
        let out = Command::new(env!("CARGO_BIN_EXE_penumbra"))
            .args(["bake", "--help"])
            .output()
            .unwrap();
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    for option in [
        "--allow-outside",
        "--max-input-mib",
        "--max-image-size",
        "--max-image-mib",
        "--max-nodes",
        "--max-instances",
        "--max-primitives",
        "--max-triangles",
        "--max-polygons",
    ] {
        assert!(help.contains(option), "{option} not in the help:\n{help}");
    }
}
