//! On-target tests of the firmware library: one `no_std` binary, many named tests, run on an
//! emulated Cortex-M7 (QEMU `mps2-an500`, `-icount shift=0`) by `cargo xtask target-test`.
//!
//! The library is plain `no_std` code that builds for the host too: the tests, the runner, the
//! record bundle the binary embeds ([`bundle`]), the replay hardware ([`replay`]) and, behind the
//! `generate` feature (host only), the generator of that bundle ([`generate`]). The binary
//! (`src/main.rs`) is only the Cortex-M7 entry point: semihosting output, QEMU's instruction counter
//! and stack painting behind the [`Probe`] trait, and the panic and fault handlers. `tests/host.rs`
//! runs the very same list on the host (no instruction counts there).
//!
//! # Adding a test
//! 1. Write a function `fn name(cx: &mut Cx) -> Outcome` in a module of `src/tests/` (a new module is
//!    declared in `src/tests/mod.rs`). Check with [`check!`] and [`check_eq!`] (they return the
//!    failure; a panic also fails, but ends the whole run there).
//! 2. Register it in [`tests::TESTS`] with the [`test!`] macro: `test!(module::name)`. That list is
//!    the only registry; the runner prints `test module::name ... ok`.
//! 3. Numbers: measure a call with [`Cx::measure`] (instructions and stack of that call) or
//!    [`Cx::count`] (instructions only, cheaper) and report it with [`Cx::figure`], giving a budget
//!    where there is one: a figure over budget fails its test. Instruction counts under
//!    `-icount shift=0` are exact and repeatable (one tick of the timer per 40 instructions).
//! 4. Data from the host: add it to the bundle in [`generate`] (simulated records, host results,
//!    host-encoded frames) and read it through [`Cx::bundle`].
//!
//! Run: `cargo xtask target-test` (all), `cargo xtask target-test FILTER` (names containing FILTER).
#![cfg_attr(not(feature = "generate"), no_std)]
// A test's `Outcome` carries its failure message inline (no heap on the target); it is returned
// once per check, never on a hot path.
#![allow(clippy::result_large_err)]

pub mod bundle;
pub mod fatal;
#[cfg(feature = "generate")]
pub mod generate;
pub mod replay;
pub mod tests;

use core::fmt::{self, Write};

pub use bundle::{Bundle, Record};

/// What one test returns: `Err` carries the first failed check.
pub type Outcome = Result<(), Failure>;

/// Longest failure message kept (longer ones are cut).
pub const MESSAGE_LEN: usize = 480;

/// A failed check: where and what.
#[derive(Debug, Clone)]
pub struct Failure {
    pub file: &'static str,
    pub line: u32,
    pub message: heapless::String<MESSAGE_LEN>,
}

impl Failure {
    pub fn new(file: &'static str, line: u32, args: fmt::Arguments<'_>) -> Self {
        let mut message = heapless::String::new();
        let _ = Truncating(&mut message).write_fmt(args);
        Failure {
            file,
            line,
            message,
        }
    }
}

/// Writes what fits and drops the rest (a heapless string refuses a whole piece that does not fit).
struct Truncating<'s, const N: usize>(&'s mut heapless::String<N>);

impl<const N: usize> Write for Truncating<'_, N> {
    fn write_str(&mut self, s: &str) -> fmt::Result {
        for c in s.chars() {
            if self.0.push(c).is_err() {
                break;
            }
        }
        Ok(())
    }
}

/// Fails the test (returns a [`Failure`]) unless the condition holds.
#[macro_export]
macro_rules! check {
    ($cond:expr $(,)?) => {
        $crate::check!($cond, "{}", stringify!($cond))
    };
    ($cond:expr, $($fmt:tt)+) => {
        if !$cond {
            return Err($crate::Failure::new(file!(), line!(), format_args!($($fmt)+)));
        }
    };
}

/// Fails the test unless `left == right`; shows both.
#[macro_export]
macro_rules! check_eq {
    ($left:expr, $right:expr $(,)?) => {
        $crate::check_eq!($left, $right, "")
    };
    ($left:expr, $right:expr, $($fmt:tt)+) => {
        match (&$left, &$right) {
            (l, r) => {
                if !(*l == *r) {
                    return Err($crate::Failure::new(
                        file!(),
                        line!(),
                        format_args!(
                            "{} == {} failed: left {:?}, right {:?}. {}",
                            stringify!($left),
                            stringify!($right),
                            l,
                            r,
                            format_args!($($fmt)+)
                        ),
                    ));
                }
            }
        }
    };
}

