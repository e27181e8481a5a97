//! Firmware binary for the STM32H743. Everything in here names hardware; everything else is in
//! `tribo-firmware`. On the host this builds to an empty program (see Cargo.toml).
#![cfg_attr(all(target_arch = "arm", target_os = "none"), no_std)]
#![cfg_attr(all(target_arch = "arm", target_os = "none"), no_main)]

#[cfg(all(target_arch = "arm", target_os = "none"))]
mod board;
#[cfg(all(target_arch = "arm", target_os = "none"))]
mod irqs;
#[cfg(all(target_arch = "arm", target_os = "none"))]
mod memory;
#[cfg(all(target_arch = "arm", target_os = "none"))]
mod mpu;
#[cfg(all(target_arch = "arm", target_os = "none"))]
mod safety;
#[cfg(all(target_arch = "arm", target_os = "none"))]
mod sampling;

#[cfg(not(all(target_arch = "arm", target_os = "none")))]
fn main() {
    eprintln!("tribo-board is firmware for the STM32H743: build it with `cargo xtask firmware`.");
}
