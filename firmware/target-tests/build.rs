//! For the ARM build: links the test binary with its own complete linker script, `qemu.x` (QEMU's
//! mps2-an500 map and the sections cortex-m-rt's start-up code expects), given to the linker by its
//! absolute path. It includes no `memory.x`, so the board's map (the top-level `memory.x`, which the
//! linker would find first in its working directory, the workspace root) cannot shadow it. Also
//! passes on where `cargo xtask target-test` wrote the record bundle.
use std::{env, path::PathBuf};

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-changed=qemu.x");
    println!("cargo:rerun-if-env-changed=TRIBO_TARGET_BUNDLE");
    println!("cargo::rustc-check-cfg=cfg(tribo_bundle)");
    let bare_metal = env::var("CARGO_CFG_TARGET_OS").as_deref() == Ok("none");
    if !bare_metal {
        return;
    }
    let manifest = PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets it"));
    println!(
        "cargo:rustc-link-arg-bins=-T{}",
        manifest.join("qemu.x").display()
    );
    if let Some(bundle) = env::var_os("TRIBO_TARGET_BUNDLE") {
        println!(
            "cargo:rerun-if-changed={}",
            PathBuf::from(&bundle).display()
        );
        println!("cargo:rustc-cfg=tribo_bundle");
    }
}
