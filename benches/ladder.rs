//! The scale ladder: bakes every rung of [`fixtures::ladder`] (about 5 000 to 100 000
//! triangles) with the release `penumbra` binary, one child process per bake, and reports time,
//! peak memory and the `--stats` counts, so that each change to the solver, the mesher or the
//! atlas is measured before and after on scenes of real size.
//!
//! ```text
//! cargo bench --bench ladder [-- --scenes a,b,c --timeout SECS --solver S --extra "ARGS"
//!                                --out FILE --title TITLE --keep DIR --bin PATH]
//! ```
//!
//! * `--scenes`: rung names, comma-separated (default: all, in increasing size).
//! * `--timeout`: seconds per bake (default 600); a bake over it is killed and reported as
//!   `timeout > N s`.
//! * `--solver S`: adds `--solver S` to every bake; `--extra "ARGS"`: more bake arguments
//!   (split at whitespace). A flag the binary does not know fails the bake, and the row says so.
//! * `--out FILE` (default `docs/bench-ladder.md`): the report is written there as a section
//!   `## TITLE` (default `Run`), replacing a section of the same title and keeping the others,
//!   so one file holds before and after. It is rewritten after every bake, so an interrupted
//!   run keeps the rungs it finished. The tables also go to stdout.
//! * `--keep DIR`: keep the generated glbs, baked glbs and stats there (default: a temporary
//!   directory, removed at the end).
//! * `--bin PATH`: the `penumbra` binary (default: the one `cargo bench` builds with this
//!   bench, `target/release/penumbra`).
//! * `--real DIR` (or the `PENUMBRA_REAL_SCENES` environment variable): a folder of real
//!   third-party scenes; `real_city_florence.glb` and `real_city_munich_lamps.glb`, when there,
//!   join the ladder as the rungs `florence` and `munich-lamps` (skipped when absent).
//! * `--accuracy SPP`: after each bake, `penumbra reference OUT --spp SPP --against` the bake's
//!   float lightmap: the RMSE (reference noise removed), bias and noise relative to the mean,
//!   overall and by region (ground, roof, wall; lit, shadow), as `penumbra reference --against`
//!   defines them.
//!
//! The first rung is `demo`, the shipped `fixtures/cornell-box.glb`.
//!
//! Each bake runs `penumbra bake IN OUT --stats stats.json --quiet [--solver S] [ARGS]` with the
//! default options otherwise; the bench measures the child's wall time and peak resident
//! memory (`ru_maxrss` from `wait4`), and reads from `stats.json` the per-stage seconds, the
//! counts (triangles, polygons, elements, vertices, emitters, lights), the `discontinuity`
//! counters, every numeric counter under `solve` (so a new solver's counters show up without
//! editing this file), the lightmap size and the warnings. Then the growth exponent `k` in
//! `time ∝ triangles^k`: a least-squares fit over the rungs that finished, per scene family,
//! and pairwise between consecutive rungs.
//!
//! The machine may be shared and noisy: compare ratios within one run.

use penumbra::fixtures::ladder::{self, LadderScene};
use serde_json::Value;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Stages as `--stats` names them in `timings_s`, in pipeline order.
/// What `--help` (or an unknown argument) prints.
const USAGE: &str = "usage: cargo bench --bench ladder [-- --scenes a,b,c --timeout SECS \
    --solver S --extra \"ARGS\" --out FILE --title TITLE --keep DIR --bin PATH --real DIR \
    --accuracy SPP] (see the module doc in benches/ladder.rs)";

const STAGES: [&str; 9] = [
    "load",
    "visibility",
    "discontinuity",
    "mesh",
    "solve",
    "atlas",
    "lightmap",
    "write",
    "total",
];

struct Options {
    scenes: Vec<String>,
    timeout: Duration,
    extra: Vec<String>,
    out: PathBuf,
    title: String,
    keep: Option<PathBuf>,
    bin: PathBuf,
    real: Option<PathBuf>,
    accuracy: Option<u32>,
}

/// The folder of real scenes (`--real`), for the file rungs' generators.
static REAL: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();

fn read_real(name: &str) -> Vec<u8> {
    let dir = REAL.get().expect("--real is set before the real rungs run");
    std::fs::read(dir.join(name)).expect("cannot read the real scene")
}

