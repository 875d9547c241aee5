//! Writes the generated test scenes of `penumbra::fixtures` as glb files.
//!
//! ```text
//! cargo run --example make_fixtures [OUTPUT_DIR]
//! cargo run --release --example make_fixtures -- --ladder DIR
//! cargo run --release --example make_fixtures -- --town TRIANGLES FILE
//! cargo run --release --example make_fixtures -- --sill-town TRIANGLES FILE
//! cargo run --release --example make_fixtures -- --tiled-box TILES FILE
//! cargo run --example make_fixtures -- --box-on-ground FILE
//! cargo run --example make_fixtures -- --textured DIR
//! cargo run --example make_fixtures -- --normal-wall FILE
//! ```
//!
//! `OUTPUT_DIR` defaults to `fixtures` (relative to the current directory, so run it from the
//! repository root). Each scene becomes `OUTPUT_DIR/<name>.glb`, e.g. `fixtures/cornell-box.glb`;
//! the output is deterministic, so re-running it leaves the files unchanged.
//!
//! `--ladder DIR` writes the scale-ladder scenes (`penumbra::fixtures::ladder`, up to several
//! megabytes each) to `DIR/<rung>.glb` instead; they are generated on demand and not kept in
//! `fixtures/`. `--town TRIANGLES FILE` writes the ladder's sunlit town at about that many
//! triangles (`penumbra::fixtures::ladder::town`), e.g. a small one for `penumbra compare`;
//! `--sill-town TRIANGLES FILE` the same town with a sill under every window
//! (`penumbra::fixtures::ladder::sill_town`: many small polygons).
//! `--tiled-box TILES FILE` writes the box on a floor of TILES x TILES tiles of the seam
//! pictures (`penumbra::fixtures::tiled_box_on_floor`).
//! `--box-on-ground FILE` writes the sky's scene (`penumbra::fixtures::box_on_ground`: no light
//! of its own, so it is not in `fixtures/`; bake it with `--sky`).
//! `--textured DIR` writes the textured scenes of the tests (`penumbra::fixtures::textured`:
//! an alpha-tested plate and its geometric twin, a half-lit emissive texture, textured floors,
//! a glass pane, a glass pane before a wall)
//! and the failure sweep's `cutout_lattice` to `DIR/<name>.glb`.
//! `--normal-wall FILE` writes the normal-mapped wall of the directional lightmap's client
//! check (`penumbra::fixtures::textured::normal_mapped_wall`).

use std::path::PathBuf;

fn main() -> std::io::Result<()> {
    let args: Vec<std::ffi::OsString> = std::env::args_os().skip(1).collect();
    let usage = || -> ! {
        eprintln!(
            "usage: make_fixtures [OUTPUT_DIR] | make_fixtures --ladder DIR \
             | make_fixtures --town TRIANGLES FILE | make_fixtures --sill-town TRIANGLES FILE \
             | make_fixtures --interior ROOMS FILE \
             | make_fixtures --tiled-box TILES FILE \
             | make_fixtures --box-on-ground FILE | make_fixtures --textured DIR \
             | make_fixtures --normal-wall FILE"
        );
        std::process::exit(2);
    };
    if args.first().is_some_and(|a| a == "--ladder") {
        let [_, dir] = args.as_slice() else { usage() };
        let dir = PathBuf::from(dir);
        std::fs::create_dir_all(&dir)?;
        for rung in penumbra::fixtures::ladder::ladder() {
            let glb = (rung.generate)();
            let path = dir.join(format!("{}.glb", rung.name));
            std::fs::write(&path, &glb)?;
            println!(
                "{} ({} bytes, about {} triangles)",
                path.display(),
                glb.len(),
                rung.triangles
            );
        }
        return Ok(());
    }
    let generated: Option<fn(usize) -> Vec<u8>> = match args.first().and_then(|a| a.to_str()) {
        Some("--town") => Some(penumbra::fixtures::ladder::town),
        Some("--sill-town") => Some(penumbra::fixtures::ladder::sill_town),
        Some("--interior") => Some(penumbra::fixtures::ladder::interior),
        Some("--tiled-box") => Some(penumbra::fixtures::tiled_box_on_floor),
        _ => None,
    };
    if let Some(generate) = generated {
        let [_, size, file] = args.as_slice() else {
            usage()
        };
        let Some(size) = size.to_str().and_then(|t| t.parse().ok()) else {
            usage()
        };
        let glb = generate(size);
        std::fs::write(file, &glb)?;
        println!("{} ({} bytes)", PathBuf::from(file).display(), glb.len());
        return Ok(());
    }
    if args.first().is_some_and(|a| a == "--normal-wall") {
        let [_, file] = args.as_slice() else { usage() };
        return std::fs::write(file, penumbra::fixtures::textured::normal_mapped_wall());
    }
    if args.first().is_some_and(|a| a == "--textured") {
        use penumbra::fixtures::textured::{self, Floor};
        let [_, dir] = args.as_slice() else { usage() };
        let dir = PathBuf::from(dir);
        std::fs::create_dir_all(&dir)?;
        let scenes = [
            ("masked-occluder", textured::masked_occluder()),
            ("ring-occluder", textured::ring_occluder()),
            ("half-lit-emitter", textured::half_lit_emitter()),
            ("sunlit-fence", textured::sunlit_fence()),
            (
                "checker-room",
                textured::floor_room(Floor::Checker {
                    albedo: [0.8; 3],
                    cells: 32,
                }),
            ),
            (
                "halves-room",
                textured::floor_room(Floor::Halves {
                    left: [200, 30, 30],
                    right: [230, 230, 230],
                }),
            ),
            (
                "cutout-lattice",
                penumbra::fixtures::failure::cutout_lattice(),
            ),
            (
                "glass-pane",
                textured::glass_pane(textured::Glass::Blend(0.5)),
            ),
            (
                "glass-before-wall",
                textured::glass_before_wall(textured::Glass::Blend(0.5)),
            ),
        ];
        for (name, glb) in scenes {
            let path = dir.join(format!("{name}.glb"));
            std::fs::write(&path, &glb)?;
            println!("{} ({} bytes)", path.display(), glb.len());
        }
        return Ok(());
    }
    if args.first().is_some_and(|a| a == "--box-on-ground") {
        let [_, file] = args.as_slice() else { usage() };
        let glb = penumbra::fixtures::box_on_ground();
        std::fs::write(file, &glb)?;
        println!("{} ({} bytes)", PathBuf::from(file).display(), glb.len());
        return Ok(());
    }
    if args.len() > 1 {
        usage();
    }
    let dir = args
        .first()
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("fixtures"));
    std::fs::create_dir_all(&dir)?;
    for (name, glb) in penumbra::fixtures::all() {
        let path = dir.join(format!("{name}.glb"));
        std::fs::write(&path, &glb)?;
        println!("{} ({} bytes)", path.display(), glb.len());
    }
    Ok(())
}
