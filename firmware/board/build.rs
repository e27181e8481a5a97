//! The board binary's link: cortex-m-rt's `link.x` with the board's memory map, the top-level
//! `memory.x` of the repository (beside Cargo.toml), and defmt's `defmt.x`.
//!
//! `memory.x` is copied to this crate's `OUT_DIR`, which goes on the linker's search path, so the
//! link does not depend on the linker's working directory (the workspace root, where the linker
//! would find the same file first anyway). The linker scripts are named here rather than in
//! `.cargo/config.toml`: the on-target tests link with their own complete script (QEMU's map, see
//! `firmware/target-tests/build.rs`), which never includes a `memory.x`, so the board's map cannot
//! shadow theirs.
use std::{env, fs, path::PathBuf};

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    let manifest = PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets it"));
    let memory_x = manifest.join("../../memory.x");
    println!("cargo:rerun-if-changed={}", memory_x.display());
    if env::var("CARGO_CFG_TARGET_OS").as_deref() != Ok("none") {
        // The host build is an empty program: no linker scripts.
        return;
    }
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    fs::copy(&memory_x, out.join("memory.x")).expect("memory.x at the top of the repository");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
}
