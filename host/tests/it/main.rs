//! The host's integration tests, one test binary (`cargo test -p tribo --test it`; one module per
//! subject, `cargo test -p tribo --test it contract::` runs one). They share [`support`]: the
//! `tribo` binary spawned and a virtual rig as a process of its own; the lab catalog's tests take
//! their PostgreSQL server and stores from `tribo-testkit`.
//!
//! Side by side in one process, each test keeps to itself: every `tribo` it runs is a process of
//! its own (its environment and working folder set on the command, never on this process), every
//! folder is a fresh temporary one, every rig and panel listens on a port the system picks
//! (`127.0.0.1:0`), and no test changes this process's environment, working folder or threads.

mod support;

mod cli_explain;
mod cli_fit;
mod cli_honest;
mod contract;
mod crash;
mod exit_contract;
mod failsafe_process;
mod lab_catalog;
mod onboard_release;
mod panel_browser;
mod panel_http;
mod run_identity;
mod selftest;
mod table_refit;