/// Names a test function for [`tests::TESTS`]: `test!(module::function)`.
#[macro_export]
macro_rules! test {
    ($first:ident $(:: $rest:ident)*) => {
        $crate::Test {
            name: concat!(stringify!($first) $(, "::", stringify!($rest))*),
            run: $first $(:: $rest)*,
        }
    };
}

/// One registered test.
#[derive(Clone, Copy)]
pub struct Test {
    pub name: &'static str,
    pub run: fn(&mut Cx<'_>) -> Outcome,
}

/// What a measured call cost.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Cost {
    /// Instructions executed by the call (`None` where the platform cannot count them).
    pub instructions: Option<u64>,
    /// Bytes of stack the call used below the caller's stack pointer (`None` where not measured).
    pub stack: Option<u32>,
}

/// The platform's meters: QEMU's instruction counter and stack painting on the target, nothing on
/// the host.
pub trait Probe {
    /// Where the tests run, for the report.
    fn platform(&self) -> &'static str;
    /// Instructions per tick of the counter (the uncertainty of one [`Probe::count`]).
    fn resolution(&self) -> u64;
    /// Instructions executed by `f` (`None` when the platform cannot count).
    fn count(&mut self, f: &mut dyn FnMut()) -> Option<u64>;
    /// Instructions executed by `f` and the stack depth it reached (paints the stack below the
    /// caller first, so it costs more than [`Probe::count`]).
    fn measure(&mut self, f: &mut dyn FnMut()) -> Cost;
    /// A plain function reading the instruction counter, for code that times itself inside a
    /// measured call (the replay hardware's ring reads).
    fn clock(&self) -> replay::Clock;
}

/// A probe that measures nothing (the host).
#[derive(Debug, Default)]
pub struct NoProbe;

impl Probe for NoProbe {
    fn platform(&self) -> &'static str {
        "host (no instruction counter)"
    }
    fn resolution(&self) -> u64 {
        0
    }
    fn count(&mut self, f: &mut dyn FnMut()) -> Option<u64> {
        f();
        None
    }
    fn measure(&mut self, f: &mut dyn FnMut()) -> Cost {
        f();
        Cost::default()
    }
    fn clock(&self) -> replay::Clock {
        || None
    }
}

/// A reported number.
#[derive(Debug, Clone, Copy)]
pub struct Figure {
    pub name: &'static str,
    pub value: u64,
    pub unit: &'static str,
    pub budget: Option<u64>,
}

/// Most figures kept for the closing table.
pub const MAX_FIGURES: usize = 64;

/// What a test gets: the probe, the output, the embedded bundle, the figures table.
pub struct Cx<'a> {
    probe: &'a mut dyn Probe,
    out: &'a mut dyn Write,
    bundle: Option<&'a Bundle<'a>>,
    figures: heapless::Vec<Figure, MAX_FIGURES>,
    /// The `test name ... ` line waits for its verdict.
    line_open: bool,
}

impl<'a> Cx<'a> {
    pub fn new(
        probe: &'a mut dyn Probe,
        out: &'a mut dyn Write,
        bundle: Option<&'a Bundle<'a>>,
    ) -> Self {
        Cx {
            probe,
            out,
            bundle,
            figures: heapless::Vec::new(),
            line_open: false,
        }
    }

    /// Ends the open `test name ... ` line before a note goes under it.
    fn close_line(&mut self) {
        if self.line_open {
            let _ = self.out.write_str("\n");
            self.line_open = false;
        }
    }

    /// The records and vectors generated on the host (fails the test if the binary has none).
    pub fn bundle(&self) -> Result<&'a Bundle<'a>, Failure> {
        self.bundle.ok_or_else(|| {
            Failure::new(
                file!(),
                line!(),
                format_args!(
                    "no record bundle: build the binary with `cargo xtask target-test`, which \
                     generates it"
                ),
            )
        })
    }

    /// True where instructions are counted (the target).
    pub fn counting(&self) -> bool {
        self.probe.resolution() > 0
    }

    /// Instructions per counter tick.
    pub fn resolution(&self) -> u64 {
        self.probe.resolution()
    }

    /// Instructions of `f` (`None` on the host).
    pub fn count(&mut self, mut f: impl FnMut()) -> Option<u64> {
        self.probe.count(&mut f)
    }

