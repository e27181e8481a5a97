//! The soak: run after run against one virtual rig through a faulty line, a fault drawn at random
//! for each (seeded, so a failure replays): a clean line; a lossy line (0.5–5 % of the frames each
//! way dropped or corrupted); the cable pulled mid-run (then, the run finished with nobody
//! listening, a pull over a clean or a lossy line); the rig power-cycled before the run; the load
//! knob turned between runs. After every run, against the rig's own copy (pulled over a clean
//! line):
//!
//! - the stored run is bit-identical to the rig's (each frame once, in the rig's order), or it says
//!   exactly which blocks are missing, and holds nothing the rig did not send for that run;
//! - no stored run holds a frame of another run (every run frame carries its run's number, checked
//!   against the header's; and the run numbers of one rig never repeat).
//!
//! `cargo test -p tribo-tests --test soak` runs a short soak (`SOAK_RUNS`, default 30);
//! `cargo xtask soak` runs 1000 and prints the figures.

mod faulty_line;
mod host_common;

use faulty_line::{Bench, Faults};
use host_common::plan;
use std::collections::{BTreeMap, BTreeSet};
use std::sync::atomic::AtomicBool;
use tribo::link::session::{pull_run, record_run, Outcome};
use tribo_physics::stats::Rng;
use tribo_rig::{VirtualRig, VirtualRigConfig};
use tribo_wire::frame::decode_one;
use tribo_wire::DeviceMsg;

/// What the soak saw.
#[derive(Debug, Default)]
struct Figures {
    runs: usize,
    faults: BTreeMap<&'static str, usize>,
    intact: usize,
    honestly_incomplete: usize,
    mixed: usize,
    frames_checked: usize,
}

/// The run number and block of a run frame.
fn run_frame(raw: &[u8]) -> Option<(u32, Option<u32>)> {
    let msg = decode_one::<DeviceMsg>(raw).ok()?.msg;
    Some(match msg {
        DeviceMsg::RunStarted(h) => (h.run_id, None),
        DeviceMsg::Samples(b) => (b.run_id, Some(b.block)),
        DeviceMsg::Packed(p) => (p.run_id, Some(p.block)),
        DeviceMsg::Gap(g) => (g.run_id, None),
        DeviceMsg::EcrRange(e) => (e.run_id, None),
        DeviceMsg::Result(r) => (r.run_id, None),
        DeviceMsg::RunEnded(e) => (e.run_id, None),
        _ => return None,
    })
}

fn record(bench: &mut Bench, faults: Faults, store: &std::path::Path, load: f32) -> Outcome {
    bench
        .session(faults, |link| {
            let info = link.hello()?;
            let mut p = plan();
            p.config.rig.load_n = load;
            record_run(link, &info, store, &p, &AtomicBool::new(false), &mut |_| {})
        })
        .0
        .unwrap_or_else(|e| {
            panic!(
                "the run finishes (complete or not): {e:#}; the rig's last fault: {:?} at {} µs",
                bench.rig().app().last_fault(),
                bench.rig().now_us()
            )
        })
}

fn pull(bench: &mut Bench, faults: Faults, store: &std::path::Path) -> Outcome {
    bench
        .session(faults, |link| {
            let info = link.hello()?;
            pull_run(link, &info, store, None, false, &mut |_| {})
        })
        .0
        .expect("the pull finishes")
}

