//! Builds xatlas (the C++ in `src/atlas/xatlas/`) with penumbra's C interface to it.
//!
//! The flags are set here, not by the environment, so that a crate depending on penumbra builds
//! the same xatlas: `XA_MULTITHREADED=0` (xatlas's task scheduler can hang at `Destroy`, see
//! the module doc of `src/atlas/mod.rs`) and full optimization in every profile (xatlas at `-O0`
//! makes a debug build's atlas tens of times slower).

fn main() {
    let dir = "src/atlas/xatlas";
    for file in ["shim.cpp", "xatlas.cpp", "xatlas.h"] {
        println!("cargo:rerun-if-changed={dir}/{file}");
    }
    let mut build = cc::Build::new();
    build
        .cpp(true)
        .file(format!("{dir}/shim.cpp"))
        .include(dir)
        .define("XA_MULTITHREADED", "0")
        .define("NDEBUG", None)
        .opt_level(3)
        .debug(false)
        .warnings(false);
    if build.get_compiler().is_like_msvc() {
        build.flag("/EHsc");
    } else {
        build.flag("-std=c++11");
    }
    build.compile("penumbra_xatlas");
}
