//! Acquisition gaps end to end: a virtual rig whose firmware stops reading its converter's ring for
//! 300 ms in the middle of a run (the DMA laps the reader) sends a gap frame with the exact missing
//! samples; the run goes on; the host stores the gap with the run, lists it, and refuses to fit
//! across it unless told to fit the longest clean stretch.

mod host_common;

use host_common::*;
use std::sync::atomic::AtomicBool;
use std::time::Duration;
use tribo::link::session::record_run;
use tribo_rig::{AcquisitionFaults, ServeOptions, VirtualRig, VirtualRigConfig};

fn fit_args(record: &std::path::Path, longest: bool) -> tribo::cmd::fit::Args {
    tribo::cmd::fit::Args {
        record: vec![record.to_owned()],
        law: tribo_physics::LawSpec::CoulombViscous,
        json: false,
        plot: None,
        mass_kg: None,
        stiffness: None,
        load_n: None,
        apparatus_mu1: 0.0,
        windows: 0,
        longest_clean_stretch: longest,
    }
}

#[test]
fn a_stalled_reader_gives_a_stored_run_whose_gap_the_host_reports_and_will_not_fit_across() {
    let cfg = VirtualRigConfig {
        law: tribo_physics::FrictionLaw::coulomb_viscous(0.01, 0.004),
        seed: 21,
        acquisition: AcquisitionFaults {
            stall_reader_after_ms: Some(1200),
            stall_reader_ms: 300,
            adc_overrun_after_ms: None,
        },
        ..Default::default()
    };
    let rig = VirtualRig::new(cfg).unwrap();
    let truth = rig.truth().unwrap();
    let port = RigOnTcp::serve(
        rig,
        ServeOptions {
            speed: 20.0,
            max_wait: Duration::from_millis(2),
            ..Default::default()
        },
    );
    let store = tempfile::tempdir().unwrap();
    let (mut link, info) = connect(&port);
    let o = record_run(
        &mut link,
        &info,
        store.path(),
        &plan(),
        &AtomicBool::new(false),
        &mut |_| {},
    )
    .unwrap();
    let run = &o.run;
    // One gap: 300 ms at 10 kS/s, of which the 2048-scan ring kept the last 2048 samples, 1.2 s
    // into the run.
    let gaps: Vec<_> = run.gaps().copied().collect();
    assert_eq!(gaps.len(), 1, "{gaps:?}");
    let g = gaps[0];
    assert!((900..=1000).contains(&g.count), "{g:?}");
    assert!((11_900..=12_100).contains(&g.first_sample), "{g:?}");
    // Stored whole: every block, the end; the samples missing between blocks are exactly the gap.
    assert!(run.is_complete(), "{:?}", run.missing_blocks());
    let stretches = run.clean_stretches();
    assert_eq!(stretches.len(), 2, "{stretches:?}");
    assert_eq!(stretches[0].end, g.first_sample as u64);
    assert_eq!(stretches[1].start, g.first_sample as u64 + g.count as u64);
    let end = run.end().unwrap();
    assert_eq!(end.overruns, g.count);
    assert_eq!(end.reason, tribo_wire::EndReason::Stopped);
    // The catalog marks the run; its host fit was refused, saying how to get one.
    let rows = tribo_store::RunCatalog::open(store.path())
        .unwrap()
        .list(&Default::default())
        .unwrap();
    assert_eq!(rows[0].lost_samples, g.count as u64);
    let host_error = run.results.host_error.as_deref().unwrap_or("");
    assert!(
        host_error.contains("--longest-clean-stretch") && run.results.host.is_none(),
        "{host_error}"
    );
    // `tribo fit RUN` refuses, names the gap and the flag…
    let e = tribo::cmd::fit::run(fit_args(run.dir(), false)).unwrap_err();
    let msg = format!("{e:#}");
    assert!(
        msg.contains("--longest-clean-stretch")
            && msg.contains(&format!("{}..{}", g.first_sample, g.first_sample + g.count)),
        "{msg}"
    );
    // …and with the flag fits the first 1.2 s (the longest stretch), which hold the
    // contact's constants.
    let rec = tribo::load_for_fit(run.dir(), tribo::Holes::LongestCleanStretch).unwrap();
    assert_eq!(rec.len() as u64, stretches[0].end - stretches[0].start);
    let r = tribo_physics::identify::fit(
        &rec,
        tribo_physics::LawSpec::CoulombViscous,
        &Default::default(),
    )
    .unwrap();
    assert_close("longest clean stretch", r.mu[0], r.mu[1], truth);
    tribo::cmd::fit::run(fit_args(run.dir(), true)).unwrap();
    // The firmware's on-board result, from the half-cycles before the gap, replays on the host
    // (the replay steps over the gap as the rig's pipeline did).
    let recorded = *run.result().unwrap();
    let replayed = tribo::replay::replay_pipeline(run).unwrap();
    let d = tribo::replay::compare(&recorded, &replayed, 1e-3);
    assert!(d.is_empty(), "{d:?}");
    assert!(recorded.cycles >= 5, "{recorded:?}");
}