fn demo() -> Vec<u8> {
    std::fs::read(Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/cornell-box.glb"))
        .expect("cannot read fixtures/cornell-box.glb")
}

fn florence() -> Vec<u8> {
    read_real("real_city_florence.glb")
}

fn munich_lamps() -> Vec<u8> {
    read_real("real_city_munich_lamps.glb")
}

/// The rungs that are files: the demo first, the real scenes (in `o.real`, when present) last.
fn file_rungs(o: &Options) -> (Vec<LadderScene>, Vec<LadderScene>) {
    let first = vec![LadderScene {
        name: "demo",
        description: "the shipped demo: a Cornell box under its area light",
        triangles: 36,
        generate: demo,
    }];
    let mut last = Vec::new();
    if let Some(dir) = &o.real {
        let _ = REAL.set(dir.clone());
        let real = [
            (
                "florence",
                "real OpenStreetMap city (Florence) under a sun",
                35_373,
                "real_city_florence.glb",
                florence as fn() -> Vec<u8>,
            ),
            (
                "munich-lamps",
                "real OpenStreetMap city (Munich) under 64 lamp panels",
                39_064,
                "real_city_munich_lamps.glb",
                munich_lamps,
            ),
        ];
        for (name, description, triangles, file, generate) in real {
            if dir.join(file).is_file() {
                last.push(LadderScene {
                    name,
                    description,
                    triangles,
                    generate,
                });
            } else {
                eprintln!(
                    "{} is absent: rung {name} skipped",
                    dir.join(file).display()
                );
            }
        }
    }
    (first, last)
}

fn options() -> Options {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut o = Options {
        scenes: Vec::new(),
        timeout: Duration::from_secs(600),
        extra: Vec::new(),
        out: root.join("docs").join("bench-ladder.md"),
        title: "Run".into(),
        keep: None,
        bin: PathBuf::from(env!("CARGO_BIN_EXE_penumbra")),
        real: std::env::var_os("PENUMBRA_REAL_SCENES").map(PathBuf::from),
        accuracy: None,
    };
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut value = || args.next().unwrap_or_else(|| panic!("{a} needs a value"));
        match a.as_str() {
            "--scenes" => {
                o.scenes = value()
                    .split(',')
                    .map(str::trim)
                    .filter(|s| !s.is_empty())
                    .map(String::from)
                    .collect()
            }
            "--timeout" => {
                let v = value();
                let secs: f64 = v.parse().expect("--timeout SECS");
                o.timeout = Duration::from_secs_f64(secs.max(1.0));
            }
            "--solver" => {
                o.extra.push("--solver".into());
                o.extra.push(value());
            }
            "--extra" => o.extra.extend(value().split_whitespace().map(String::from)),
            "--out" => o.out = PathBuf::from(value()),
            "--title" => o.title = value(),
            "--keep" => o.keep = Some(PathBuf::from(value())),
            "--bin" => o.bin = PathBuf::from(value()),
            "--real" => o.real = Some(PathBuf::from(value())),
            "--accuracy" => o.accuracy = Some(value().parse().expect("--accuracy SPP")),
            "--bench" => {} // `cargo bench` passes it.
            "--help" | "-h" => {
                println!("{USAGE}");
                std::process::exit(0);
            }
            other => {
                // A typo must not start an hour of baking that overwrites the report.
                eprintln!("unknown argument {other:?}\n{USAGE}");
                std::process::exit(2);
            }
        }
    }
    o
}

/// How a bake ended.
enum Outcome {
    Ok,
    /// Non-zero exit or killed by a signal: the message (first line of stderr, or the panic).
    Failed(String),
    /// Killed after the time limit.
    Timeout,
}

/// One rung's measurements.
struct Row {
    name: &'static str,
    description: &'static str,
    /// Triangles of the generated scene (from the stats when the bake finished, else as the
    /// library's loader counts them).
    triangles: usize,
    glb_bytes: usize,
    wall_s: f64,
    /// Peak resident memory of the child, MiB.
    peak_rss_mib: f64,
    outcome: Outcome,
    stats: Option<Value>,
    /// `penumbra reference --against`'s `accuracy` (with `--accuracy`).
    accuracy: Option<Value>,
}

