//! Linker setup for the QEMU images, so no `.cargo/config.toml` is needed: the repository's
//! `memory.x` (mps2-an386 map) goes on the linker search path, and cortex-m-rt's `link.x` and
//! defmt's `defmt.x` are passed as linker scripts. Only applies to bare-metal ARM targets.
//! With the `mpc` feature, the generated Rust module named by `FERROSID_MPC_MODEL` is copied to
//! `$OUT_DIR/mpc_model.rs` for the `mpc` image (a `compile_error!` saying what to set when the
//! variable is missing or unreadable).
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
    println!("cargo::rustc-check-cfg=cfg(ctl_kn)");
    if env::var_os("CARGO_FEATURE_CTL").is_some() {
        let text = generated("FERROSID_CTL_MODEL", "\"pid-notch\" or \"hinf\"");
        // The PID + notch block present: the image runs it (else the state-space block).
        if text.contains("pub const KN_SECTIONS") {
            println!("cargo:rustc-cfg=ctl_kn");
        }
        write_out("ctl_model.rs", &text);
    }
    if env::var_os("CARGO_FEATURE_MPC").is_some() {
        const VAR: &str = "FERROSID_MPC_MODEL";
        println!("cargo:rerun-if-env-changed={VAR}");
        let text = match env::var_os(VAR) {
            Some(path) => {
                let path = PathBuf::from(path);
                println!("cargo:rerun-if-changed={}", path.display());
                std::fs::read_to_string(&path).unwrap_or_else(|e| {
                    format!(
                        "compile_error!({:?});\n",
                        format!(
                            "{VAR}={}: cannot read the generated module: {e}",
                            path.display()
                        )
                    )
                })
            }
            None => format!(
                "compile_error!({:?});\n",
                format!(
                    "set {VAR} to the Rust module written by `ferrosid codegen` for a pipeline \
                     run with [control] method = \"mpc\""
                )
            ),
        };
        let out = PathBuf::from(env::var_os("OUT_DIR").unwrap_or_default()).join("mpc_model.rs");
        if std::fs::read_to_string(&out).ok().as_deref() != Some(text.as_str()) {
            std::fs::write(&out, text).expect("write mpc_model.rs");
        }
    }
}

/// The generated module named by the environment variable `var` (or a `compile_error!` saying
/// what to set).
fn generated(var: &str, method: &str) -> String {
    println!("cargo:rerun-if-env-changed={var}");
    match env::var_os(var) {
        Some(path) => {
            let path = PathBuf::from(path);
            println!("cargo:rerun-if-changed={}", path.display());
            std::fs::read_to_string(&path).unwrap_or_else(|e| {
                format!(
                    "compile_error!({:?});\n",
                    format!(
                        "{var}={}: cannot read the generated module: {e}",
                        path.display()
                    )
                )
            })
        }
        None => format!(
            "compile_error!({:?});\n",
            format!(
                "set {var} to the Rust module written by `ferrosid codegen` for a pipeline run \
                 with [control] method = {method}"
            )
        ),
    }
}

/// Writes `text` to `$OUT_DIR/name` when it changed.
fn write_out(name: &str, text: &str) {
    let out = PathBuf::from(env::var_os("OUT_DIR").unwrap_or_default()).join(name);
    if std::fs::read_to_string(&out).ok().as_deref() != Some(text) {
        std::fs::write(&out, text).expect("write generated module");
    }
}
