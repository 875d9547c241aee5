//! A deterministic mutation test of the whole command line: a few hundred mutants of the
//! fixtures, each baked under a time limit, must each end in exit 0 or in exit 1 with a message
//! that names the file; never a panic, never past the limit, the input never changed, and no
//! temporary file left behind.
//!
//! Mutants are built from fixed seeds, so a failure reproduces: the message gives the seed and
//! the mutations, and the mutant is kept in `target/tmp/mutants/`. `PENUMBRA_MUTANTS=N` runs N
//! mutants instead of the default and `PENUMBRA_MUTANTS_FROM=K` starts at mutant K (for longer
//! runs), and `PENUMBRA_MUTANT_INPUTS=DIR` adds every `.glb` in DIR to the fixtures mutated.
//! The `cargo fuzz` targets in `tests/fuzz` cover the loader and the bake, coverage-guided.
//!
//! One mutant in [`UNTRUSTED_SHARE`] is of the untrusted-input classes ([`mutate_untrusted`]):
//! URIs that lead out of the input's folder (`..`, absolute paths, symbolic links) or name
//! special files (a FIFO, `/dev/zero`, `/dev/urandom`, a directory), image bombs, scale
//! extremes, and instance and primitive explosions. Each mutant's folder holds those special
//! files, and a folder beside it a file with a random marker: the marker must never be in the
//! output or the messages. `PENUMBRA_MUTANT_CLASSES=untrusted` makes every mutant one of them.

use crate::output::split_glb;
use crate::{Below, Rng};
use penumbra::fixtures;
use serde_json::{Value, json};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Mutants per `cargo test` run.
const MUTANTS: usize = 500;

/// The longest a bake of one (small) mutant may take.
const LIMIT: Duration = Duration::from_secs(30);

/// JSON pointers of every value in `v`, depth first.
fn pointers(v: &Value, at: String, out: &mut Vec<String>) {
    match v {
        Value::Object(m) => {
            for (k, x) in m {
                pointers(
                    x,
                    format!("{at}/{}", k.replace('~', "~0").replace('/', "~1")),
                    out,
                );
            }
        }
        Value::Array(a) => {
            for (i, x) in a.iter().enumerate() {
                pointers(x, format!("{at}/{i}"), out);
            }
        }
        _ => {}
    }
    out.push(at);
}

/// Numbers that break things: indices at and past array ends, sizes past u32, floats at the
/// edges of f32.
const NUMBERS: [f64; 22] = [
    0.0,
    1.0,
    -1.0,
    2.0,
    3.0,
    4.0,
    7.0,
    8.0,
    12.0,
    255.0,
    65535.0,
    2147483648.0,
    4294967296.0,
    9.223372036854776e18,
    0.5,
    -0.5,
    1e-30,
    1e30,
    3.4e38,
    -3.4e38,
    1e12,
    1e-12,
];

/// Float bit patterns written into vertex data.
const FLOATS: [f32; 9] = [
    f32::NAN,
    f32::INFINITY,
    f32::MAX,
    -1e12,
    1e12,
    0.0,
    1e-40,
    1e6,
    -7.5,
];