fn main() {
    let o = options();
    let (first, last) = file_rungs(&o);
    let all: Vec<LadderScene> = first
        .into_iter()
        .chain(ladder::ladder())
        .chain(last)
        .collect();
    let rungs: Vec<LadderScene> = if o.scenes.is_empty() {
        all.clone()
    } else {
        o.scenes
            .iter()
            .map(|s| {
                *all.iter().find(|r| r.name == s).unwrap_or_else(|| {
                    let names: Vec<&str> = all.iter().map(|r| r.name).collect();
                    panic!("unknown scene {s:?}; one of {}", names.join(", "))
                })
            })
            .collect()
    };
    assert!(
        o.bin.exists(),
        "{} does not exist: run `cargo build --release` first, or pass --bin",
        o.bin.display()
    );
    let (dir, temporary) = match &o.keep {
        Some(d) => (d.clone(), false),
        None => (
            std::env::temp_dir().join(format!("penumbra-ladder-{}", std::process::id())),
            true,
        ),
    };
    std::fs::create_dir_all(&dir).expect("cannot create the work directory");
    let header = Header::now();
    let start = Instant::now();
    let mut rows: Vec<Row> = Vec::new();
    for rung in &rungs {
        eprintln!(
            "[{:7.1} s] {}: generating",
            start.elapsed().as_secs_f64(),
            rung.name
        );
        let glb = (rung.generate)();
        let input = dir.join(format!("{}.glb", rung.name));
        std::fs::write(&input, &glb).expect("cannot write the scene");
        eprintln!(
            "[{:7.1} s] {}: baking ({:.1} MiB glb)",
            start.elapsed().as_secs_f64(),
            rung.name,
            glb.len() as f64 / 1048576.0
        );
        // The exact count, as the baker's loader sees it.
        let triangles = penumbra::load::from_bytes(glb.clone(), &input)
            .and_then(|g| penumbra::load::scene(&g))
            .map_or(rung.triangles, |s| s.triangles.len());
        let row = bake(&o, &dir, rung, &input, glb.len(), triangles);
        eprintln!(
            "[{:7.1} s] {}: {} in {:.1} s, peak {:.0} MiB",
            start.elapsed().as_secs_f64(),
            rung.name,
            row.status(&o),
            row.wall_s,
            row.peak_rss_mib
        );
        rows.push(row);
        // Rewrite after every bake: an interrupted run keeps what it measured.
        let section = report(&rows, &rungs, &o, &header, start.elapsed(), false);
        write_section(&o.out, &o.title, &section);
    }
    let section = report(&rows, &rungs, &o, &header, start.elapsed(), true);
    print!("## {}\n\n{section}", o.title);
    write_section(&o.out, &o.title, &section);
    eprintln!("written to {}", o.out.display());
    if temporary {
        let _ = std::fs::remove_dir_all(&dir);
    }
}

