//! The on-board analysis (calibration, peaks, envelope, Coulomb–viscous fit) on the target, over
//! the simulated records, against the host's results for the same counts.
//!
//! Tolerance: none. The target's result must equal the host's bit for bit. Rust evaluates `f32` and
//! `f64` operations as IEEE 754 on both (the M7's FPU is IEEE, single and double precision, with
//! subnormals: cortex-m-rt leaves flush-to-zero off), never contracts `a * b + c` into a fused
//! multiply-add unless asked (`mul_add`, which this code does not use), and the analysis uses no
//! platform maths library (`fit::sqrt`/`ln`/`cos` and `micromath` are plain arithmetic), in the same
//! order on both. Any difference is therefore a real platform difference (a compiler or
//! code-generation bug, an FPU mode), which this test exists to catch; the failure shows both
//! results and the distance in ulps.
//!
//! Figures: instructions per five-channel sample of the whole pipeline, `Pipeline::push` of every
//! sample plus the end-of-run fit, spread over the samples (budget 1,000: about 2 % of a 480 MHz
//! core at 10 kS/s); `push` alone; the worst chunk of [`CHUNK`] pushes; the end-of-run fit in one
//! call and its worst step as the application runs it; the deepest stack of those calls.

use crate::bundle::{analyse, same_bits, ulps, Stop, CHUNK};
use crate::{check, check_eq, Cx, Failure, Outcome};
use tribo_firmware::analysis::{Pipeline, MU0_PRECISION, MU1_PRECISION};
use tribo_firmware::app::AppConfig;
use tribo_firmware::wire::{Verdict, CHANNELS};

/// Budget of `Pipeline::push`, instructions per five-channel sample.
pub const SAMPLE_BUDGET: u64 = 1_000;
/// Budget of the stack of one pipeline call, bytes.
pub const STACK_BUDGET: u64 = 16 * 1024;

struct Names {
    whole: &'static str,
    per_sample: &'static str,
    worst_chunk: &'static str,
    finish: &'static str,
    finish_step: &'static str,
    stack: &'static str,
}

macro_rules! names {
    ($rec:literal) => {
        Names {
            whole: concat!("pipeline.", $rec, ".whole_per_sample"),
            per_sample: concat!("pipeline.", $rec, ".push_per_sample"),
            worst_chunk: concat!("pipeline.", $rec, ".worst_256_samples"),
            finish: concat!("pipeline.", $rec, ".finish_in_one_call"),
            finish_step: concat!("pipeline.", $rec, ".worst_finish_step"),
            stack: concat!("pipeline.", $rec, ".stack_bytes"),
        }
    };
}

