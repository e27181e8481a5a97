//! `tribo replay RUN`: the logged samples through the firmware pipeline again, and the run's
//! envelope against the simulated law.

mod host_common;

use host_common::*;
use tribo::replay::{compare, envelope_vs_simulation, replay_pipeline};

#[test]
fn replay_reproduces_the_onboard_result_and_locates_a_wrong_law() {
    let (port, truth) = virtual_rig(0.02, 0.004, 9, 20.0);
    let store = tempfile::tempdir().unwrap();
    let o = record_plain_run(&port, store.path());
    let recorded = *o.run.result().unwrap();

    let replayed = replay_pipeline(&o.run).unwrap();
    // The same firmware over the same samples gives the same result. The hold capture the log
    // lacks is stood in for by the samples at rest at the end of the run, which moves the
    // secondary estimators' last digits at most; the value shown (best) and the cycles hold.
    let d = compare(&recorded, &replayed, 1e-3);
    eprintln!("replay differences: {d:?}");
    assert!(
        !d.iter()
            .any(|x| x.field.starts_with("best") || x.field == "cycles" || x.field == "verdict"),
        "{d:?}"
    );
    for (a, b) in [
        (recorded.averaging, replayed.averaging),
        (recorded.decrement, replayed.decrement),
    ] {
        assert!(
            (a.mu0 - b.mu0).abs() < 1e-3 && (a.mu1 - b.mu1).abs() < 5e-4,
            "{a:?} vs {b:?}"
        );
    }
    assert_close(
        "replayed",
        replayed.best.mu0 as f64,
        replayed.best.mu1 as f64,
        truth,
    );
    // The comparison names what differs, and nothing when nothing does.
    assert!(compare(&recorded, &recorded, 1e-6).is_empty());
    let mut changed = recorded;
    changed.best.mu0 *= 1.01;
    changed.cycles += 3;
    let d = compare(&recorded, &changed, 1e-4);
    let fields: Vec<&str> = d.iter().map(|x| x.field.as_str()).collect();
    assert_eq!(fields, ["best.mu0", "cycles"]);

    // The true law follows the recorded envelope to the end; a law with twice the Coulomb friction
    // leaves it within a few cycles.
    let rec = tribo::load_record(o.run.dir()).unwrap();
    let rows = envelope_vs_simulation(&rec, truth.0, truth.1).unwrap();
    let a0 = rows[0].2;
    assert!(rows.len() > 20);
    assert!(
        rows.iter().all(|r| (r.2 - r.3).abs() < 0.01 * a0),
        "true law departs"
    );
    let wrong = envelope_vs_simulation(&rec, 2.0 * truth.0, truth.1).unwrap();
    let first = wrong
        .iter()
        .position(|r| (r.2 - r.3).abs() > 0.02 * a0)
        .expect("a wrong law departs");
    assert!((1..6).contains(&first), "departs at cycle {first}");
}
