//! Writes the generated test scenes of `penumbra::fixtures` as glb files.
//!
//! ```text
//! cargo run --example make_fixtures [OUTPUT_DIR]
//! ```
//!
//! `OUTPUT_DIR` defaults to `fixtures` (relative to the current directory, so run it from the
//! repository root). Each scene becomes `OUTPUT_DIR/<name>.glb`, e.g. `fixtures/cornell-box.glb`;
//! the output is deterministic, so re-running it leaves the files unchanged.

use std::path::PathBuf;

fn main() -> std::io::Result<()> {
    let mut args = std::env::args_os().skip(1);
    let dir = args
        .next()
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("fixtures"));
    if args.next().is_some() {
        eprintln!("usage: make_fixtures [OUTPUT_DIR]");
        std::process::exit(2);
    }
    std::fs::create_dir_all(&dir)?;
    for (name, glb) in penumbra::fixtures::all() {
        let path = dir.join(format!("{name}.glb"));
        std::fs::write(&path, &glb)?;
        println!("{} ({} bytes)", path.display(), glb.len());
    }
    Ok(())
}
