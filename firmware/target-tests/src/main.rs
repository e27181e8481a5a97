//! The on-target test binary: Cortex-M7 entry point under QEMU (`cargo xtask target-test` builds and
//! runs it). Everything else, the tests included, is in the library. On the host this is an empty
//! program (see `tests/host.rs` for the host run of the same tests).
#![cfg_attr(all(target_arch = "arm", target_os = "none"), no_std)]
#![cfg_attr(all(target_arch = "arm", target_os = "none"), no_main)]

#[cfg(all(target_arch = "arm", target_os = "none"))]
mod qemu;

#[cfg(not(all(target_arch = "arm", target_os = "none")))]
fn main() {
    eprintln!(
        "tribo-target-tests runs on an emulated Cortex-M7: `cargo xtask target-test` (needs \
         qemu-system-arm). On the host: `cargo test -p tribo-target-tests`."
    );
}