/// Bakes one rung in a child process, with the time limit; measures wall time and peak RSS.
// The child is reaped by `libc::wait4` (std's `wait` would lose the resource usage).
#[allow(clippy::zombie_processes)]
fn bake(
    o: &Options,
    dir: &Path,
    rung: &LadderScene,
    input: &Path,
    glb_bytes: usize,
    triangles: usize,
) -> Row {
    let output = dir.join(format!("{}.baked.glb", rung.name));
    let stats_path = dir.join(format!("{}.stats.json", rung.name));
    let stderr_path = dir.join(format!("{}.stderr.txt", rung.name));
    let exr_path = dir.join(format!("{}.exr", rung.name));
    let _ = std::fs::remove_file(&stats_path);
    let stderr = std::fs::File::create(&stderr_path).expect("cannot create the stderr file");
    let started = Instant::now();
    let mut child = Command::new(&o.bin)
        .arg("bake")
        .arg(input)
        .arg(&output)
        .arg("--stats")
        .arg(&stats_path)
        .arg("--quiet")
        .args(
            o.accuracy
                .map(|_| ["--exr".into(), exr_path.clone()])
                .into_iter()
                .flatten(),
        )
        .args(&o.extra)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(stderr)
        .spawn()
        .expect("cannot start penumbra");
    let pid = child.id() as libc::pid_t;
    let mut status: libc::c_int = 0;
    // SAFETY: rusage is plain old data; zeroed is a valid value.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    let mut timed_out = false;
    loop {
        // SAFETY: `pid` is our own child, not yet reaped (std's `Child` is never waited on).
        let r = unsafe { libc::wait4(pid, &mut status, libc::WNOHANG, &mut usage) };
        if r == pid {
            break;
        }
        if r < 0 {
            let e = std::io::Error::last_os_error();
            if e.kind() == std::io::ErrorKind::Interrupted {
                continue;
            }
            panic!("wait4: {e}");
        }
        if !timed_out && started.elapsed() > o.timeout {
            timed_out = true;
            let _ = child.kill(); // SIGKILL; reaped by the next wait4
            continue;
        }
        std::thread::sleep(Duration::from_millis(if timed_out { 10 } else { 100 }));
    }
    let wall_s = started.elapsed().as_secs_f64();
    // Linux reports ru_maxrss in KiB.
    let peak_rss_mib = usage.ru_maxrss as f64 / 1024.0;
    let outcome = if timed_out {
        Outcome::Timeout
    } else if libc::WIFEXITED(status) && libc::WEXITSTATUS(status) == 0 {
        Outcome::Ok
    } else {
        let text = std::fs::read_to_string(&stderr_path).unwrap_or_default();
        let how = if libc::WIFEXITED(status) {
            format!("exit {}", libc::WEXITSTATUS(status))
        } else if libc::WIFSIGNALED(status) {
            format!("signal {}", libc::WTERMSIG(status))
        } else {
            format!("status {status}")
        };
        Outcome::Failed(format!("{how}: {}", first_message(&text)))
    };
    let stats = match outcome {
        Outcome::Ok => std::fs::read(&stats_path)
            .ok()
            .and_then(|b| serde_json::from_slice::<Value>(&b).ok()),
        _ => None,
    };
    let triangles = stats
        .as_ref()
        .and_then(|s| s["triangles"].as_u64())
        .map_or(triangles, |t| t as usize);
    let accuracy = match (o.accuracy, &outcome) {
        (Some(spp), Outcome::Ok) => accuracy(o, dir, rung, &output, &exr_path, spp),
        _ => None,
    };
    Row {
        name: rung.name,
        description: rung.description,
        triangles,
        glb_bytes,
        wall_s,
        peak_rss_mib,
        outcome,
        stats,
        accuracy,
    }
}

/// `penumbra reference BAKED --spp SPP --against EXR`'s accuracy, or `None` when it failed.
fn accuracy(
    o: &Options,
    dir: &Path,
    rung: &LadderScene,
    baked: &Path,
    exr: &Path,
    spp: u32,
) -> Option<Value> {
    let stats = dir.join(format!("{}.reference.json", rung.name));
    let status = Command::new(&o.bin)
        .arg("reference")
        .arg(baked)
        .arg("--out")
        .arg(dir.join(format!("{}.reference.exr", rung.name)))
        .arg("--spp")
        .arg(spp.to_string())
        .arg("--against")
        .arg(exr)
        .arg("--stats")
        .arg(&stats)
        .arg("--quiet")
        .args(sky_of(&o.extra))
        .stdin(Stdio::null())
        .status()
        .ok()?;
    if !status.success() {
        eprintln!("{}: the reference failed ({status})", rung.name);
        return None;
    }
    let json: Value = serde_json::from_slice(&std::fs::read(&stats).ok()?).ok()?;
    Some(json["accuracy"].clone())
}

/// The `--sky R,G,B` among the bake's extra arguments, for the reference to match.
fn sky_of(extra: &[String]) -> Vec<String> {
    extra
        .windows(2)
        .find(|w| w[0] == "--sky")
        .map(|w| w.to_vec())
        .unwrap_or_default()
}

/// The first line of stderr; for a panic, the `panicked at` line and the message after it.
fn first_message(stderr: &str) -> String {
    let lines: Vec<&str> = stderr.lines().filter(|l| !l.trim().is_empty()).collect();
    match lines.iter().position(|l| l.contains("panicked at")) {
        Some(i) => {
            let mut m = lines[i].trim().to_string();
            if let Some(next) = lines.get(i + 1) {
                m.push(' ');
                m.push_str(next.trim());
            }
            m
        }
        None => lines
            .first()
            .map_or_else(|| "(no message)".into(), |l| l.trim().to_string()),
    }
}