/// Applies one random mutation; returns what it did.
fn mutate(rng: &mut Rng, json: &mut Value, bin: &mut Vec<u8>) -> String {
    let mut ptrs = Vec::new();
    pointers(json, String::new(), &mut ptrs);
    // Numbers of the scene (transforms, colours, lights, cameras) mostly still bake, and so
    // reach every stage; numbers of the container (counts, offsets) mostly stop at the loader.
    let scene_number = |p: &&String| {
        ["/nodes/", "/materials/", "/extensions/", "/cameras/"]
            .iter()
            .any(|s| p.starts_with(s))
    };
    let all_numbers: Vec<&String> = ptrs
        .iter()
        .filter(|p| json.pointer(p).is_some_and(Value::is_number))
        .collect();
    let scene_numbers: Vec<&String> = all_numbers.iter().copied().filter(scene_number).collect();
    let pick = rng.below(10);
    let numbers = if pick < 4 && !scene_numbers.is_empty() {
        scene_numbers
    } else {
        all_numbers
    };
    match pick {
        0..=5 if !numbers.is_empty() => {
            let p = numbers[rng.below(numbers.len())].clone();
            let old = json.pointer(&p).and_then(Value::as_f64).unwrap_or(0.0);
            let new = match rng.below(4) {
                0 => json!(old + 1.0),
                1 => json!(old * 2.0),
                _ => {
                    let x = NUMBERS[rng.below(NUMBERS.len())];
                    if x.fract() == 0.0 && (0.0..1.9e19).contains(&x) {
                        json!(x as u64)
                    } else if x.fract() == 0.0 && x.abs() < 1e18 {
                        json!(x as i64)
                    } else {
                        json!(x)
                    }
                }
            };
            *json.pointer_mut(&p).unwrap() = new.clone();
            format!("{p} = {new}")
        }
        6 => {
            // Remove an object member.
            let p = &ptrs[rng.below(ptrs.len())];
            let Some((parent, key)) = p.rsplit_once('/') else {
                return "nothing".into();
            };
            match json.pointer_mut(parent) {
                Some(Value::Object(m)) => {
                    m.remove(&key.replace("~1", "/").replace("~0", "~"));
                    format!("remove {p}")
                }
                _ => "nothing".into(),
            }
        }
        7 => {
            let p = ptrs[rng.below(ptrs.len())].clone();
            let new =
                [json!(null), json!("x"), json!([]), json!({}), json!(-1)][rng.below(5)].clone();
            if p.is_empty() {
                return "nothing".into();
            }
            *json.pointer_mut(&p).unwrap() = new.clone();
            format!("{p} = {new}")
        }
        8 => {
            // Duplicate an array element (more nodes, primitives, children...).
            let arrays: Vec<&String> = ptrs
                .iter()
                .filter(|p| {
                    json.pointer(p)
                        .and_then(Value::as_array)
                        .is_some_and(|a| !a.is_empty())
                })
                .collect();
            if arrays.is_empty() {
                return "nothing".into();
            }
            let p = arrays[rng.below(arrays.len())].clone();
            let a = json.pointer_mut(&p).unwrap().as_array_mut().unwrap();
            let x = a[rng.below(a.len())].clone();
            a.push(x);
            format!("duplicate in {p}")
        }
        _ if bin.len() >= 4 && rng.below(8) > 0 => {
            let at = rng.below(bin.len() / 4) * 4;
            let f = FLOATS[rng.below(FLOATS.len())];
            bin[at..at + 4].copy_from_slice(&f.to_le_bytes());
            format!("bin[{at}] = {f}")
        }
        _ => {
            let n = rng.below(bin.len() + 1);
            bin.truncate(n);
            format!("bin truncated to {n}")
        }
    }
}

/// One mutant in this many is of the untrusted-input classes.
const UNTRUSTED_SHARE: usize = 5;

/// Files every mutant's folder holds, for the URIs of [`mutate_untrusted`] to name: a FIFO,
/// links out of the folder (to the marker file, to its folder, to `/dev/urandom`), a
/// directory, and a PNG whose header declares a huge image.
const PLANTED: [&str; 6] = [
    "fifo", "link-out", "linkdir", "urandom", "subdir", "bomb.png",
];

/// URIs that lead out of the folder or name special files; `{outside}` is the marker's
/// folder (absolute), `{secret}` the marker file (absolute).
const BAD_URIS: [&str; 17] = [
    "../outside/secret.txt",
    "%2E%2E/outside/secret.txt",
    "./../outside/secret.txt",
    "subdir/../../outside/secret.txt",
    "../../../../../../../../etc/passwd",
    "{secret}",
    "{outside}/secret.txt",
    "/proc/self/environ",
    "/dev/zero",
    "/dev/urandom",
    "link-out",
    "linkdir/secret.txt",
    "urandom",
    "fifo",
    "subdir",
    "bomb.png",
    "file:///etc/passwd",
];

/// Declared sizes of the image bombs, pixels (width, height).
const BOMBS: [(u32, u32); 5] = [
    (23170, 23170),
    (100_000, 100_000),
    (16385, 1),
    (1, 1 << 30),
    (16384, 16384),
];

/// Node scales at and past the extremes.
const SCALES: [f64; 8] = [1e-30, 1e-12, 1e-9, 1e-6, 1e6, 1e9, 1e30, 1e-300];

/// Instance and primitive counts of the explosions: a few hundred bake (or fail in the atlas)
/// within the time limit; the rest are past the default limits, and must be refused at once.
const EXPLOSIONS: [usize; 5] = [300, 10_001, 15_000, 25_000, 100_000];

