//! `tribo fit`: identify a friction law from a record (thesis ch. 3.5), with the standard error of
//! every constant, the record's noise floor and a verdict.

use crate::analysis::{
    apparatus_damping, cross_check_text, fit_law, not_analysable_json, open_analysable, FitOutcome,
    FitRequest, RigFlags, RigUsed,
};
use crate::exit::Incomplete;
use anyhow::{Context, Result};
use clap::Parser;
use std::fmt::Write as _;
use std::path::PathBuf;
use tribo_physics::envelope::mark_crandall;
use tribo_physics::identify::{
    scaled_envelope, EnvelopeData, FitOptions, FitResult, FitVerdict, LawSpec, WindowFit,
    ADEQUATE_RATIO, NUMERICAL_FLOOR,
};
use tribo_physics::Record;
use tribo_report::plot::{Panel, Series};
use tribo_report::Figure;

/// The long `--help` of the command.
pub const LONG_ABOUT: &str = "Fit a friction law to a record by Levenberg–Marquardt on the Mark & Crandall envelope.

RECORD is a CSV with header `t_s,x_m,v_m_s[,ft_n,temp_c,ecr_ohm]` and rig constants in
`# mass_kg=…`, `# stiffness_n_per_m=…`, `# load_n=…` comment lines (the flags below override
them; a constant neither gives takes the real rig's value, and the output says so), a
dimensionless CSV `tau,y,ydot`, or a run folder of the store.

Every constant comes with its standard error (±, one standard deviation: from the Jacobian at the
optimum, with the residuals' correlation taken into account). The *noise floor* is the
envelope's measurement noise read from the record itself; the *gap* is the RMS difference
between measured and fitted envelopes. Both are relative to the initial amplitude. The verdict:

  adequate       converged, gap ≤ 1.5 × noise floor: the law describes the record
  inadequate     converged, gap above that: the law misses something (try `tribo explain`)
  not-converged  the iteration limit came first: the constants are not trustworthy (status 3)
  drifting       converged and at the noise floor, but the force channel shows μ0 drifting over
                 the motion (its trend beyond 4σ and 1 %, on the `drift` line): never adequate
  not-analysable no oscillation (a pin that never moves is named so), too few half cycles, a
                 saturated or stuck channel or a non-finite sample: nothing is fitted, no
                 constant printed (status 3)

`--json` prints one object: `law`, `verdict`, `mu` and `mu_se` (dimensionless constants of seed
eq. 10–13 in order of j and their standard errors), `gap`, `noise_floor`, `p_si`, `p_si_se` (SI
coefficients of μ(v) = Σ p_j v^j, v in m/s), `params`, `params_se`, `iterations`, `converged`,
`shape` (straight/convex/concave/mixed), `y0`, `y0_se` (fitted initial amplitude), `points`,
`n_eff` (effectively independent residuals), `half_cycles`, `span` (the part of the record
compared: `start`, `end`, `samples`, the noise of y and y' read from the record, `rest_level`,
`spikes` and `clipped` samples left out), `cross_check` (the on-board result beside the host's:
`onboard_mu`, `onboard_mu_se`, `z`, `agree`, `usable`, `suspect`; `null` for a law the rig does not fit,
`{\"unavailable\": why}` when there is none), `channels` (is the velocity column the
displacement's derivative: `gain`, `r2`, `samples`, `half_cycles`, `consistent`; false flags
swapped input cables, printed as `CHANNELS SWAPPED?`; `null` for too little motion), `record`,
`rig` (the constants used and where each came from: record, flag, default) and `defaults` (the
constants a default stood in for). A record
that cannot be analysed gives `{\"record\", \"verdict\": \"not-analysable\", \"message\", \"channels\", …}`, any
other failure `{\"record\", \"verdict\": \"error\", \"status\", \"message\"}`: one object on every
outcome.

What is compared is derived from the record and printed on the `compared` line: from the release
(a hold before it is skipped) to where the velocity sinks into its own noise (the stop and the rest
after it are not compared); speckle spikes and a few clipped peaks are left out and counted.

The on-board result (the rig's own for a run folder, else the firmware's pipeline run over the
record) is shown beside the host fit, with the distance between them in combined σ; more than 3σ
on μ0 or μ1 is called a disagreement, with what to suspect. When the on-board analysis's own two
estimators disagree (`estimators-disagree`), its result is called not usable here (`usable`:
false), never compared.

`--windows N` also fits the law on N successive windows of equal amplitude drop (thesis
ch. 3.7, Tables 6–7) and prints one row per window; with `--json` the object gains
`\"windows\": [{\"a_start\", \"a_end\", \"tau_start\", \"tau_end\", \"fit\": {…}}, …]`. Constants that
drift from window to window mean the law misses an amplitude-dependent term.

A record with holes is refused: a run whose rig lost samples (its acquisition gaps), a run with
blocks not received, a CSV whose time axis jumps. `--longest-clean-stretch` fits the longest
stretch of consecutive samples instead (and says which on stderr).";

///  Fit a friction law to a record by Levenberg–Marquardt on the Mark & Crandall envelope.
#[derive(Parser, Debug)]
pub struct Args {
    /// The record (CSV, or a run folder; `-` reads a CSV from standard input, as `tribo sim -o -`
    /// writes one). Several records (`tribo fit runs/*`) are fitted on every core, with a
    /// progress bar on standard error, and printed in the order given (with `--json`: one object
    /// a line, in that order).
    #[arg(required = true, num_args = 1..)]
    pub record: Vec<PathBuf>,
    /// Law: coulomb, viscous, coulomb-viscous, quadratic, poly:N, lugre.
    #[arg(long, default_value = "coulomb-viscous")]
    pub law: LawSpec,
    /// Print one JSON object: set by the global `--json`.
    #[arg(skip)]
    pub json: bool,
    /// Write an SVG figure: measured vs fitted envelope.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Override the record's mass (kg).
    #[arg(long, visible_alias = "mass", allow_negative_numbers = true)]
    pub mass_kg: Option<f64>,
    /// Override the record's stiffness (N/m).
    #[arg(long, allow_negative_numbers = true)]
    pub stiffness: Option<f64>,
    /// Override the record's normal load (N).
    #[arg(long, visible_alias = "load", allow_negative_numbers = true)]
    pub load_n: Option<f64>,
    /// Known apparatus damping μ_a kept fixed (0 = fit the total damping).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub apparatus_mu1: f64,
    /// Also fit on N amplitude windows (0 = off).
    #[arg(long, default_value_t = 0)]
    pub windows: usize,
    /// If the record has holes (samples the rig lost, blocks not received), fit the longest
    /// stretch of consecutive samples instead of refusing.
    #[arg(long)]
    pub longest_clean_stretch: bool,
}

/// Runs `tribo fit`.
pub fn run(a: Args) -> Result<()> {
    if a.record.len() > 1 {
        return run_many(&a);
    }
    let path = a.record[0].clone();
    let mut buf = String::new();
    let r = run_inner(&a, &path, &mut buf);
    if a.json && !buf.is_empty() {
        crate::out::print_json(buf.trim_end())?;
    } else {
        crate::out::text(&buf)?;
    }
    r.map_err(|e| super::exit::json_on_error(a.json, &path, e))
}

/// `tribo fit A B C…`: every record fitted on its own worker thread (as many as there are cores;
/// each fit's own simulations then stay on its thread), the outputs printed in the order given as
/// soon as all before them are done. Every record is fitted whatever happens to the others; the
/// command ends with the first failure's status (in the order given), after a count on stderr.
fn run_many(a: &Args) -> Result<()> {
    use std::sync::Mutex;
    if a.plot.is_some() {
        anyhow::bail!(
            "--plot draws one record's figure: give one record with it (fit the others without --plot)"
        );
    }
    if a.record.iter().filter(|p| p.as_os_str() == "-").count() > 0 {
        anyhow::bail!(
            "`-` (standard input) is one record: it cannot be fitted beside others; save it to a file first"
        );
    }
    let n = a.record.len();
    let bar = indicatif::ProgressBar::new(n as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{spinner} [{elapsed_precise}] {bar:30} {pos}/{len} records fitted ({per_sec}) {msg}",
        )
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    // Outputs waiting for those before them, and the first not yet printed.
    let done: Mutex<(Vec<Option<Fitted1>>, usize)> =
        Mutex::new(((0..n).map(|_| None).collect(), 0));
    let failures: Mutex<Vec<(usize, anyhow::Error)>> = Mutex::new(Vec::new());
    let print_error: Mutex<Option<std::io::Error>> = Mutex::new(None);
    let order: Vec<usize> = (0..n).collect();
    // Each record is fitted on one worker (one per core, each taking the next record as it
    // finishes one); its output is printed as soon as every record before it is printed.
    tribo_physics::identify::map_on_every_core(
        &order,
        |&i| {
            let path = &a.record[i];
            let mut buf = String::new();
            let r = run_inner(a, path, &mut buf).err();
            if a.json && buf.is_empty() {
                if let Some(e) = &r {
                    buf = super::exit::error_json(path, e).to_string();
                }
            }
            if !buf.is_empty() && !buf.ends_with('\n') {
                buf.push('\n');
            }
            let mut d = done.lock().unwrap_or_else(|p| p.into_inner());
            d.0[i] = Some((buf, r));
            // Print every output whose predecessors are all printed.
            while d.1 < n {
                let k = d.1;
                let Some((text, err)) = d.0[k].take() else {
                    break;
                };
                d.1 += 1;
                let sep = if !a.json && k > 0 { "\n" } else { "" };
                if let Err(e) = bar.suspend(|| crate::out::text(&format!("{sep}{text}"))) {
                    let mut pe = print_error.lock().unwrap_or_else(|p| p.into_inner());
                    if pe.is_none() {
                        *pe = e.downcast::<std::io::Error>().ok();
                    }
                }
                if let Some(e) = err {
                    if !a.json {
                        bar.suspend(|| crate::errln!("{}: {e:#}", a.record[k].display()));
                    }
                    failures
                        .lock()
                        .unwrap_or_else(|p| p.into_inner())
                        .push((k, e));
                }
            }
        },
        || bar.inc(1),
    );
    bar.finish_and_clear();
    if let Some(e) = print_error.into_inner().unwrap_or_else(|p| p.into_inner()) {
        return Err(anyhow::Error::new(e).context("cannot write to standard output"));
    }
    let mut failures = failures.into_inner().unwrap_or_else(|p| p.into_inner());
    failures.sort_by_key(|f| f.0);
    if failures.is_empty() {
        crate::errln!("{n} records fitted");
        return Ok(());
    }
    crate::errln!(
        "{} of {n} records fitted; {} not (their messages above; the status is the first one's)",
        n - failures.len(),
        failures.len()
    );
    let (_, first) = failures.swap_remove(0);
    Err(first)
}

/// One record's output and, if it failed, why.
type Fitted1 = (String, Option<anyhow::Error>);

/// Fits one record, writing what `tribo fit` prints for it to `out` (its JSON object, or its
/// table); the error is the command's outcome for it.
fn run_inner(a: &Args, path: &std::path::Path, out: &mut String) -> Result<()> {
    let spec = a.law;
    let holes = if a.longest_clean_stretch {
        crate::Holes::LongestCleanStretch
    } else {
        crate::Holes::Refuse
    };
    // The one visit to the loader: the record, the constants that were defaults, the run.
    let opened = open_analysable(path, holes)?;
    let mut rec = opened.record;
    let req = FitRequest {
        law: spec,
        flags: RigFlags {
            mass_kg: a.mass_kg,
            stiffness_n_per_m: a.stiffness,
            load_n: a.load_n,
        },
        apparatus_mu1: a.apparatus_mu1,
        windows: a.windows,
    };
    let name = path.display().to_string();
    let f = match fit_law(&name, &mut rec, &opened.defaults, opened.run.as_ref(), &req)? {
        FitOutcome::Fitted(f) => f,
        FitOutcome::NotAnalysable { rig, why } => {
            // Swapped input cables can be why nothing is fitted: the check is said here too.
            let channels = crate::analysis::identity::record_velocity_check(&rec);
            if a.json {
                let mut j = not_analysable_json(&name, &rig, &why);
                j["channels"] = serde_json::to_value(channels)?;
                let _ = writeln!(out, "{j}");
            } else if let Some(c) = channels.filter(|c| !c.consistent) {
                let _ = writeln!(out, "channels   {}", c.text());
            }
            return Err(Incomplete(format!(
                "{name}: not analysable: {why}; no constant is fitted"
            ))
            .into());
        }
    };
    if f.spec != spec && spec != LawSpec::CoulombViscous {
        crate::errln!(
            "note: {name} is the apparatus alone (load 0): it has no friction law; its damping is \
             fitted ({}) instead of {spec}",
            f.spec
        );
    }
    let r = &f.result;
    if a.json {
        let _ = writeln!(out, "{}", f.json(&name, &rec)?);
    } else {
        out.push_str(&table(&name, &f.rig, r, &rec));
        if let Some(line) = cross_check_text(&f.check) {
            let _ = writeln!(out, "{line}");
        }
        if let Some(c) = crate::analysis::identity::record_velocity_check(&rec) {
            let _ = writeln!(out, "channels   {}", c.text());
        }
        if let Some(w) = &f.windows {
            out.push_str(&window_table(w));
        }
    }
    if let Some(p) = &a.plot {
        let svg = figure(&rec, r, f.spec, &f.options)?;
        std::fs::write(p, svg).with_context(|| format!("writing {}", p.display()))?;
    }
    if r.verdict == FitVerdict::NotConverged {
        return Err(Incomplete(format!(
            "{name}: the fit did not converge in {} iterations; its constants are not trustworthy",
            r.iterations
        ))
        .into());
    }
    Ok(())
}

/// `value ± se` with the value rounded to the standard error's second significant digit (`?` when
/// the standard error is unknown).
pub fn pm(v: f64, se: f64) -> String {
    if !v.is_finite() {
        return "—".into();
    }
    if !(se.is_finite() && se > 0.0) {
        return format!("{v:.6e} ± ?");
    }
    let mag = v.abs().max(se);
    if !(1e-4..1e5).contains(&mag) {
        return format!("{v:.4e} ± {se:.1e}");
    }
    let digits = (1 - se.log10().floor() as i32).max(0) as usize;
    if digits > 8 {
        return format!("{v:.6e} ± {se:.1e}");
    }
    format!("{v:.digits$} ± {se:.digits$}")
}

/// What part of the record was compared, in the record's time.
pub fn span_text(rec: &Record, r: &FitResult) -> String {
    let sp = &r.span;
    let t = |i: usize| {
        rec.t
            .get(i.min(rec.len().saturating_sub(1)))
            .copied()
            .unwrap_or(0.0)
    };
    let rig = rec.rig().ok();
    let si = |y: f64, v: bool| match (rig, rec.units) {
        (Some(rig), tribo_physics::record::Units::Si) => {
            if v {
                format!("{:.1e} m/s", rig.v_of_ydot(y))
            } else {
                format!("{:.1e} m", rig.x_of_y(y))
            }
        }
        _ => format!("{y:.1e}"),
    };
    // A dimensionless record's time is τ, its channels y and y′: no unit.
    let dimensionless = rec.units == tribo_physics::record::Units::Dimensionless;
    let (tn, tu, xn, vn) = if dimensionless {
        ("τ", "", "y", "y′")
    } else {
        ("t", " s", "x", "v")
    };
    let mut s = format!(
        "{tn} = {:.4}{tu} (the release{}) to {:.4}{tu}",
        t(sp.start),
        if sp.held() > 0 {
            format!(", after {} samples held", sp.held())
        } else {
            String::new()
        },
        t(sp.end.saturating_sub(1))
    );
    if sp.at_rest() > 0 {
        let _ = write!(
            s,
            " (then |{vn}| < {}: {} samples at rest or in the noise, not compared)",
            si(sp.rest_level, true),
            sp.at_rest()
        );
    }
    if sp.spikes > 0 {
        let _ = write!(
            s,
            "; {} spike samples (speckle dropouts, glitches) left out",
            sp.spikes
        );
    }
    if sp.clipped > 0 {
        let _ = write!(
            s,
            "; {} samples at a converter's rail (clipped peaks) left out",
            sp.clipped
        );
    }
    let _ = write!(
        s,
        "; noise read from the record: {xn} {}, {vn} {}",
        si(sp.noise_y, false),
        si(sp.noise_ydot, true)
    );
    s
}

fn table(record: &str, rig: &RigUsed, r: &FitResult, rec: &Record) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "record     {record}");
    if let (Some((mu_a, se, c)), Some(rg)) = (apparatus_damping(rec, r), rec.rig) {
        let _ = writeln!(
            s,
            "rig        m = {} kg, k = {} N/m, load 0: the apparatus alone (no contact)",
            rg.mass_kg, rg.stiffness_n_per_m
        );
        let _ = writeln!(
            s,
            "mu_a       {:<30} c = {:.4e} N·s/m  (the blades' damping, = 2ζ; a contact's μ1 is \
             fitted with it unless `--apparatus-mu1` holds it)",
            pm(mu_a, se),
            c
        );
        let _ = writeln!(
            s,
            "gap        {:.3e} = {:.2} × the noise floor {:.3e}",
            r.gap,
            r.gap_ratio(),
            r.noise_floor
        );
        let _ = writeln!(s, "compared   {}", span_text(rec, r));
        let _ = writeln!(s, "verdict    {}", r.verdict.sentence());
        let _ = writeln!(s, "±          one standard error");
        return s;
    }
    let _ = writeln!(s, "rig        {}", rig.describe());
    let _ = writeln!(s, "law        {}", r.law);
    // SI coefficients of μ(v) for an SI record; a dimensionless one has none (μ_j is all).
    let dimensionless = rec.units == tribo_physics::record::Units::Dimensionless;
    let unit = |j: usize| match j {
        0 => String::new(),
        1 => " s/m".to_string(),
        j => format!(" (s/m)^{j}"),
    };
    let fitted = |j: usize| r.law == LawSpec::LuGre || r.law.powers().contains(&j);
    for (j, (m, p)) in r.mu.iter().zip(&r.p_si).enumerate() {
        if !fitted(j) {
            continue;
        }
        if dimensionless {
            let _ = writeln!(s, "mu{j:<8} {}", pm(*m, r.mu_se[j]));
            continue;
        }
        let _ = writeln!(
            s,
            "mu{j:<8} {:<30} p{j} = {}{}",
            pm(*m, r.mu_se[j]),
            pm(*p, r.p_si_se[j]),
            unit(j)
        );
    }
    if r.law == LawSpec::LuGre {
        let _ = writeln!(
            s,
            "mu_s       {}   (LuGre static level; σ0, σ1, v_s fixed)",
            pm(r.params[1], r.params_se[1])
        );
    }
    let _ = writeln!(
        s,
        "gap        {:.3e} = {:.2} × the noise floor {:.3e}{}  (RMS envelope difference and noise, / initial amplitude)",
        r.gap,
        r.gap_ratio(),
        r.noise_floor,
        if r.noise_floor <= NUMERICAL_FLOOR {
            " (the simulation's resolution: a noiseless record)"
        } else {
            ""
        }
    );
    let _ = writeln!(s, "shape      {}", r.shape.name());
    let _ = writeln!(s, "compared   {}", span_text(rec, r));
    let _ = writeln!(
        s,
        "fit        {} iterations, {} envelope points ({:.0} effectively independent), {} half cycles",
        r.iterations, r.points, r.n_eff, r.half_cycles
    );
    let _ = writeln!(s, "verdict    {}", r.verdict.sentence());
    if let Some(t) = &r.mu0_trend {
        let _ = writeln!(s, "drift      {}", t.text());
    }
    if r.verdict == FitVerdict::Inadequate {
        let _ = writeln!(
            s,
            "           (gap > {ADEQUATE_RATIO} × noise floor; the ± hold for the law's best \
             approximation of the record, not for a law that describes it)"
        );
    }
    let _ = writeln!(s, "±          one standard error");
    s
}