impl Row {
    fn finished(&self) -> bool {
        matches!(self.outcome, Outcome::Ok)
    }

    fn status(&self, o: &Options) -> String {
        match &self.outcome {
            Outcome::Ok => "ok".into(),
            Outcome::Timeout => format!("timeout > {} s", o.timeout.as_secs()),
            Outcome::Failed(m) => format!("failed ({m})"),
        }
    }

    /// A number from the stats by JSON pointer (`/timings_s/solve`).
    fn num(&self, pointer: &str) -> Option<f64> {
        self.stats.as_ref()?.pointer(pointer)?.as_f64()
    }

    fn total_s(&self) -> Option<f64> {
        self.num("/timings_s/total")
    }
}

/// What the header line says about the run.
struct Header {
    date: String,
    commit: String,
    threads: usize,
    load_before: String,
    command: String,
}

impl Header {
    fn now() -> Header {
        let git = |args: &[&str]| {
            Command::new("git")
                .args(args)
                .current_dir(env!("CARGO_MANIFEST_DIR"))
                .output()
                .ok()
                .filter(|out| out.status.success())
                .map(|out| String::from_utf8_lossy(&out.stdout).trim().to_string())
        };
        let mut commit = git(&["rev-parse", "--short", "HEAD"]).unwrap_or_else(|| "unknown".into());
        if git(&["status", "--porcelain", "--untracked-files=no"]).is_some_and(|s| !s.is_empty()) {
            commit.push_str(" (with uncommitted changes)");
        }
        let mut command = String::from("cargo bench --bench ladder");
        let args: Vec<String> = std::env::args()
            .skip(1)
            .filter(|a| a != "--bench")
            .collect();
        if !args.is_empty() {
            command.push_str(" --");
            for a in args {
                if a.contains(' ') || a.is_empty() {
                    let _ = write!(command, " \"{a}\"");
                } else {
                    let _ = write!(command, " {a}");
                }
            }
        }
        Header {
            date: today(),
            commit,
            threads: std::thread::available_parallelism().map_or(1, |n| n.get()),
            load_before: loadavg(),
            command,
        }
    }
}

