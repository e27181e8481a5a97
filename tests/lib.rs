//! Integration tests live in `tests/*.rs` beside this file; this library only holds shared helpers.
