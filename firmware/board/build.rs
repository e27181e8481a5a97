//! Puts the board's `memory.x` on the linker path of the ARM build.
//!
//! It lives here, not at the workspace root: the linker looks for `memory.x` in its working
//! directory (the workspace root) before the `-L` paths, so a root `memory.x` would be the memory
//! map of every ARM binary of the workspace (the on-target tests need QEMU's).
use std::{env, fs, path::PathBuf};

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let manifest = PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets it"));
    let memory_x = manifest.join("memory.x");
    fs::copy(&memory_x, out.join("memory.x")).expect("memory.x next to Cargo.toml");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed={}", memory_x.display());
    println!("cargo:rerun-if-changed=build.rs");
}
