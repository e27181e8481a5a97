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
//! Figures: instructions per five-channel sample of `Pipeline::push` (budget 1,000: about 2 % of a
//! 480 MHz core at 10 kS/s), the worst chunk of [`CHUNK`] pushes, the end-of-run fit
//! (`Pipeline::finish` in one call), and the deepest stack of those calls.

use crate::bundle::{analyse, same_bits, ulps, Stop, CHUNK};
use crate::{check, check_eq, Cx, Failure, Outcome};
use tribo_firmware::analysis::{Pipeline, MU0_PRECISION, MU1_PRECISION};
use tribo_firmware::wire::{Verdict, CHANNELS};

/// Budget of `Pipeline::push`, instructions per five-channel sample.
pub const SAMPLE_BUDGET: u64 = 1_000;
/// Budget of the stack of one pipeline call, bytes.
pub const STACK_BUDGET: u64 = 16 * 1024;

struct Names {
    per_sample: &'static str,
    worst_chunk: &'static str,
    finish: &'static str,
    stack: &'static str,
}

macro_rules! names {
    ($rec:literal) => {
        Names {
            per_sample: concat!("pipeline.", $rec, ".instructions_per_sample"),
            worst_chunk: concat!("pipeline.", $rec, ".worst_256_samples"),
            finish: concat!("pipeline.", $rec, ".finish_in_one_call"),
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
    let per_sample = cost.push.map(|n| n / (got.pushed as u64).max(1));
    let r1 = cx.figure(
        names.per_sample,
        per_sample,
        "instructions/sample",
        Some(SAMPLE_BUDGET),
    );
    let r2 = cx.figure(
        names.worst_chunk,
        cost.worst_chunk,
        "instructions/256 samples",
        Some(SAMPLE_BUDGET * CHUNK as u64),
    );
    let r3 = cx.figure(names.finish, cost.finish, "instructions", None);
    let r4 = cx.figure(
        names.stack,
        cost.stack.map(u64::from),
        "bytes",
        Some(STACK_BUDGET),
    );
    r1.and(r2).and(r3).and(r4)
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
