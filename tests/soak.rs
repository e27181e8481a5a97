//! The soak: run after run against one virtual rig through a faulty line, a fault drawn at random
//! for each (seeded, so a failure replays): a clean line; a lossy line (0.5–5 % of the frames each
//! way dropped or corrupted); the cable pulled mid-run (then, the run finished with nobody
//! listening, a pull over a clean or a lossy line); the rig power-cycled before the run; the load
//! knob turned between runs; the rig's power cut mid-stream (then what it kept in flash pulled
//! over a clean line: a run cut short is incomplete or ends "aborted", and says so); two hosts
//! racing for the rig (two PCs, each with its own store, both
//! running `tribo run` on the rig served by [`tribo_rig::TcpRig`], as `tribo rig --virtual` serves
//! it, at the same moment: one is served, the other waits for it to go and is turned away after the
//! hand-over time, saying why and having recorded nothing, or is served next and records a run of
//! its own; half of the races the first host keeps the rig longer than the hand-over, so both
//! outcomes come up). After every run, against the rig's own copy (pulled over a clean line):
//!
//! - the stored run is bit-identical to the rig's (each frame once, in the rig's order), or it says
//!   exactly which blocks are missing, and holds nothing the rig did not send for that run;
//! - no stored run holds a frame of another run (every run frame carries its run's number, checked
//!   against the header's; and the run numbers of one rig never repeat);
//! - of two racing hosts, either one recorded and the other was refused (its error says the rig
//!   serves one host at a time, its store holds no run) or both recorded, under two run numbers.
//!
//! `cargo test -p tribo-tests --test soak` runs a short soak (`SOAK_RUNS`, default 30);
//! `cargo xtask soak` runs 1000 and prints the figures.

mod faulty_line;
mod host_common;

use faulty_line::{rig_copy, Bench, Faults};
use host_common::plan;
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::sync::Barrier;
use std::time::{Duration, Instant};
use tribo::link::session::{pull_run, record_run, Outcome};
use tribo::link::{Address, Link, LinkErrorKind};
use tribo_physics::stats::Rng;
use tribo_rig::{HostEvent, VirtualRig, VirtualRigConfig, HANDOVER};
use tribo_wire::frame::decode_one;
use tribo_wire::DeviceMsg;

/// What the soak saw.
#[derive(Debug, Default)]
struct Figures {
    /// Runs drawn (a race is one, whatever it stored).
    runs: usize,
    faults: BTreeMap<&'static str, usize>,
    /// Stored runs checked against the rig's copy.
    stored: usize,
    intact: usize,
    honestly_incomplete: usize,
    mixed: usize,
    frames_checked: usize,
    races: usize,
    /// Races where the first host kept the rig past the hand-over time.
    races_held: usize,
    /// Races where one host recorded and the other was turned away.
    races_one_refused: usize,
    /// Races where both hosts recorded, one after the other.
    races_both_recorded: usize,
    /// Runs the power cut short (the rig still running when it went).
    power_cuts_mid_run: usize,
    /// Power cuts before the release, or before the run's header reached the host (the rig then
    /// offers its last run, already held).
    power_cuts_before_the_run: usize,
    /// Runs cut short that the rig lost whole (the power went before the run reached its flash).
    power_cuts_run_lost: usize,
    /// Of those, stored whole as far as the flash kept them, their end saying "aborted".
    power_cuts_stored_aborted: usize,
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
        DeviceMsg::Chain(c) => (c.run_id, None),
        DeviceMsg::Result(r) => (r.run_id, None),
        DeviceMsg::RunEnded(e) => (e.run_id, None),
        _ => return None,
    })
}

fn record(bench: &mut Bench, faults: Faults, store: &std::path::Path, load: f32) -> Outcome {
    try_record(bench, faults, store, load)
        .0
        .unwrap_or_else(|e| {
            panic!(
                "the run finishes (complete or not): {e:#}; the rig's last fault: {:?} at {} µs",
                bench.rig().app().last_fault(),
                bench.rig().now_us()
            )
        })
}