/// Applies one untrusted-input mutation; returns what it did. `outside` is the absolute folder
/// of the marker file.
fn mutate_untrusted(rng: &mut Rng, json: &mut Value, bin: &mut Vec<u8>, outside: &Path) -> String {
    let uri = |rng: &mut Rng| {
        let outside = outside.display().to_string();
        BAD_URIS[rng.below(BAD_URIS.len())]
            .replace("{secret}", &format!("{outside}/secret.txt"))
            .replace("{outside}", &outside)
    };
    // Appends `value` to the top-level array `key` (made an array if it is not); its index.
    let push = |json: &mut Value, key: &str, value: Value| {
        if !json[key].is_array() {
            json[key] = json!([]);
        }
        let array = json[key].as_array_mut().unwrap();
        array.push(value);
        array.len() - 1
    };
    let len = |json: &Value, key: &str| json[key].as_array().map_or(0, Vec::len);
    match rng.below(7) {
        0 => {
            // An image at a bad URI, used as a material's base colour texture.
            let u = uri(rng);
            let image = push(json, "images", json!({"uri": u}));
            let texture = push(json, "textures", json!({"source": image}));
            if let Some(m) = json["materials"].as_array_mut().and_then(|m| m.first_mut())
                && m.is_object()
            {
                m["pbrMetallicRoughness"]["baseColorTexture"] = json!({"index": texture});
            }
            format!("image at {u:?}")
        }
        1 => {
            // A buffer at a bad URI: a new one, or the scene's own one.
            let u = uri(rng);
            let buffer = json!({"uri": u, "byteLength": bin.len().max(1)});
            let buffer = if rng.below(3) == 0 && len(json, "buffers") > 0 {
                json["buffers"][0] = buffer;
                0
            } else {
                push(json, "buffers", buffer)
            };
            format!("buffers[{buffer}] at {u:?}")
        }
        2 => {
            // An image bomb inside the glb (a bufferView image).
            let (w, h) = BOMBS[rng.below(BOMBS.len())];
            let png = crate::untrusted::png_bomb(w, h);
            let offset = bin.len();
            bin.extend_from_slice(&png);
            let view = push(
                json,
                "bufferViews",
                json!({"buffer": 0, "byteOffset": offset, "byteLength": png.len()}),
            );
            if json["buffers"][0].is_object() {
                json["buffers"][0]["byteLength"] = json!(bin.len());
            }
            let image = push(
                json,
                "images",
                json!({"bufferView": view, "mimeType": "image/png"}),
            );
            let texture = push(json, "textures", json!({"source": image}));
            if let Some(m) = json["materials"].as_array_mut().and_then(|m| m.first_mut())
                && m.is_object()
            {
                m["emissiveTexture"] = json!({"index": texture});
                m["pbrMetallicRoughness"]["baseColorTexture"] = json!({"index": texture});
            }
            format!("image bomb {w} x {h}")
        }
        3 => {
            // The whole scene scaled, or one node.
            let s = SCALES[rng.below(SCALES.len())];
            let nodes = len(json, "nodes");
            if rng.below(2) == 0 || nodes == 0 {
                let roots = json["scenes"][0]["nodes"].clone();
                let root = push(
                    json,
                    "nodes",
                    json!({"children": roots, "scale": [s, s, s]}),
                );
                json["scenes"][0]["nodes"] = json!([root]);
                format!("scene scaled by {s:e}")
            } else {
                let n = rng.below(nodes);
                if json["nodes"][n].is_object() {
                    json["nodes"][n]["scale"] = json!([s, s, s]);
                    json["nodes"][n].as_object_mut().map(|o| o.remove("matrix"));
                }
                format!("node {n} scaled by {s:e}")
            }
        }
        4 => {
            // Many nodes instancing one mesh.
            let n = EXPLOSIONS[rng.below(EXPLOSIONS.len())];
            let meshes = json["meshes"].as_array().map_or(0, Vec::len);
            let mesh = rng.below(meshes.max(1));
            let first = len(json, "nodes");
            if first == 0 {
                json["nodes"] = json!([]);
            }
            let side = (n as f64).sqrt().ceil() as usize;
            let nodes = json["nodes"].as_array_mut().unwrap();
            for k in 0..n {
                let (x, z) = ((k % side) as f64 * 2.0, (k / side) as f64 * 2.0);
                nodes.push(json!({"mesh": mesh, "translation": [x, 0.0, z]}));
            }
            if let Some(roots) = json["scenes"][0]["nodes"].as_array_mut() {
                roots.extend((first..first + n).map(|i| json!(i)));
            }
            format!("{n} nodes instancing mesh {mesh}")
        }
        5 => {
            // Many primitives in one mesh.
            let n = EXPLOSIONS[rng.below(EXPLOSIONS.len())];
            let meshes = json["meshes"].as_array().map_or(0, Vec::len);
            let mesh = rng.below(meshes.max(1));
            let prim = json["meshes"][mesh]["primitives"][0].clone();
            if prim.is_object() {
                json["meshes"][mesh]["primitives"] = Value::Array(vec![prim; n]);
            }
            format!("{n} primitives in mesh {mesh}")
        }
        _ => {
            // A deep chain of nodes, each scaled a little: a tree, but a tall one.
            let n = EXPLOSIONS[rng.below(EXPLOSIONS.len())];
            let first = len(json, "nodes");
            if first == 0 {
                json["nodes"] = json!([]);
            }
            let roots = json["scenes"][0]["nodes"].clone();
            let nodes = json["nodes"].as_array_mut().unwrap();
            for k in 0..n {
                let child = if k + 1 < n {
                    json!([first + k + 1])
                } else {
                    roots.clone()
                };
                nodes.push(json!({"children": child, "scale": [1.001, 1.001, 1.001]}));
            }
            json["scenes"][0]["nodes"] = json!([first]);
            format!("a chain of {n} nodes")
        }
    }
}

