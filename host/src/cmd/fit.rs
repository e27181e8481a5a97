//! `tribo fit`: identify a friction law from a record (thesis ch. 3.5).

use anyhow::{Context, Result};
use clap::Parser;
use std::fmt::Write as _;
use std::path::PathBuf;
use tribo_physics::envelope::mark_crandall;
use tribo_physics::identify::{
    fit, fit_windows, simulated_envelope, EnvelopeData, FitOptions, FitResult, LawSpec, WindowFit,
};
use tribo_physics::{Record, Rig};

/// Fit a friction law to a record by Levenberg–Marquardt on the Mark & Crandall envelope.
///
/// RECORD is a CSV with header `t_s,x_m,v_m_s[,ft_n,temp_c,ecr_ohm]` and rig constants in
/// `# mass_kg=…`, `# stiffness_n_per_m=…`, `# load_n=…` comment lines (the flags below override
/// them), or a dimensionless CSV `tau,y,ydot`.
///
/// `--json` prints one object `{"law", "mu": [μ0, μ1, …], "gap", "p_si", "params", "iterations",
/// "converged", "shape", "y0", "points"}`: `mu` are the dimensionless constants of seed eq. 10–13 in
/// order of j, `gap` the RMS envelope difference divided by the initial amplitude, `shape` the
/// envelope shape (straight/convex/concave/mixed) the fitted law predicts.
///
/// `--windows N` also fits the law on N successive windows of equal amplitude drop (thesis
/// ch. 3.7, Tables 6–7) and prints one row per window; with `--json` the object gains
/// `"windows": [{"a_start", "a_end", "tau_start", "tau_end", "fit": {…}}, …]`. Constants that
/// drift from window to window mean the law misses an amplitude-dependent term.
///
/// A record with holes is refused: a run whose rig lost samples (its acquisition gaps), a run with
/// blocks not received, a CSV whose time axis jumps. `--longest-clean-stretch` fits the longest
/// stretch of consecutive samples instead (and says which on stderr).
#[derive(Parser, Debug)]
pub struct Args {
    /// The record (CSV).
    pub record: PathBuf,
    /// Law: coulomb, viscous, coulomb-viscous, quadratic, poly:N, lugre.
    #[arg(long, default_value = "coulomb-viscous")]
    pub law: String,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
    /// Write an SVG figure: measured vs fitted envelope.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Override the record's mass (kg).
    #[arg(long)]
    pub mass_kg: Option<f64>,
    /// Override the record's stiffness (N/m).
    #[arg(long)]
    pub stiffness: Option<f64>,
    /// Override the record's normal load (N).
    #[arg(long)]
    pub load_n: Option<f64>,
    /// Known apparatus damping μ_a kept fixed (0 = fit the total damping).
    #[arg(long, default_value_t = 0.0)]
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
    let spec: LawSpec = a.law.parse().map_err(anyhow::Error::msg)?;
    let holes = if a.longest_clean_stretch {
        crate::Holes::LongestCleanStretch
    } else {
        crate::Holes::Refuse
    };
    let mut rec = crate::load_for_fit(&a.record, holes)?;
    if a.mass_kg.is_some() || a.stiffness.is_some() || a.load_n.is_some() {
        let base = rec.rig.unwrap_or(Rig::REAL);
        rec.rig = Some(
            Rig::new(
                a.mass_kg.unwrap_or(base.mass_kg),
                a.stiffness.unwrap_or(base.stiffness_n_per_m),
                a.load_n.unwrap_or(base.load_n),
            )
            .map_err(anyhow::Error::msg)?,
        );
    }
    let opts = FitOptions {
        apparatus_mu1: a.apparatus_mu1,
        ..FitOptions::default()
    };
    let r = fit(&rec, spec, &opts)?;
    let windows = if a.windows > 0 {
        fit_windows(&rec, spec, a.windows, &opts)?
    } else {
        Vec::new()
    };
    if a.json {
        let mut j = r.to_json();
        if a.windows > 0 {
            let items: Vec<String> = windows.iter().map(WindowFit::to_json).collect();
            j.pop(); // the closing brace
            let _ = write!(j, ", \"windows\": [{}]}}", items.join(", "));
        }
        println!("{j}");
    } else {
        print!("{}", table(&r));
        if a.windows > 0 {
            print!("{}", window_table(&windows));
        }
    }
    if let Some(p) = &a.plot {
        let svg = figure(&rec, &r, spec, &opts)?;
        std::fs::write(p, svg).with_context(|| format!("writing {}", p.display()))?;
    }
    Ok(())
}

