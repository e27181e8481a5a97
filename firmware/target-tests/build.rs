//! For the ARM build: puts this crate's `memory.x` (QEMU's mps2-an500) on the linker path, with an
//! empty `defmt.x` (the workspace's ARM rustflags link `-Tdefmt.x`, as the board binary needs; this
//! binary has no defmt, and keeping the flags identical lets it share the board's build of `core`),
//! and passes on where `cargo xtask target-test` wrote the record bundle.
use std::{env, fs, path::PathBuf};

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-changed=memory.x");
    println!("cargo:rerun-if-env-changed=TRIBO_TARGET_BUNDLE");
    println!("cargo::rustc-check-cfg=cfg(tribo_bundle)");
    let bare_metal = env::var("CARGO_CFG_TARGET_OS").as_deref() == Ok("none");
    if !bare_metal {
        return;
    }
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let manifest = PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets it"));
    fs::copy(manifest.join("memory.x"), out.join("memory.x")).expect("memory.x");
    fs::write(
        out.join("defmt.x"),
        "/* no defmt in the on-target tests */\n",
    )
    .expect("defmt.x");
    println!("cargo:rustc-link-search={}", out.display());
    if let Some(bundle) = env::var_os("TRIBO_TARGET_BUNDLE") {
        println!(
            "cargo:rerun-if-changed={}",
            PathBuf::from(&bundle).display()
        );
        println!("cargo:rustc-cfg=tribo_bundle");
    }
}