/// Whether mutants are only of the untrusted-input classes (`PENUMBRA_MUTANT_CLASSES`).
fn untrusted_only() -> bool {
    std::env::var("PENUMBRA_MUTANT_CLASSES").is_ok_and(|v| v == "untrusted")
}

/// Mutant `i` of the seed set: glb bytes and what was done. `outside` is the folder of the
/// marker file.
fn mutant(i: usize, bases: &[(&str, Vec<u8>)], outside: &Path) -> (Vec<u8>, String) {
    let mut rng = Rng(0x5EED_0000 + i as u64);
    let (name, base) = &bases[rng.below(bases.len())];
    let mut what = vec![name.to_string()];
    if untrusted_only() || i % UNTRUSTED_SHARE == UNTRUSTED_SHARE - 1 {
        let (mut json, mut bin) = split_glb(base);
        for _ in 0..[1, 1, 1, 2][rng.below(4)] {
            what.push(mutate_untrusted(&mut rng, &mut json, &mut bin, outside));
        }
        return (
            penumbra::write::to_glb(&json, bin).unwrap(),
            what.join("; "),
        );
    }
    if rng.below(10) == 0 {
        // Raw damage to the file: bit flips or a cut.
        let mut bytes = base.clone();
        if rng.below(2) == 0 {
            for _ in 0..1 + rng.below(8) {
                let at = rng.below(bytes.len());
                bytes[at] ^= 1 << rng.below(8);
                what.push(format!("flip byte {at}"));
            }
        } else {
            let n = rng.below(bytes.len());
            bytes.truncate(n);
            what.push(format!("file cut at {n}"));
        }
        return (bytes, what.join("; "));
    }
    let (mut json, mut bin) = split_glb(base);
    for _ in 0..[1, 1, 1, 2, 2, 3][rng.below(6)] {
        what.push(mutate(&mut rng, &mut json, &mut bin));
    }
    (
        penumbra::write::to_glb(&json, bin).unwrap(),
        what.join("; "),
    )
}

/// The folder beside a worker's folder that holds the marker file, and the marker.
fn plant_outside(dir: &Path) -> (PathBuf, String) {
    let outside = dir.with_file_name(format!(
        "{}-outside",
        dir.file_name().unwrap().to_string_lossy()
    ));
    let _ = std::fs::remove_dir_all(&outside);
    std::fs::create_dir_all(&outside).unwrap();
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos());
    let marker = format!("MARKER-{:x}-{nanos:x}", std::process::id());
    std::fs::write(outside.join("secret.txt"), &marker).unwrap();
    (std::fs::canonicalize(&outside).unwrap(), marker)
}