    /// Instructions and stack depth of `f`.
    pub fn measure(&mut self, mut f: impl FnMut()) -> Cost {
        self.probe.measure(&mut f)
    }

    /// The probe's plain clock function (see [`Probe::clock`]).
    pub fn probe_clock(&self) -> replay::Clock {
        self.probe.clock()
    }

    /// A line of explanation under the test's name.
    pub fn note(&mut self, args: fmt::Arguments<'_>) {
        self.close_line();
        let _ = self.out.write_str("    ");
        let _ = self.out.write_fmt(args);
        let _ = self.out.write_str("\n");
    }

    /// Reports a figure (printed now and in the closing table) and fails when it exceeds `budget`.
    /// Figures are only reported where they are measured: on the host this does nothing.
    pub fn figure(
        &mut self,
        name: &'static str,
        value: Option<u64>,
        unit: &'static str,
        budget: Option<u64>,
    ) -> Outcome {
        let Some(value) = value else {
            return Ok(());
        };
        self.close_line();
        let _ = write!(self.out, "    figure {name} = {value} {unit}");
        if let Some(b) = budget {
            let _ = write!(self.out, " (budget {b})");
        }
        let _ = self.out.write_str("\n");
        let _ = self.figures.push(Figure {
            name,
            value,
            unit,
            budget,
        });
        match budget {
            Some(b) if value > b => Err(Failure::new(
                file!(),
                line!(),
                format_args!("{name} = {value} {unit} is over its budget of {b} {unit}"),
            )),
            _ => Ok(()),
        }
    }

    /// Figures reported so far.
    pub fn figures(&self) -> &[Figure] {
        &self.figures
    }
}

/// Totals of a run.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Summary {
    pub passed: usize,
    pub failed: usize,
    pub filtered_out: usize,
}

impl Summary {
    pub fn ok(&self) -> bool {
        self.failed == 0 && self.passed > 0
    }
}

/// Runs every test of `tests` whose name contains `filter` (all when empty), libtest style:
/// `test name ... ok` / `FAILED` with the failure under it, then `test result: ok. N passed; M
/// failed; K filtered out` and the table of figures. The name is printed before the test runs, so
/// a panic or a fault report follows the name of the test that caused it.
pub fn run(cx: &mut Cx<'_>, tests: &[Test], filter: &str) -> Summary {
    let mut s = Summary::default();
    let selected = tests.iter().filter(|t| t.name.contains(filter)).count();
    s.filtered_out = tests.len() - selected;
    let platform = cx.probe.platform();
    let _ = writeln!(cx.out, "\nrunning {selected} tests on {platform}");
    for t in tests.iter().filter(|t| t.name.contains(filter)) {
        let _ = write!(cx.out, "test {} ... ", t.name);
        cx.line_open = true;
        let outcome = (t.run)(cx);
        if let Err(f) = &outcome {
            cx.close_line();
            let _ = writeln!(cx.out, "    failed at {}:{}: {}", f.file, f.line, f.message);
        }
        let verdict = if outcome.is_ok() { "ok" } else { "FAILED" };
        if cx.line_open {
            let _ = writeln!(cx.out, "{verdict}");
        } else {
            let _ = writeln!(cx.out, "test {} ... {verdict}", t.name);
        }
        cx.line_open = false;
        match outcome {
            Ok(()) => s.passed += 1,
            Err(_) => s.failed += 1,
        }
    }
    let _ = writeln!(
        cx.out,
        "\ntest result: {}. {} passed; {} failed; {} filtered out",
        if s.ok() { "ok" } else { "FAILED" },
        s.passed,
        s.failed,
        s.filtered_out
    );
    if !cx.figures.is_empty() {
        let res = cx.probe.resolution();
        let _ = writeln!(
            cx.out,
            "\nfigures ({platform}; instruction counts exact to ±{res} per measured call):"
        );
        for f in cx.figures.iter() {
            let _ = write!(cx.out, "  {:<44} {:>12} {:<22}", f.name, f.value, f.unit);
            match f.budget {
                Some(b) => {
                    let verdict = if f.value <= b { "ok" } else { "OVER" };
                    let _ = writeln!(cx.out, " budget {b:>8}  {verdict}");
                }
                None => {
                    let _ = writeln!(cx.out);
                }
            }
        }
    }
    s
}
