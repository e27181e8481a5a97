//! Integration tests live in `tests/*.rs` beside this file; this library holds nothing. What they
//! share is `host_common.rs` (a virtual rig on a local TCP port, run plans), which each test
//! includes with `mod host_common;`, and the dev-only `tribo-testkit` crate.
