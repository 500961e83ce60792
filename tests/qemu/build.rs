//! Linker setup for the QEMU images, so no `.cargo/config.toml` is needed: the repository's
//! `memory.x` (mps2-an386 map) goes on the linker search path, and cortex-m-rt's `link.x` and
//! defmt's `defmt.x` are passed as linker scripts. Only applies to bare-metal ARM targets.
use std::env;
use std::path::PathBuf;

fn main() {
    let manifest_dir = PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").unwrap_or_default());
    let root = manifest_dir.join("..").join("..");
    println!("cargo:rerun-if-changed=../../memory.x");
    println!("cargo:rerun-if-changed=build.rs");
    let target = env::var("TARGET").unwrap_or_default();
    if target.starts_with("thumb") {
        println!("cargo:rustc-link-search={}", root.display());
        // --nmagic: no page alignment of sections (flash addresses start at 0).
        println!("cargo:rustc-link-arg=--nmagic");
        println!("cargo:rustc-link-arg=-Tlink.x");
        println!("cargo:rustc-link-arg=-Tdefmt.x");
    }
}
