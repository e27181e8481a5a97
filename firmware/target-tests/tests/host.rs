//! The on-target test list, run on the host: the same tests, the same generated bundle, no
//! instruction counts. Keeps the tests themselves honest where a debugger is at hand, and shows the
//! runner reports failures (a corrupted bundle must fail the tests that use it).

use tribo_target_tests::generate::bundle;
use tribo_target_tests::{run, tests::TESTS, Bundle, Cx, NoProbe};

/// Runs `f` on a thread with the stack the app tests need (they hold the board's run store, ~2 MiB,
/// as locals, as the target's 4 MiB stack allows).
fn big_stack(f: impl FnOnce() + Send + 'static) {
    std::thread::Builder::new()
        .stack_size(64 << 20)
        .spawn(f)
        .unwrap()
        .join()
        .unwrap();
}

#[test]
fn every_on_target_test_passes_on_the_host() {
    big_stack(every_on_target_test_passes);
}

fn every_on_target_test_passes() {
    let bytes = bundle().expect("bundle generates");
    let b = Bundle::parse(&bytes).expect("bundle parses");
    assert!(b.records().count() >= 3);
    let mut out = String::new();
    let mut probe = NoProbe;
    let summary = {
        let mut cx = Cx::new(&mut probe, &mut out, Some(&b));
        run(&mut cx, TESTS, "")
    };
    eprintln!("{out}");
    assert!(summary.ok(), "{out}");
    assert_eq!(summary.passed, TESTS.len());
    assert!(out.contains(&format!(
        "test result: ok. {} passed; 0 failed",
        TESTS.len()
    )));
}

#[test]
fn a_wrong_host_result_fails_the_comparison() {
    big_stack(a_wrong_host_result_fails);
}

fn a_wrong_host_result_fails() {
    let mut bytes = bundle().expect("bundle generates");
    // Flip the lowest bit of the coulomb_viscous record's host μ0 (one ulp): the last occurrence of
    // its four bytes, which follow that record's counts.
    let b = Bundle::parse(&bytes).expect("bundle parses");
    let rec = b.records().find(|r| r.name == "coulomb_viscous").unwrap();
    let mu0 = rec.host.result.best.mu0.to_le_bytes();
    let at = bytes
        .windows(4)
        .rposition(|w| w == mu0)
        .expect("the host's μ0 is in the bundle");
    bytes[at] ^= 1;
    let b = Bundle::parse(&bytes).expect("still parses");
    let mut out = String::new();
    let mut probe = NoProbe;
    let summary = {
        let mut cx = Cx::new(&mut probe, &mut out, Some(&b));
        run(&mut cx, TESTS, "coulomb_viscous")
    };
    eprintln!("{out}");
    assert_eq!(summary.passed, 0, "{out}");
    assert_eq!(summary.failed, 2, "{out}");
    assert!(
        out.contains("test result: FAILED. 0 passed; 2 failed"),
        "{out}"
    );
}

#[test]
fn without_a_bundle_the_tests_that_need_it_fail_with_a_clear_message() {
    let mut out = String::new();
    let mut probe = NoProbe;
    let summary = {
        let mut cx = Cx::new(&mut probe, &mut out, None);
        run(&mut cx, TESTS, "pipeline::noisy")
    };
    assert_eq!((summary.passed, summary.failed), (0, 1), "{out}");
    assert!(out.contains("cargo xtask target-test"), "{out}");
}