/// The report section (without its `## title` line).
fn report(
    rows: &[Row],
    rungs: &[LadderScene],
    o: &Options,
    h: &Header,
    wall: Duration,
    complete: bool,
) -> String {
    let mut s = String::new();
    let w = &mut s;
    let extra = if o.extra.is_empty() {
        "default options".to_string()
    } else {
        format!("default options plus `{}`", o.extra.join(" "))
    };
    let _ = writeln!(
        w,
        "`{}`: {} (UTC), commit `{}`, {} threads (load average {} before, {} now); \
         `penumbra bake --stats --quiet`, {extra}; time limit {} s per bake; whole run {:.0} s{}. \
         Machine: 2 shared cores; compare ratios within one run.\n",
        h.command,
        h.date,
        h.commit,
        h.threads,
        h.load_before,
        loadavg(),
        o.timeout.as_secs(),
        wall.as_secs_f64(),
        if complete {
            String::new()
        } else {
            format!(
                " (**partial**: {} of {} rungs so far)",
                rows.len(),
                rungs.len()
            )
        }
    );

    // Times.
    let _ = writeln!(w, "### Time (s) and memory\n");
    let _ = write!(w, "| scene | triangles | polygons | elements | vertices |");
    for st in STAGES {
        let _ = write!(w, " {st} |");
    }
    let _ = writeln!(w, " wall | peak RSS MiB | status |");
    let _ = write!(w, "|---|--:|--:|--:|--:|");
    for _ in STAGES {
        let _ = write!(w, "--:|");
    }
    let _ = writeln!(w, "--:|--:|---|");
    for r in rows {
        let _ = write!(
            w,
            "| {} | {} | {} | {} | {} |",
            r.name,
            r.triangles,
            int(r.num("/polygons")),
            int(r.num("/elements")),
            int(r.num("/vertices"))
        );
        for st in STAGES {
            let _ = write!(w, " {} |", opt_secs(r.num(&format!("/timings_s/{st}"))));
        }
        let _ = writeln!(
            w,
            " {} | {:.0} | {} |",
            secs(r.wall_s),
            r.peak_rss_mib,
            escape(&r.status(o))
        );
    }
    let _ = writeln!(w);

    // Accuracy.
    if rows.iter().any(|r| r.accuracy.is_some()) {
        const REGIONS: [&str; 6] = [
            "ground-lit",
            "ground-shadow",
            "roof-lit",
            "roof-shadow",
            "wall-lit",
            "wall-shadow",
        ];
        let _ = writeln!(
            w,
            "### Accuracy against `penumbra reference` (RMSE, reference noise removed, % of the mean)\n"
        );
        let _ = write!(w, "| scene | RMSE | bias | noise |");
        for r in REGIONS {
            let _ = write!(w, " {r} |");
        }
        let _ = writeln!(w);
        let _ = writeln!(w, "|---|--:|--:|--:|{}", "--:|".repeat(REGIONS.len()));
        let pct = |v: &Value| {
            v.as_f64()
                .map_or("-".into(), |x| format!("{:.1}", 100.0 * x))
        };
        for r in rows {
            let Some(a) = &r.accuracy else { continue };
            let _ = write!(
                w,
                "| {} | {} | {} | {} |",
                r.name,
                pct(&a["all"]["rmse"]),
                pct(&a["all"]["bias"]),
                pct(&a["all"]["noise"])
            );
            for g in REGIONS {
                let _ = write!(w, " {} |", pct(&a["regions"][g]["rmse"]));
            }
            let _ = writeln!(w);
        }
        let _ = writeln!(w);
    }

    // Counts.
    let _ = writeln!(w, "### Counts\n");
    let _ = writeln!(
        w,
        "| scene | what | glb MiB | instances | area emitters | punctual lights | lightmap | texels/m | warnings |"
    );
    let _ = writeln!(w, "|---|---|--:|--:|--:|--:|--:|--:|--:|");
    for r in rows {
        let lightmap = match (r.num("/lightmap_width"), r.num("/lightmap_height")) {
            (Some(a), Some(b)) => format!("{a}x{b}"),
            _ => "-".into(),
        };
        let warnings = r
            .stats
            .as_ref()
            .and_then(|s| s["warnings"].as_array())
            .map_or("-".into(), |a| a.len().to_string());
        let _ = writeln!(
            w,
            "| {} | {} | {:.2} | {} | {} | {} | {lightmap} | {} | {warnings} |",
            r.name,
            r.description,
            r.glb_bytes as f64 / 1048576.0,
            int(r.num("/instances")),
            int(r.num("/area_emitters")),
            int(r.num("/punctual_lights")),
            r.num("/texels_per_unit")
                .map_or("-".into(), |t| format!("{t:.2}")),
        );
    }
    let _ = writeln!(w);

    // Discontinuity and solve counters, generically: every numeric field present.
    for (title, pointer) in [
        ("Discontinuity counters (`discontinuity`)", "/discontinuity"),
        ("Solve counters (`solve`)", "/solve"),
    ] {
        let per_row: Vec<Vec<(String, f64)>> = rows
            .iter()
            .map(|r| {
                let mut out = Vec::new();
                if let Some(v) = r.stats.as_ref().and_then(|s| s.pointer(pointer)) {
                    flatten("", v, &mut out);
                }
                out
            })
            .collect();
        let mut keys: Vec<String> = Vec::new();
        for row in &per_row {
            for (k, _) in row {
                if !keys.contains(k) {
                    keys.push(k.clone());
                }
            }
        }
        if keys.is_empty() {
            continue;
        }
        let _ = writeln!(w, "### {title}\n");
        let _ = write!(w, "| scene |");
        for k in &keys {
            let _ = write!(w, " {k} |");
        }
        let _ = writeln!(w);
        let _ = write!(w, "|---|");
        for _ in &keys {
            let _ = write!(w, "--:|");
        }
        let _ = writeln!(w);
        for (r, vals) in rows.iter().zip(&per_row) {
            if !r.finished() {
                continue;
            }
            let _ = write!(w, "| {} |", r.name);
            for k in &keys {
                let v = vals.iter().find(|(key, _)| key == k).map(|(_, v)| *v);
                let _ = write!(w, " {} |", number(v));
            }
            let _ = writeln!(w);
        }
        let _ = writeln!(w);
    }

    // Growth.
    let _ = writeln!(w, "### Growth: k in time ∝ triangles^k\n");
    let done: Vec<&Row> = rows
        .iter()
        .filter(|r| r.finished() && r.total_s().is_some_and(|t| t > 0.0))
        .collect();
    let total = |r: &Row| r.total_s().unwrap_or(f64::NAN);
    let mut fits = Vec::new();
    let all: Vec<(f64, f64)> = done
        .iter()
        .map(|r| (r.triangles as f64, total(r)))
        .collect();
    fits.push(("all finished rungs".to_string(), all));
    let mut families: Vec<&str> = Vec::new();
    for r in &done {
        let f = family(r.name);
        if !families.contains(&f) {
            families.push(f);
        }
    }
    for f in families {
        let pts: Vec<(f64, f64)> = done
            .iter()
            .filter(|r| family(r.name) == f)
            .map(|r| (r.triangles as f64, total(r)))
            .collect();
        fits.push((format!("{f} family"), pts));
    }
    let _ = writeln!(
        w,
        "Total bake time (`timings_s.total`), least-squares fit of log t against log triangles:\n"
    );
    let _ = writeln!(w, "| rungs | n | k |");
    let _ = writeln!(w, "|---|--:|--:|");
    for (name, pts) in &fits {
        if pts.len() >= 2 {
            let _ = writeln!(w, "| {name} | {} | {} |", pts.len(), fmt_k(fit(pts)));
        }
    }
    let _ = writeln!(w);
    let _ = writeln!(
        w,
        "Pairwise, between consecutive finished rungs (k only where the triangle counts differ \
         by 10 % or more; across families it mixes scene kinds), then between consecutive rungs \
         of one family:\n"
    );
    let _ = writeln!(w, "| from | to | triangles x | time x | k |");
    let _ = writeln!(w, "|---|---|--:|--:|--:|");
    let mut pairs: Vec<(&Row, &Row)> = done.windows(2).map(|p| (p[0], p[1])).collect();
    for (i, a) in done.iter().enumerate() {
        let next = done[i + 1..]
            .iter()
            .find(|b| family(b.name) == family(a.name));
        if let Some(b) = next
            && !pairs
                .iter()
                .any(|(x, y)| x.name == a.name && y.name == b.name)
        {
            pairs.push((a, b));
        }
    }
    for (a, b) in pairs {
        let tx = b.triangles as f64 / a.triangles as f64;
        let sx = total(b) / total(a);
        let k = if tx.ln().abs() >= 1.1f64.ln() {
            sx.ln() / tx.ln()
        } else {
            f64::NAN
        };
        let _ = writeln!(
            w,
            "| {} | {} | {:.2} | {:.2} | {} |",
            a.name,
            b.name,
            tx,
            sx,
            fmt_k(k)
        );
    }
    let _ = writeln!(w);
    // Per stage, over all finished rungs.
    if done.len() >= 2 {
        let _ = writeln!(w, "Per stage, fit over all finished rungs:\n");
        let _ = write!(w, "|");
        for st in STAGES {
            let _ = write!(w, " {st} |");
        }
        let _ = writeln!(w);
        let _ = write!(w, "|");
        for _ in STAGES {
            let _ = write!(w, "--:|");
        }
        let _ = writeln!(w);
        let _ = write!(w, "|");
        for st in STAGES {
            let pts: Vec<(f64, f64)> = done
                .iter()
                .filter_map(|r| {
                    let t = r.num(&format!("/timings_s/{st}"))?;
                    (t > 0.0).then_some((r.triangles as f64, t))
                })
                .collect();
            let k = if pts.len() >= 2 { fit(&pts) } else { f64::NAN };
            let _ = write!(w, " {} |", fmt_k(k));
        }
        let _ = writeln!(w, "\n");
    }
    s
}