/// Checks a stored run against the rig's own copy; returns whether it is whole.
fn check(o: &Outcome, truth: &[Vec<u8>], run_id: u32, f: &mut Figures) -> Result<bool, String> {
    let stored = o.run.frames();
    f.frames_checked += stored.len();
    // No frame of another run.
    for raw in &stored {
        match run_frame(raw) {
            Some((id, _)) if id == run_id => {}
            other => {
                f.mixed += 1;
                return Err(format!("a frame of run {other:?} filed under run {run_id}"));
            }
        }
    }
    let c = o.run.completeness();
    if c.is_complete() {
        if stored.len() != truth.len() || stored.iter().zip(truth).any(|(a, b)| *a != &b[..]) {
            let held: BTreeSet<&[u8]> = stored.iter().copied().collect();
            let lacking: Vec<String> = truth
                .iter()
                .filter(|t| !held.contains(&t[..]))
                .map(|t| match decode_one::<DeviceMsg>(t) {
                    Ok(f) => format!("{:?}", f.msg).chars().take(160).collect(),
                    Err(e) => format!("undecodable: {e:?}"),
                })
                .collect();
            return Err(format!(
                "called complete but differs from the rig's copy ({} frames vs {}); lacking: {lacking:?}",
                stored.len(),
                truth.len()
            ));
        }
        return Ok(true);
    }
    // Incomplete: what it holds is the rig's, and what it says is missing is exactly the rest.
    let rig: BTreeSet<&[u8]> = truth.iter().map(|v| &v[..]).collect();
    if let Some(x) = stored.iter().find(|s| !rig.contains(*s)) {
        return Err(format!(
            "holds a frame the rig did not send for this run ({} bytes)",
            x.len()
        ));
    }
    let held: BTreeSet<u32> = stored
        .iter()
        .filter_map(|r| run_frame(r).and_then(|x| x.1))
        .collect();
    let missing: BTreeSet<u32> = truth
        .iter()
        .filter_map(|r| run_frame(r).and_then(|x| x.1))
        .filter(|b| !held.contains(b))
        .collect();
    let said: BTreeSet<u32> = c.missing.iter().copied().collect();
    if c.end && said != missing {
        return Err(format!(
            "says {} blocks missing, {} are: {}",
            said.len(),
            missing.len(),
            c.summary()
        ));
    }
    Ok(false)
}

fn soak(runs: usize, seed: u64) -> Figures {
    let mut rng = Rng::new(seed);
    let mut bench = Bench::new(
        VirtualRig::new(VirtualRigConfig {
            law: tribo_physics::FrictionLaw::coulomb_viscous(0.02, 0.004),
            seed,
            ..Default::default()
        })
        .unwrap(),
    );
    let store = tempfile::tempdir().unwrap();
    let mut f = Figures::default();
    let mut ids = BTreeSet::new();
    let mut failures = Vec::new();
    for i in 0..runs {
        let pick = rng.next_u64() % 6;
        let load = [0.1f32, 0.2, 0.3, 0.5][(rng.next_u64() % 4) as usize];
        let line_seed = rng.next_u64();
        let kind = match pick {
            0 => "clean line",
            1 => "lossy line",
            2 => "cable pulled, pulled back clean",
            3 => "cable pulled, pulled back lossy",
            4 => "rig power-cycled before the run",
            _ => "load knob turned",
        };
        *f.faults.entry(kind).or_default() += 1;
        if pick == 4 {
            bench.rig().power_cycle();
        }
        let lossy = || Faults::lossy(line_seed, 500 + (line_seed % 4_500) as u32);
        let faults = match pick {
            1 => lossy(),
            2 | 3 => Faults {
                cut_after_bytes: Some(2_000 + line_seed % 20_000),
                ..Faults::default()
            },
            _ => Faults::default(),
        };
        let mut o = record(&mut bench, faults, store.path(), load);
        if !o.is_complete() && (pick == 2 || pick == 3) {
            bench.run_on(30.0);
            let line = if pick == 3 {
                lossy()
            } else {
                Faults::default()
            };
            o = pull(&mut bench, line, store.path());
        }
        let Some(h) = o.run.header() else {
            failures.push(format!("run {i} ({kind}): no header stored"));
            continue;
        };
        let id = h.run_id;
        if !ids.insert(id) {
            f.mixed += 1;
            failures.push(format!("run {i} ({kind}): run number {id} used twice"));
        }
        let truth = bench.rig_frames(id);
        f.runs += 1;
        match check(&o, &truth, id, &mut f) {
            Ok(true) => f.intact += 1,
            Ok(false) => f.honestly_incomplete += 1,
            Err(e) => failures.push(format!("run {i} ({kind}, run {id}): {e}")),
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
    f
}

#[test]
fn soak_under_faults() {
    let runs = std::env::var("SOAK_RUNS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(30);
    let seed = std::env::var("SOAK_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1);
    let t = std::time::Instant::now();
    let f = soak(runs, seed);
    eprintln!(
        "soak (seed {seed}): {} runs in {:.0} s; faults {:?}; {} intact (bit-identical to the rig's \
         copy), {} honestly incomplete (exactly the missing blocks said), {} mixed; {} frames checked",
        f.runs,
        t.elapsed().as_secs_f64(),
        f.faults,
        f.intact,
        f.honestly_incomplete,
        f.mixed,
        f.frames_checked
    );
    assert_eq!(f.mixed, 0);
    assert_eq!(f.runs, runs);
}