/// Creates the [`PLANTED`] files in a mutant's folder (off Unix, only the portable ones: no
/// FIFO or links).
fn plant(dir: &Path, #[cfg_attr(not(unix), allow(unused))] outside: &Path) {
    #[cfg(unix)]
    {
        let fifo = std::ffi::CString::new(dir.join("fifo").to_str().unwrap()).unwrap();
        // SAFETY: a valid NUL-terminated path.
        assert_eq!(unsafe { libc::mkfifo(fifo.as_ptr(), 0o644) }, 0, "mkfifo");
        std::os::unix::fs::symlink(outside.join("secret.txt"), dir.join("link-out")).unwrap();
        std::os::unix::fs::symlink(outside, dir.join("linkdir")).unwrap();
        std::os::unix::fs::symlink("/dev/urandom", dir.join("urandom")).unwrap();
    }
    std::fs::create_dir(dir.join("subdir")).unwrap();
    std::fs::write(
        dir.join("bomb.png"),
        crate::untrusted::png_bomb(23170, 23170),
    )
    .unwrap();
}

/// How a mutant's bake ended: baked, or refused with this message.
enum Outcome {
    Baked,
    Refused(String),
}

/// Bakes one mutant under the limit; `Err` says what went wrong. The marker (of the file
/// outside the folder) must be in neither the output nor the messages.
fn check(dir: &Path, glb: &[u8], outside: &Path, marker: &str) -> Result<Outcome, String> {
    let _ = std::fs::remove_dir_all(dir);
    std::fs::create_dir_all(dir).unwrap();
    plant(dir, outside);
    let input = dir.join("in.glb");
    std::fs::write(&input, glb).unwrap();
    let output = dir.join("out.glb");
    let mut child = Command::new(env!("CARGO_BIN_EXE_penumbra"))
        .arg("bake")
        .args([&input, &output])
        .args(["--budget", "300", "--patches", "32", "--resolution", "32"])
        .args(["--supersample", "1", "--threads", "1", "--quiet"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let start = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if start.elapsed() > LIMIT {
            let _ = child.kill();
            let _ = child.wait();
            return Err(format!("still running after {LIMIT:?}"));
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    let mut stderr = String::new();
    use std::io::Read;
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut stderr)
        .unwrap();
    if stderr.contains("panicked") {
        return Err(format!("panicked: {stderr}"));
    }
    if stderr.contains(marker) {
        return Err(format!("the outside marker is in the messages: {stderr}"));
    }
    if let Ok(out) = std::fs::read(&output)
        && out.windows(marker.len()).any(|w| w == marker.as_bytes())
    {
        return Err("the outside marker is in the output".into());
    }
    match status.code() {
        Some(0) => {}
        Some(1) if stderr.starts_with("error: ") && stderr.contains("in.glb") => {}
        Some(1) => return Err(format!("exit 1 without naming the file: {stderr}")),
        other => return Err(format!("exit {other:?}: {stderr}")),
    }
    if std::fs::read(&input).unwrap() != glb {
        return Err("the input changed".into());
    }
    let planted: Vec<PathBuf> = PLANTED.iter().map(|p| dir.join(p)).collect();
    let mut left: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p != &input && !(p == &output && status.success()) && !planted.contains(p))
        .collect();
    left.sort();
    if !left.is_empty() {
        return Err(format!("left behind: {left:?}"));
    }
    if std::fs::read_to_string(outside.join("secret.txt"))
        .ok()
        .as_deref()
        != Some(marker)
    {
        return Err("the file outside the folder changed".into());
    }
    Ok(if status.success() {
        Outcome::Baked
    } else {
        Outcome::Refused(stderr)
    })
}

/// A refusal's kind for the tally: the message with the file, numbers and quoted parts taken
/// out, cut to its first words.
fn kind_of_refusal(message: &str) -> String {
    let text = message.lines().next().unwrap_or("");
    let text = text.split_once(".glb: ").map_or(text, |(_, rest)| rest);
    let mut out = String::new();
    let mut quoted = false;
    for c in text.chars() {
        if c == '"' {
            quoted = !quoted;
            continue;
        }
        if quoted {
            continue;
        }
        out.push(if c.is_ascii_digit() { '#' } else { c });
    }
    let words: Vec<&str> = out.split_whitespace().take(9).collect();
    words.join(" ")
}

#[test]
fn mutants_of_the_fixtures_fail_cleanly() {
    let count = std::env::var("PENUMBRA_MUTANTS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(MUTANTS);
    let mut bases: Vec<(&str, Vec<u8>)> = vec![
        ("box-on-floor", fixtures::box_on_floor()),
        ("point-light", fixtures::point_light()),
        ("spot-light", fixtures::spot_light()),
        ("directional-light", fixtures::directional_light()),
        ("instanced", fixtures::instanced()),
        ("square-occluder", fixtures::square_occluder()),
        ("cornell-box", fixtures::cornell_box()),
        // Textures: an alpha-tested plate, an emissive texture, a textured floor, glass.
        ("masked-occluder", fixtures::textured::masked_occluder()),
        (
            "glass-pane",
            fixtures::textured::glass_pane(fixtures::textured::Glass::Blend(0.5)),
        ),
        ("half-lit-emitter", fixtures::textured::half_lit_emitter()),
        (
            "checker-room",
            fixtures::textured::floor_room(fixtures::textured::Floor::Checker {
                albedo: [0.8; 3],
                cells: 4,
            }),
        ),
    ];
    // More inputs to mutate: every .glb in the directory PENUMBRA_MUTANT_INPUTS (e.g. real
    // scenes; keep them small, each bake has the same time limit).
    if let Ok(dir) = std::env::var("PENUMBRA_MUTANT_INPUTS") {
        let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
            .unwrap_or_else(|e| panic!("PENUMBRA_MUTANT_INPUTS={dir}: {e}"))
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|x| x == "glb"))
            .collect();
        files.sort();
        for f in files {
            let name: &'static str = f.file_name().unwrap().to_string_lossy().into_owned().leak();
            bases.push((name, std::fs::read(&f).unwrap()));
        }
    }
    let from: usize = std::env::var("PENUMBRA_MUTANTS_FROM")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(0);
    let keep = Path::new(env!("CARGO_TARGET_TMPDIR")).join("mutants");
    let workers = 2;
    let start = Instant::now();
    type Tally = std::collections::BTreeMap<String, usize>;
    let (failures, baked, tally): (Vec<String>, usize, Tally) = std::thread::scope(|s| {
        let handles: Vec<_> = (0..workers)
            .map(|w| {
                let (bases, keep) = (&bases, &keep);
                s.spawn(move || {
                    let dir = crate::scratch(&format!("mutants-{w}"));
                    let (outside, marker) = plant_outside(&dir);
                    let (mut failed, mut baked) = (Vec::new(), 0);
                    let mut tally = Tally::new();
                    for i in (from + w..from + count).step_by(workers) {
                        let (glb, what) = mutant(i, bases, &outside);
                        match check(&dir, &glb, &outside, &marker) {
                            Ok(Outcome::Baked) => baked += 1,
                            Ok(Outcome::Refused(message)) => {
                                *tally.entry(kind_of_refusal(&message)).or_default() += 1;
                            }
                            Err(e) => {
                                std::fs::create_dir_all(keep).unwrap();
                                let path = keep.join(format!("mutant-{i}.glb"));
                                std::fs::write(&path, &glb).unwrap();
                                let kept = path.display();
                                failed.push(format!("mutant {i} ({what}), kept as {kept}: {e}"));
                            }
                        }
                    }
                    let _ = std::fs::remove_dir_all(&dir);
                    let _ = std::fs::remove_dir_all(&outside);
                    (failed, baked, tally)
                })
            })
            .collect();
        let mut all = (Vec::new(), 0, Tally::new());
        for h in handles {
            let (failed, baked, tally) = h.join().unwrap();
            all.0.extend(failed);
            all.1 += baked;
            for (k, n) in tally {
                *all.2.entry(k).or_default() += n;
            }
        }
        all
    });
    let refused = count - baked - failures.len();
    eprintln!(
        "{count} mutants in {:.0} s: {baked} baked (exit 0), {refused} refused cleanly (exit 1)",
        start.elapsed().as_secs_f64()
    );
    let mut kinds: Vec<(&String, &usize)> = tally.iter().collect();
    kinds.sort_by(|a, b| b.1.cmp(a.1).then(a.0.cmp(b.0)));
    for (kind, n) in kinds {
        eprintln!("{n:>7}  exit 1: {kind}");
    }
    assert!(
        failures.is_empty(),
        "{} of {count} mutants failed:\n{}",
        failures.len(),
        failures.join("\n")
    );
    // The mutants must reach the bake, not only the parser: error paths alone would miss hangs
    // and panics in the stages.
    if !untrusted_only() {
        assert!(baked * 4 >= count, "only {baked} of {count} mutants baked");
    }
}