/// The scene family: the name without its size suffix (`town-25k` -> `town`).
fn family(name: &str) -> &str {
    name.rsplit_once('-').map_or(name, |(f, _)| f)
}

/// Every numeric leaf of `v` (objects flattened with `.`; arrays skipped), in order.
fn flatten(prefix: &str, v: &Value, out: &mut Vec<(String, f64)>) {
    match v {
        Value::Object(m) => {
            for (k, v) in m {
                let key = if prefix.is_empty() {
                    k.clone()
                } else {
                    format!("{prefix}.{k}")
                };
                flatten(&key, v, out);
            }
        }
        Value::Number(n) => {
            if let Some(x) = n.as_f64() {
                out.push((prefix.to_string(), x));
            }
        }
        _ => {}
    }
}

/// Least-squares slope of log y against log x.
fn fit(pts: &[(f64, f64)]) -> f64 {
    let n = pts.len() as f64;
    let (lx, ly): (Vec<f64>, Vec<f64>) = pts.iter().map(|&(x, y)| (x.ln(), y.ln())).unzip();
    let mx = lx.iter().sum::<f64>() / n;
    let my = ly.iter().sum::<f64>() / n;
    let sxy: f64 = lx.iter().zip(&ly).map(|(x, y)| (x - mx) * (y - my)).sum();
    let sxx: f64 = lx.iter().map(|x| (x - mx) * (x - mx)).sum();
    if sxx > 0.0 { sxy / sxx } else { f64::NAN }
}

