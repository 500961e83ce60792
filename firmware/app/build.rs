//! Build script of the power-up image.
//!
//! 1. Linker setup for bare-metal ARM (no `.cargo/config.toml` needed): the repository's
//!    `memory.x` (mps2-an386 map) on the search path, cortex-m-rt's `link.x` and defmt's
//!    `defmt.x` as linker scripts.
//! 2. The flashed model: the Rust module written by `ferrosid codegen`, named by the
//!    environment variable `FERROSID_POWERUP_MODEL` (a path), is copied to
//!    `$OUT_DIR/flashed_model.rs`, which `src/main.rs` includes. Without the variable the
//!    copied file is a `compile_error!` that says how to generate one, so the image can never
//!    be built around a model that does not exist.
use std::env;
use std::path::PathBuf;

const MODEL_VAR: &str = "FERROSID_POWERUP_MODEL";

fn main() {
    let manifest_dir = PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").unwrap_or_default());
    let root = manifest_dir.join("..").join("..");
    println!("cargo:rerun-if-changed=../../memory.x");
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-env-changed={MODEL_VAR}");
    let target = env::var("TARGET").unwrap_or_default();
    if target.starts_with("thumb") {
        println!("cargo:rustc-link-search={}", root.display());
        println!("cargo:rustc-link-arg=--nmagic");
        println!("cargo:rustc-link-arg=-Tlink.x");
        println!("cargo:rustc-link-arg=-Tdefmt.x");
    }

    let out = PathBuf::from(env::var_os("OUT_DIR").unwrap_or_default()).join("flashed_model.rs");
    let text = match env::var_os(MODEL_VAR) {
        Some(path) => {
            let path = PathBuf::from(path);
            println!("cargo:rerun-if-changed={}", path.display());
            match std::fs::read_to_string(&path) {
                Ok(t) => t,
                Err(e) => format!(
                    "compile_error!({:?});\n",
                    format!(
                        "{MODEL_VAR}={}: cannot read the generated model: {e}",
                        path.display()
                    )
                ),
            }
        }
        None => format!(
            "compile_error!({:?});\n",
            format!(
                "set {MODEL_VAR} to the Rust module written by `ferrosid codegen --model \
                 model.json ... --out-dir DIR` (DIR/<prefix>.rs)"
            )
        ),
    };
    // Write only on change so an unchanged model does not relink the image.
    if std::fs::read_to_string(&out).ok().as_deref() != Some(text.as_str()) {
        if let Err(e) = std::fs::write(&out, text) {
            panic!("cannot write {}: {e}", out.display());
        }
    }
}
