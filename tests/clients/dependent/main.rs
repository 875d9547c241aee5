//! Bakes a glb with penumbra's library at its default options: `penumbra-dependent IN OUT`.
//! tests/clients/run checks that the output has the same bytes as `penumbra bake IN OUT`.

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [input, output] = args.as_slice() else {
        return Err("usage: penumbra-dependent IN OUT".into());
    };
    let bake = penumbra::bake_file(
        input.as_ref(),
        &penumbra::OutputFiles::glb(output),
        &penumbra::BakeOptions::default(),
        &|_, _, _| {},
    )?;
    println!("{} elements", bake.stats.elements);
    Ok(())
}