fn window_table(w: &[WindowFit]) -> String {
    let mut s =
        String::from("windows    (constants drifting with amplitude = the law misses a term)\n");
    let n = w.first().map_or(0, |x| x.fit.mu.len());
    let _ = write!(
        s,
        "{:>9} {:>9} {:>9} {:>9}",
        "A_start", "A_end", "tau_start", "tau_end"
    );
    for j in 0..n {
        let _ = write!(s, " {:>13}", format!("mu{j}"));
    }
    let _ = writeln!(s, " {:>10}", "gap");
    for x in w {
        let _ = write!(
            s,
            "{:>9.4} {:>9.4} {:>9.2} {:>9.2}",
            x.a_start, x.a_end, x.tau_start, x.tau_end
        );
        for m in &x.fit.mu {
            let _ = write!(s, " {m:>13.5e}");
        }
        let _ = writeln!(s, " {:>10.3e}", x.fit.gap);
        let _ = write!(s, "{:>39}", "± ");
        for m in &x.fit.mu_se {
            let _ = write!(s, " {m:>13.1e}");
        }
        let _ = writeln!(s);
    }
    s
}

/// SVG: measured and fitted envelopes vs τ (left) and the fitted law f(y') (right).
fn figure(rec: &Record, r: &FitResult, spec: LawSpec, opts: &FitOptions) -> Result<String> {
    let (tau, y, ydot) = rec.dimensionless()?;
    let data = EnvelopeData::over(&tau, &y, &ydot, &r.span, 1500).map_err(anyhow::Error::msg)?;
    let fitted = scaled_envelope(&data, spec.law(&r.params), r.initial_scale(&data), opts)
        .map_err(anyhow::Error::msg)?;
    let measured = {
        let a = mark_crandall(&y, &ydot);
        let stride = a.len().div_ceil(1500);
        (0..a.len())
            .step_by(stride)
            .map(|i| (tau[i] - tau[r.span.start.min(tau.len() - 1)], a[i]))
            .collect::<Vec<_>>()
    };
    let fit_pts: Vec<(f64, f64)> = data.tau.iter().copied().zip(fitted).collect();
    let law = r.friction_law();
    let vmax = data.a0();
    let law_pts: Vec<(f64, f64)> = (1..=200)
        .map(|i| {
            let v = vmax * i as f64 / 200.0;
            (v, law.steady_force(v))
        })
        .collect();
    let mut env = Panel::new("Mark & Crandall envelope", "τ", "A = √(y² + y'²)");
    env.series = vec![
        Series::line("measured", 6, measured),
        Series::line(format!("fitted {}", r.law), 1, fit_pts),
    ];
    let mut law_panel = Panel::new(
        format!("fitted law f(y') ({}), gap {:.2e}", r.law, r.gap),
        "y'",
        "f = F / N",
    );
    law_panel.series = vec![Series::line(r.law.to_string(), 0, law_pts)];
    let fig = Figure {
        name: "fit".into(),
        title: format!("tribo fit: {}", r.law),
        caption: String::new(),
        panels: vec![env, law_panel],
        size: (900, 760),
    };
    Ok(tribo_report::plot::to_svg(&fig)?)
}
