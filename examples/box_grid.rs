//! Writes `penumbra::fixtures::box_grid(n)` to a file: `cargo run --release --example box_grid
//! -- 20 box-grid-20.glb` (for timing the solvers on a scene of `12 n²` box triangles).

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let n: usize = args
        .next()
        .ok_or_else(|| anyhow::anyhow!("usage: box_grid N OUT.glb"))?
        .parse()?;
    let out = args
        .next()
        .ok_or_else(|| anyhow::anyhow!("usage: box_grid N OUT.glb"))?;
    std::fs::write(out, penumbra::fixtures::box_grid(n))?;
    Ok(())
}