/// Runs the pipeline over record `name` on this platform and compares with the host.
fn on_record(cx: &mut Cx<'_>, name: &str, names: Names) -> Outcome {
    let b = cx.bundle()?;
    let rec = b.record(name).ok_or_else(|| {
        Failure::new(
            file!(),
            line!(),
            format_args!("the bundle has no record {name:?}"),
        )
    })?;
    let mut p = match Pipeline::new(&rec.configure) {
        Ok(p) => p,
        Err(e) => {
            check!(false, "{name}: configuration refused: {e:?}");
            return Ok(());
        }
    };
    let r = analyse(&rec, &mut p, &mut |f| cx.measure(f));
    check!(r.is_ok(), "{name}: {:?}", r.err());
    let Ok((got, cost)) = r else { return Ok(()) };
    let host = rec.host;
    cx.note(format_args!(
        "{}: {} samples after release, {} half-cycles, {:?}; μ0 = {:e} (true {}), μ1 = {:e} (true {}), {:?}",
        rec.about,
        got.pushed,
        got.half_cycles,
        got.stop,
        got.result.best.mu0,
        rec.mu0,
        got.result.best.mu1,
        rec.mu1,
        got.result.verdict
    ));
    check_eq!(
        got.pushed,
        host.pushed,
        "samples taken before the pipeline stopped"
    );
    check_eq!(got.half_cycles, host.half_cycles);
    check_eq!(got.stop, host.stop);
    check!(
        got.stop != Stop::NotFinished,
        "the record ended before the pipeline stopped"
    );
    check!(
        same_bits(&got.result, &host.result),
        "target and host differ: μ0 {:e} vs {:e} ({} ulp), μ1 {:e} vs {:e} ({} ulp)\n      target {:?}\n      host   {:?}",
        got.result.best.mu0,
        host.result.best.mu0,
        ulps(got.result.best.mu0, host.result.best.mu0),
        got.result.best.mu1,
        host.result.best.mu1,
        ulps(got.result.best.mu1, host.result.best.mu1),
        got.result,
        host.result
    );
    // and both are right: the physics, within the method's stated precision
    check_eq!(got.result.verdict, Verdict::Ok);
    let (d0, d1) = (
        (got.result.best.mu0 as f64 - rec.mu0).abs(),
        (got.result.best.mu1 as f64 - rec.mu1).abs(),
    );
    check!(
        d0 <= MU0_PRECISION && d1 <= MU1_PRECISION,
        "{name}: |Δμ0| = {d0:e}, |Δμ1| = {d1:e} beyond ±{MU0_PRECISION}, ±{MU1_PRECISION}"
    );
    check_eq!(
        rec.configure.channels.len(),
        CHANNELS,
        "five-channel record"
    );
    // The end-of-run fit as the application runs it: in steps of its rows per poll, the same
    // result as in one call.
    let rows = AppConfig::new(0).finish_rows_per_poll;
    let mut job = p.start_finish(0);
    let (mut steps, mut worst_step, mut stepped) = (0u32, None::<u64>, None);
    while stepped.is_none() && steps < 1_000_000 {
        steps += 1;
        let c = cx.count(|| stepped = p.finish_step(&mut job, rows));
        worst_step = c.map(|c| worst_step.map_or(c, |w| w.max(c)));
    }
    check!(
        stepped.is_some_and(|r| same_bits(&r, &got.result)),
        "the fit in steps of {rows} rows differs from the fit in one call: {stepped:?}"
    );
    cx.note(format_args!(
        "end-of-run fit: {steps} steps of {rows} rows (one per poll in the application)"
    ));
    let samples = (got.pushed as u64).max(1);
    let whole = cost
        .push
        .zip(cost.finish)
        .map(|(push, finish)| (push + finish) / samples);
    let r0 = cx.figure(
        names.whole,
        whole,
        "instructions/sample",
        Some(SAMPLE_BUDGET),
    );
    let r1 = cx.figure(
        names.per_sample,
        cost.push.map(|n| n / samples),
        "instructions/sample",
        None,
    );
    let r2 = cx.figure(
        names.worst_chunk,
        cost.worst_chunk,
        "instructions/256 samples",
        Some(SAMPLE_BUDGET * CHUNK as u64),
    );
    let r3 = cx
        .figure(names.finish, cost.finish, "instructions", None)
        .and(cx.figure(names.finish_step, worst_step, "instructions", None));
    let r4 = cx.figure(
        names.stack,
        cost.stack.map(u64::from),
        "bytes",
        Some(STACK_BUDGET),
    );
    r0.and(r1).and(r2).and(r3).and(r4)
}

/// The apparatus alone: viscous damping only (μ0 = 0, μ1 = 0.0011), a 3 s record cut at the
/// configured maximum duration.
pub fn unloaded(cx: &mut Cx) -> Outcome {
    on_record(cx, "unloaded", names!("unloaded"))
}

/// Coulomb + viscous friction, no noise beyond the 16-bit quantisation; the pin stops.
pub fn coulomb_viscous(cx: &mut Cx) -> Outcome {
    on_record(cx, "coulomb_viscous", names!("coulomb_viscous"))
}

/// Coulomb + viscous friction with the vibrometer's noise at twice the rig's (the reversal
/// detector measures it from the motion).
pub fn noisy(cx: &mut Cx) -> Outcome {
    on_record(cx, "noisy", names!("noisy"))
}

/// Held 0.3 s at 20 kS/s with five times the simulator's vibrometer noise: the first reversal is
/// the motion's, not the noise's around the release.
pub fn held_20k(cx: &mut Cx) -> Outcome {
    on_record(cx, "held_20k", names!("held_20k"))
}

/// A cubic spring (3 % of k at the release), 94 cycles: the half periods drift with the amplitude.
pub fn cubic(cx: &mut Cx) -> Outcome {
    on_record(cx, "cubic", names!("cubic"))
}

/// Five half-cycles (Coulomb-dominated, 5 kS/s): the peaks' decrement fit alone, the peak fit
/// spread over the pushes after each window.
pub fn short(cx: &mut Cx) -> Outcome {
    on_record(cx, "short", names!("short"))
}
