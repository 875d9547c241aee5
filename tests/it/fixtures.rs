//! The shipped fixtures are exactly what the generator in `src/fixtures.rs` writes.

#[test]
fn shipped_fixtures_match_the_generator() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures");
    for (name, bytes) in penumbra::fixtures::all() {
        let path = dir.join(format!("{name}.glb"));
        let shipped = std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        assert!(
            shipped == bytes,
            "{} differs from the generator: run `cargo run --example make_fixtures`",
            path.display()
        );
    }
}