fn fmt_k(k: f64) -> String {
    if k.is_finite() {
        format!("{k:.2}")
    } else {
        "-".into()
    }
}

/// Replaces the section `## title` of the file at `path` (up to the next `## ` heading) by
/// `body`, or appends it; a new file starts with a short introduction.
fn write_section(path: &Path, title: &str, body: &str) {
    let old = std::fs::read_to_string(path).unwrap_or_else(|_| INTRO.to_string());
    let heading = format!("## {title}");
    let mut out = String::new();
    let mut lines = old.lines().peekable();
    let mut replaced = false;
    while let Some(line) = lines.next() {
        if line.trim_end() == heading && !replaced {
            replaced = true;
            let _ = write!(out, "{heading}\n\n{body}");
            while let Some(next) = lines.peek() {
                if next.starts_with("## ") {
                    break;
                }
                lines.next();
            }
        } else {
            out.push_str(line);
            out.push('\n');
        }
    }
    if !replaced {
        if !out.ends_with("\n\n") {
            out.push('\n');
        }
        let _ = write!(out, "{heading}\n\n{body}");
    }
    if let Some(dir) = path.parent() {
        let _ = std::fs::create_dir_all(dir);
    }
    if let Err(e) = std::fs::write(path, out) {
        eprintln!("could not write {}: {e}", path.display());
    }
}

const INTRO: &str = "# Scale ladder benchmark

```sh
cargo bench --bench ladder  # [-- --scenes a,b,c --timeout SECS --solver S --extra \"ARGS\" --out FILE --title TITLE]
```

`benches/ladder.rs` generates the rungs of `penumbra::fixtures::ladder` (box grids, towns under
the sun, a town at night lit by street lamps, a furnished house interior; about 5 000 to 100 000
triangles), bakes each with the release `penumbra` binary in a child process (`penumbra bake
--stats --quiet`, default options unless `--solver` / `--extra` add some) under a time limit, and
reports per-stage seconds from `--stats`, the child's wall time and peak resident memory
(`ru_maxrss`), the counts, and how the bake time grows with the triangle count. Each run is a
section below (`--title`), replaced when rerun with the same title.
";

fn int(v: Option<f64>) -> String {
    v.map_or("-".into(), |x| format!("{x:.0}"))
}

fn number(v: Option<f64>) -> String {
    match v {
        None => "-".into(),
        Some(0.0) => "0".into(), // also -0
        Some(x) if x == x.trunc() && x.abs() < 1e15 => format!("{x:.0}"),
        Some(x) if x.abs() >= 0.01 => format!("{x:.3}"),
        Some(x) => format!("{x:.2e}"),
    }
}

fn opt_secs(t: Option<f64>) -> String {
    t.map_or("-".into(), secs)
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

fn escape(s: &str) -> String {
    s.replace('|', "\\|")
}

/// The 1-minute load average (Linux), to tell a quiet machine from a busy one.
fn loadavg() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|s| s.split_whitespace().next().map(str::to_string))
        .unwrap_or_else(|| "n/a".into())
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