fn table(r: &FitResult) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "law        {}", r.law);
    for (j, (m, p)) in r.mu.iter().zip(&r.p_si).enumerate() {
        let _ = writeln!(s, "mu{j:<8} {m:>14.6e}    (p{j} = {p:.6e} in SI, v in m/s)");
    }
    let _ = writeln!(
        s,
        "gap        {:.3e}  (RMS envelope difference / initial amplitude)",
        r.gap
    );
    let _ = writeln!(s, "shape      {}", r.shape.name());
    let _ = writeln!(
        s,
        "fit        {} iterations, {}, {} envelope points",
        r.iterations,
        if r.converged {
            "converged"
        } else {
            "NOT converged"
        },
        r.points
    );
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
    }
    s
}

/// SVG: measured and fitted envelopes vs τ (left) and the fitted law f(y') (right).
fn figure(rec: &Record, r: &FitResult, spec: LawSpec, opts: &FitOptions) -> Result<String> {
    let (tau, y, ydot) = rec.dimensionless()?;
    let data = EnvelopeData::new(&tau, &y, &ydot, 1500).map_err(anyhow::Error::msg)?;
    let fitted =
        simulated_envelope(&data, spec.law(&r.params), opts).map_err(anyhow::Error::msg)?;
    let measured = {
        let a = mark_crandall(&y, &ydot);
        let stride = a.len().div_ceil(1500);
        (0..a.len())
            .step_by(stride)
            .map(|i| (tau[i] - tau[0], a[i]))
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
    let mut s = String::from(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"1000\" height=\"420\" font-family=\"sans-serif\" font-size=\"12\">\n<rect width=\"1000\" height=\"420\" fill=\"white\"/>\n",
    );
    panel(
        &mut s,
        60.0,
        "envelope A(τ): measured (black), fitted (red)",
        "τ",
        &[(&measured, "black"), (&fit_pts, "red")],
    );
    panel(
        &mut s,
        560.0,
        &format!("fitted law f(y') ({}), gap {:.2e}", r.law, r.gap),
        "y'",
        &[(&law_pts, "blue")],
    );
    s.push_str("</svg>\n");
    Ok(s)
}

fn panel(s: &mut String, x0: f64, title: &str, xlabel: &str, series: &[(&Vec<(f64, f64)>, &str)]) {
    let (w, h, y0) = (400.0, 320.0, 50.0);
    let all = series.iter().flat_map(|(p, _)| p.iter());
    let (mut xmin, mut xmax, mut ymin, mut ymax) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for &(x, y) in all {
        xmin = xmin.min(x);
        xmax = xmax.max(x);
        ymin = ymin.min(y);
        ymax = ymax.max(y);
    }
    ymin = ymin.min(0.0);
    if !xmin.is_finite() || !xmax.is_finite() {
        (xmin, xmax) = (0.0, 1.0);
    }
    if !ymin.is_finite() || !ymax.is_finite() {
        (ymin, ymax) = (0.0, 1.0);
    }
    if xmax <= xmin {
        xmax = xmin + 1.0;
    }
    if ymax <= ymin {
        ymax = ymin + 1.0;
    }
    let _ = writeln!(s, "<text x=\"{}\" y=\"30\">{}</text>", x0, title);
    let _ = writeln!(
        s,
        "<rect x=\"{x0}\" y=\"{y0}\" width=\"{w}\" height=\"{h}\" fill=\"none\" stroke=\"#888\"/>"
    );
    let _ = writeln!(
        s,
        "<text x=\"{}\" y=\"{}\">{xlabel}: {xmin:.3} … {xmax:.3}</text>",
        x0,
        y0 + h + 20.0
    );
    let _ = writeln!(
        s,
        "<text x=\"{}\" y=\"{}\">y: {ymin:.4} … {ymax:.4}</text>",
        x0,
        y0 + h + 38.0
    );
    for (pts, color) in series {
        let mut d = String::new();
        for (i, &(x, y)) in pts.iter().enumerate() {
            let px = x0 + (x - xmin) / (xmax - xmin) * w;
            let py = y0 + h - (y - ymin) / (ymax - ymin) * h;
            let _ = write!(d, "{}{px:.1},{py:.1} ", if i == 0 { "M" } else { "L" });
        }
        let _ = writeln!(
            s,
            "<path d=\"{d}\" fill=\"none\" stroke=\"{color}\" stroke-width=\"1\"/>"
        );
    }
}