/// `tribo run`: what it stored, or why it stored nothing; and what the line saw.
fn try_record(
    bench: &mut Bench,
    faults: Faults,
    store: &std::path::Path,
    load: f32,
) -> (
    anyhow::Result<Outcome>,
    std::sync::Arc<faulty_line::LineStats>,
) {
    bench.session(faults, |link| {
        let info = link.hello()?;
        let mut p = plan();
        p.config.rig.load_n = load;
        record_run(link, &info, store, &p, &AtomicBool::new(false), &mut |_| {})
    })
}

fn pull(bench: &mut Bench, faults: Faults, store: &std::path::Path) -> Outcome {
    pull_into(bench, faults, store, None).expect("the pull finishes")
}

/// `tribo pull [RUN]`: the rig's last run, or the stored run `target` completed.
fn pull_into(
    bench: &mut Bench,
    faults: Faults,
    store: &std::path::Path,
    target: Option<&Path>,
) -> anyhow::Result<Outcome> {
    bench
        .session(faults, |link| {
            let info = link.hello()?;
            pull_run(link, &info, store, target, false, &mut |_| {})
        })
        .0
}

/// Checks a stored run against the rig's own copy; returns whether it is whole.
/// `sent`: frames the rig sent live that its copy may lack (the power went before they reached its
/// flash): a stored run may hold them too.
fn check(
    o: &Outcome,
    truth: &[Vec<u8>],
    sent: &[Vec<u8>],
    run_id: u32,
    f: &mut Figures,
) -> Result<bool, String> {
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
    // Incomplete: what it holds is the rig's, all that the rig still holds (the last pull asked
    // for it), and what it says is missing is exactly the rest.
    let rig: BTreeSet<&[u8]> = truth.iter().chain(sent).map(|v| &v[..]).collect();
    if let Some(x) = stored.iter().find(|s| !rig.contains(*s)) {
        return Err(format!(
            "holds a frame the rig did not send for this run ({} bytes)",
            x.len()
        ));
    }
    let held: BTreeSet<&[u8]> = stored.iter().copied().collect();
    let left = truth.iter().filter(|t| !held.contains(&t[..])).count();
    if left > 0 {
        return Err(format!(
            "incomplete ({}) but {left} frames the rig still holds were not fetched",
            c.summary()
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

/// A stored run and the rig's copy of it.
type Stored = (Outcome, Vec<Vec<u8>>);

/// What a racing host ended with.
enum Racer {
    /// It recorded a run; with the rig's copy of it, pulled over the same link right after (the
    /// rig keeps its last run only, and the other host may take the next).
    Recorded(Box<Outcome>, Vec<Vec<u8>>),
    /// The rig closed the connection before answering its hello: the error, and how long after
    /// the host knocked.
    Refused(String, Duration),
    /// Anything else.
    Failed(String),
}

/// One racing host: `tribo run`'s steps (open the TCP address, hello, record the run into its own
/// store), then the rig's copy of the run; then it keeps the rig for `linger`.
fn racing_host(addr: &str, store: &Path, load: f32, linger: Duration) -> Racer {
    let t0 = Instant::now();
    let mut link = match Link::open(&Address::Tcp(addr.into())) {
        Ok(l) => l,
        Err(e) => return Racer::Failed(format!("cannot connect: {e}")),
    };
    let info = match link.hello() {
        Ok(i) => i,
        Err(e) if e.kind == LinkErrorKind::Closed => {
            return Racer::Refused(e.to_string(), t0.elapsed())
        }
        Err(e) => return Racer::Failed(format!("hello: {e}")),
    };
    let mut p = plan();
    p.config.rig.load_n = load;
    let o = match record_run(
        &mut link,
        &info,
        store,
        &p,
        &AtomicBool::new(false),
        &mut |_| {},
    ) {
        Ok(o) => o,
        Err(e) => return Racer::Failed(format!("the run failed: {e:#}")),
    };
    let Some(id) = o.run.header().map(|h| h.run_id) else {
        return Racer::Failed("no header stored".into());
    };
    let truth = rig_copy(&mut link, id);
    std::thread::sleep(linger);
    Racer::Recorded(Box::new(o), truth)
}

/// Whether `store` holds a run folder.
fn holds_a_run(store: &Path) -> bool {
    std::fs::read_dir(store).is_ok_and(|d| d.flatten().any(|e| e.path().is_dir()))
}

/// Two hosts race for the rig, lent to a [`tribo_rig::TcpRig`]. Checks the race's outcome and
/// returns the runs stored (with the rig's copy of each), oldest first.
fn race(
    bench: &mut Bench,
    load: f32,
    linger: Duration,
    f: &mut Figures,
) -> Result<Vec<Stored>, String> {
    let stores = [tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap()];
    let start = Barrier::new(2);
    let (racers, events) = bench.lend(|addr| {
        let addr = addr.to_string();
        std::thread::scope(|s| {
            let hosts: Vec<_> = stores
                .iter()
                .map(|store| {
                    let (addr, start) = (&addr, &start);
                    s.spawn(move || {
                        start.wait();
                        racing_host(addr, store.path(), load, linger)
                    })
                })
                .collect();
            hosts
                .into_iter()
                .map(|h| {
                    h.join()
                        .unwrap_or_else(|_| Racer::Failed("the host panicked".into()))
                })
                .collect::<Vec<_>>()
        })
    });
    f.races += 1;
    let connected = events
        .iter()
        .filter(|e| matches!(e, HostEvent::Connected(_)))
        .count();
    let refused = events
        .iter()
        .filter(|e| matches!(e, HostEvent::Refused(_)))
        .count();
    let mut runs = vec![];
    let mut refusals = vec![];
    for (racer, store) in racers.into_iter().zip(&stores) {
        match racer {
            Racer::Recorded(o, truth) => runs.push((*o, truth)),
            Racer::Refused(why, after) => {
                if !why.contains("one host at a time") {
                    return Err(format!("a refused host is not told why: {why}"));
                }
                // It waited its turn: a host the rig serves for less than the hand-over time
                // leaves the rig to the next.
                if after < HANDOVER {
                    return Err(format!(
                        "a host was turned away after {after:?}, before the hand-over time \
                         ({HANDOVER:?}): {why}"
                    ));
                }
                if holds_a_run(store.path()) {
                    return Err(format!("a refused host stored a run: {why}"));
                }
                refusals.push(why);
            }
            Racer::Failed(why) => return Err(format!("a racing host failed: {why}")),
        }
    }
    match (runs.len(), refusals.len()) {
        (1, 1) => {
            if (connected, refused) != (1, 1) {
                return Err(format!(
                    "one host refused, but the rig's console heard {connected} connected and                      {refused} refused: {events:?}"
                ));
            }
            f.races_one_refused += 1;
        }
        (2, 0) => {
            if (connected, refused) != (2, 0) {
                return Err(format!(
                    "both hosts recorded, but the rig's console heard {connected} connected and                      {refused} refused: {events:?}"
                ));
            }
            f.races_both_recorded += 1;
        }
        (r, n) => return Err(format!("{r} hosts recorded and {n} were refused")),
    }
    let id = |o: &Outcome| o.run.header().map(|h| h.run_id).unwrap_or(0);
    runs.sort_by_key(|(o, _)| id(o));
    if runs.len() == 2 && id(&runs[0].0) == id(&runs[1].0) {
        return Err(format!("both hosts stored run {}", id(&runs[0].0)));
    }
    // The rig's copy taken by the last host is the rig's copy taken now, on the bench.
    let (last, truth) = runs.last().expect("a run");
    if bench.rig_frames(id(last)) != *truth {
        return Err(format!(
            "run {}: the rig's copy pulled by its host differs from the copy pulled after",
            id(last)
        ));
    }
    Ok(runs)
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
        let pick = rng.next_u64() % 8;
        let load = [0.1f32, 0.2, 0.3, 0.5][(rng.next_u64() % 4) as usize];
        let line_seed = rng.next_u64();
        let kind = match pick {
            0 => "clean line",
            1 => "lossy line",
            2 => "cable pulled, pulled back clean",
            3 => "cable pulled, pulled back lossy",
            4 => "rig power-cycled before the run",
            5 => "load knob turned",
            6 => "two hosts racing for the rig",
            _ => "the rig's power cut mid-run, then pulled",
        };
        *f.faults.entry(kind).or_default() += 1;
        if pick == 4 {
            bench.rig().power_cycle();
        }
        if pick == 5 {
            // Between runs, with the rig powered: its runs, their numbers and its clock go on.
            bench
                .rig()
                .turn_load_knob(load as f64)
                .expect("a load the rig takes");
        }
        let lossy = || Faults::lossy(line_seed, 500 + (line_seed % 4_500) as u32);
        let faults = match pick {
            1 => lossy(),
            2 | 3 => Faults {
                cut_after_bytes: Some(2_000 + line_seed % 20_000),
                ..Faults::default()
            },
            7 => Faults {
                power_cut_after_bytes: Some(2_000 + line_seed % 60_000),
                ..Faults::default()
            },
            _ => Faults::default(),
        };
        if pick == 6 {
            // Half the races, the first host keeps the rig longer than its hand-over time.
            let linger = Duration::from_millis(if line_seed.is_multiple_of(2) {
                0
            } else {
                1_500
            });
            f.runs += 1;
            f.races_held += usize::from(!linger.is_zero());
            let stored = match race(&mut bench, load, linger, &mut f) {
                Ok(s) => s,
                Err(e) => {
                    failures.push(format!("run {i} ({kind}): {e}"));
                    continue;
                }
            };
            for (o, truth) in stored {
                let id = o.run.header().expect("checked by the host").run_id;
                if !ids.insert(id) {
                    // Any repeat fails: the rig sends a run's number only once it is in flash,
                    // so no power cut, however many in a row, lets it be given again.
                    f.mixed += 1;
                    failures.push(format!("run {i} ({kind}): run number {id} used twice"));
                }
                f.stored += 1;
                match check(&o, &truth, &[], id, &mut f) {
                    Ok(true) => f.intact += 1,
                    Ok(false) => f.honestly_incomplete += 1,
                    Err(e) => failures.push(format!("run {i} ({kind}, run {id}): {e}")),
                }
            }
            continue;
        }
        // What the rig sent live during a session its power cut short.
        let mut sent: Vec<Vec<u8>> = Vec::new();
        let mut o = if pick == 7 {
            let folders = tribo_store::run::list_run_dirs(store.path()).unwrap().len();
            let resets = bench.rig().resets();
            let (r, stats) = try_record(&mut bench, faults, store.path(), load);
            sent = std::mem::take(&mut *stats.sent.lock().unwrap());
            match r {
                Ok(o) => o,
                Err(e) => {
                    // The power went before the release: an error, and nothing recorded.
                    f.runs += 1;
                    f.power_cuts_before_the_run += 1;
                    if bench.rig().resets() == resets {
                        failures.push(format!(
                            "run {i} ({kind}): failed with the rig still powered: {e:#}"
                        ));
                    } else if tribo_store::run::list_run_dirs(store.path()).unwrap().len()
                        != folders
                    {
                        failures.push(format!(
                            "run {i} ({kind}): failed ({e:#}) but left a run folder"
                        ));
                    }
                    continue;
                }
            }
        } else {
            record(&mut bench, faults, store.path(), load)
        };
        if pick == 7 {
            // The power went mid-stream (the rig powered again at once): what it kept in flash is
            // all there is; the pull must fetch all of it and say what is missing.
            let ended = o.run.end().is_some();
            let began = o.run.header().map(|h| h.run_id);
            if let Some(id) = began {
                // `tribo pull RUN`: the run this host was recording.
                let dir = o.run.dir().to_owned();
                match pull_into(&mut bench, Faults::default(), store.path(), Some(&dir)) {
                    Ok(p) => o = p,
                    Err(e) => {
                        // The power went before the run reached the rig's flash: the rig lost it,
                        // the pull says so, and the stored run (whatever it holds, all of run
                        // `id`) stays incomplete.
                        let e = format!("{e:#}");
                        f.runs += 1;
                        f.stored += 1;
                        f.power_cuts_mid_run += 1;
                        f.power_cuts_run_lost += 1;
                        if !ids.insert(id) {
                            failures.push(format!("run {i} ({kind}): run number {id} used twice"));
                        }
                        let run = tribo_store::Run::open(&dir).expect("the stored run opens");
                        let frames = run.frames();
                        f.frames_checked += frames.len();
                        if !e.contains(&format!("lost run {id}")) {
                            failures.push(format!("run {i} ({kind}): the pull failed: {e}"));
                        } else if run.completeness().is_complete() {
                            failures.push(format!(
                                "run {i} ({kind}): a run the rig lost is called complete"
                            ));
                        } else if frames
                            .iter()
                            .any(|r| run_frame(r).is_none_or(|x| x.0 != id))
                        {
                            f.mixed += 1;
                            failures.push(format!(
                                "run {i} ({kind}): a frame of another run in run {id}"
                            ));
                        } else {
                            f.honestly_incomplete += 1;
                        }
                        continue;
                    }
                }
            } else {
                o = pull(&mut bench, Faults::default(), store.path());
            }
            let offered = o.run.header().map(|h| h.run_id);
            if began.is_none() && offered.is_some_and(|id| ids.contains(&id)) {
                // The power went before this run's header reached the host: the rig offers its
                // last run, one already held, and the pull must say so and store nothing new.
                f.runs += 1;
                f.power_cuts_before_the_run += 1;
                if o.pulled_blocks != 0 || !o.is_complete() {
                    failures.push(format!(
                        "run {i} ({kind}): the rig's previous run, already held, pulled again \
                         ({} blocks)",
                        o.pulled_blocks
                    ));
                }
                continue;
            }
            if !ended {
                f.power_cuts_mid_run += 1;
                // A run the power cut short never says it ended as a run ends (stopped, or
                // its longest time): it is incomplete, or its end says it was aborted.
                match o.run.end().map(|e| e.reason) {
                    None => {}
                    Some(tribo_wire::EndReason::Aborted) => f.power_cuts_stored_aborted += 1,
                    Some(r) => failures.push(format!(
                        "run {i} ({kind}): cut short by the power, stored as ended {r:?}"
                    )),
                }
            }
        }
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
        f.stored += 1;
        match check(&o, &truth, &sent, id, &mut f) {
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
        "soak (seed {seed}): {} runs in {:.0} s; faults {:?}; {} runs stored: {} intact \
         (bit-identical to the rig's copy), {} honestly incomplete (exactly the missing blocks \
         said), {} mixed; {} frames checked; {} races ({} with the first host keeping the rig past \
         the hand-over): {} with one host refused, {} with both recorded; {} runs cut short by \
         the power ({} stored to their recovered end, \"aborted\", {} lost by the rig and kept \
         incomplete as the host had them), {} cut before the run's header reached the host (the \
         rig's previous run offered, already held); 0 run numbers given twice (any fails the soak)",
        f.runs,
        t.elapsed().as_secs_f64(),
        f.faults,
        f.stored,
        f.intact,
        f.honestly_incomplete,
        f.mixed,
        f.frames_checked,
        f.races,
        f.races_held,
        f.races_one_refused,
        f.races_both_recorded,
        f.power_cuts_mid_run,
        f.power_cuts_stored_aborted,
        f.power_cuts_run_lost,
        f.power_cuts_before_the_run
    );
    assert_eq!(f.mixed, 0);
    assert_eq!(f.runs, runs);
    assert_eq!(f.intact + f.honestly_incomplete, f.stored);
    assert_eq!(f.races_one_refused + f.races_both_recorded, f.races);
}
