//! Sweeps the element budget for every mesher on a scene (direct light only) and charts the RMS
//! error in the floor's shadows against elements and against time.
//!
//! ```text
//! cargo run --release --example mesher_sweep [SCENE.glb] [OUT_DIR]
//! ```
//!
//! Defaults: `fixtures/cornell-box.glb` and `docs/`. Writes `OUT_DIR/mesher-sweep-<scene>.svg`
//! and `.json`. Timings are wall times on whatever machine runs it: compare ratios within one
//! run.

use penumbra::BakeOptions;
use penumbra::mesh::Mesher;
use std::path::PathBuf;

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args_os().skip(1);
    let scene = args
        .next()
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("fixtures/cornell-box.glb"));
    let out = args
        .next()
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("docs"));
    let gltf = penumbra::load::read(&scene)?;
    let base = BakeOptions {
        resolution: Some(256),
        ..Default::default()
    };
    let budgets = [500, 1000, 2000, 4000, 8000, 16000];
    let meshers = [Mesher::Uniform, Mesher::Adaptive, Mesher::Discontinuity];
    let points = penumbra::compare::sweep(&gltf, &meshers, &budgets, &base)?;
    println!("| mesher | budget | elements | seconds | RMS | max |");
    println!("|---|---|---|---|---|---|");
    for p in &points {
        println!(
            "| {:?} | {} | {} | {:.3} | {:.4} | {:.3} |",
            p.mesher, p.budget, p.elements, p.seconds, p.error.rms, p.error.max
        );
    }
    let name = scene
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "scene".into());
    let svg = penumbra::compare::chart_svg(&name, &points).map_err(anyhow::Error::msg)?;
    std::fs::create_dir_all(&out)?;
    penumbra::write::write_atomically(
        &out.join(format!("mesher-sweep-{name}.svg")),
        svg.as_bytes(),
    )?;
    penumbra::write::write_atomically(
        &out.join(format!("mesher-sweep-{name}.json")),
        &serde_json::to_vec_pretty(&points)?,
    )?;
    Ok(())
}
