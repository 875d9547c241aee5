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

use crate::Rng;
use crate::output::split_glb;
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

/// Mutant `i` of the seed set: glb bytes and what was done.
fn mutant(i: usize, bases: &[(&str, Vec<u8>)]) -> (Vec<u8>, String) {
    let mut rng = Rng(0x5EED_0000 + i as u64);
    let (name, base) = &bases[rng.below(bases.len())];
    let mut what = vec![name.to_string()];
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
    (penumbra::write::to_glb(&json, bin), what.join("; "))
}

/// Bakes one mutant under the limit; `Err` says what went wrong.
fn check(dir: &Path, glb: &[u8]) -> Result<bool, String> {
    let _ = std::fs::remove_dir_all(dir);
    std::fs::create_dir_all(dir).unwrap();
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
    match status.code() {
        Some(0) => {}
        Some(1) if stderr.starts_with("error: ") && stderr.contains("in.glb") => {}
        Some(1) => return Err(format!("exit 1 without naming the file: {stderr}")),
        other => return Err(format!("exit {other:?}: {stderr}")),
    }
    if std::fs::read(&input).unwrap() != glb {
        return Err("the input changed".into());
    }
    let mut left: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p != &input && !(p == &output && status.success()))
        .collect();
    left.sort();
    if !left.is_empty() {
        return Err(format!("left behind: {left:?}"));
    }
    Ok(status.success())
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
    let (failures, baked): (Vec<String>, usize) = std::thread::scope(|s| {
        let handles: Vec<_> = (0..workers)
            .map(|w| {
                let (bases, keep) = (&bases, &keep);
                s.spawn(move || {
                    let dir = crate::scratch(&format!("mutants-{w}"));
                    let (mut failed, mut baked) = (Vec::new(), 0);
                    for i in (from + w..from + count).step_by(workers) {
                        let (glb, what) = mutant(i, bases);
                        match check(&dir, &glb) {
                            Ok(ok) => baked += usize::from(ok),
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
                    (failed, baked)
                })
            })
            .collect();
        let mut all = (Vec::new(), 0);
        for h in handles {
            let (failed, baked) = h.join().unwrap();
            all.0.extend(failed);
            all.1 += baked;
        }
        all
    });
    let refused = count - baked - failures.len();
    eprintln!("{count} mutants: {baked} baked, {refused} refused cleanly");
    assert!(
        failures.is_empty(),
        "{} of {count} mutants failed:\n{}",
        failures.len(),
        failures.join("\n")
    );
    // The mutants must reach the bake, not only the parser: error paths alone would miss hangs
    // and panics in the stages.
    assert!(baked * 4 >= count, "only {baked} of {count} mutants baked");
}
