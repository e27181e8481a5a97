//! `--report DIR`: before/after figures (SVG) and an HTML page that embeds them.

use crate::model::{simulate_spec, Prepared, Simulated};
use crate::{ExplainError, Explanation};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use tribo_report::plot::{to_svg, LegendPos, Panel, Series as PlotSeries, Style};
use tribo_report::Figure;

/// Palette indices of the report crate's (colour-blind-safe) palette.
const MEASURED: usize = 6; // black
const BASE: usize = 1; // vermillion
const FINAL: usize = 0; // blue

type Series<'a> = (&'a str, usize, Vec<(f64, f64)>);

fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// A line chart drawn by the report crate (plotters) and written as SVG.
fn plot(
    path: &Path,
    title: &str,
    xl: &str,
    yl: &str,
    series: &[Series],
) -> Result<(), ExplainError> {
    let mut panel = Panel::new(title, xl, yl);
    panel.legend_pos = LegendPos::Auto;
    panel.series = series
        .iter()
        .map(|(name, color, data)| {
            let finite = data
                .iter()
                .copied()
                .filter(|p| p.0.is_finite() && p.1.is_finite())
                .collect();
            PlotSeries::line(*name, *color, finite).with_style(Style::Line(1))
        })
        .collect();
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let fig = Figure {
        name: stem,
        title: title.into(),
        caption: String::new(),
        panels: vec![panel],
        size: (900, 420),
    };
    let svg = to_svg(&fig)?;
    std::fs::write(path, svg).map_err(|source| ExplainError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Writes `envelope.svg`, `residual.svg`, `force.svg` (if the record has a force channel) and
/// `index.html` into `dir` (created if needed). Returns the page's path.
pub fn write_report(
    data: &Prepared,
    ex: &Explanation,
    dir: &Path,
) -> Result<PathBuf, ExplainError> {
    let io = |source: std::io::Error| ExplainError::Io {
        path: dir.to_path_buf(),
        source,
    };
    std::fs::create_dir_all(dir).map_err(io)?;
    let sim = |m: &crate::FittedModel| -> Result<Simulated, ExplainError> {
        simulate_spec(data, &m.spec, &m.p)
    };
    let before = sim(&ex.base_model)?;
    let after = sim(&ex.final_model)?;
    let rig = data.rig;
    let t = |i: usize| rig.t_of_tau(data.tau[i]);
    let env = |s: &Simulated| -> Vec<(f64, f64)> {
        data.env_idx
            .iter()
            .map(|&i| (t(i), s.y[i].hypot(s.ydot[i])))
            .collect()
    };
    let meas: Vec<(f64, f64)> = data
        .env_idx
        .iter()
        .zip(&data.a_meas)
        .map(|(&i, &a)| (t(i), a))
        .collect();
    let fig = |name: &str| dir.join(name);
    let final_name = if ex.missing_effects.is_empty() {
        "final (= base)".to_string()
    } else {
        format!("base + {}", ex.missing_effects.join(" + "))
    };
    plot(
        &fig("envelope.svg"),
        "Mark & Crandall envelope",
        "t (s)",
        "A = √(y² + y'²)",
        &[
            ("measured", MEASURED, meas.clone()),
            ("base fit", BASE, env(&before)),
            (&final_name, FINAL, env(&after)),
        ],
    )?;
    let resid = |s: &Simulated| -> Vec<(f64, f64)> {
        env(s)
            .iter()
            .zip(&meas)
            .map(|(a, b)| (a.0, (a.1 - b.1) / data.a0))
            .collect()
    };
    plot(
        &fig("residual.svg"),
        "Envelope residual / initial amplitude",
        "t (s)",
        "(simulated − measured) / A0",
        &[
            ("base fit", BASE, resid(&before)),
            (&final_name, FINAL, resid(&after)),
        ],
    )?;
    let mut figs = vec!["envelope.svg", "residual.svg"];
    if let Some(fm) = &data.f_meas {
        // Three cycles from the middle of the motion.
        let n = data.tau.len();
        let mid = n / 3;
        let span = ((3.0 * 2.0 * std::f64::consts::PI / data.dtau) as usize).max(8);
        let range = mid..(mid + span).min(n);
        let series = |f: &[f64]| -> Vec<(f64, f64)> {
            range.clone().map(|i| (t(i), f[i] * rig.load_n)).collect()
        };
        plot(
            &fig("force.svg"),
            "Friction force channel (three cycles)",
            "t (s)",
            "F (N)",
            &[
                ("measured", MEASURED, series(fm)),
                ("base fit", BASE, series(&before.f_meas)),
                (&final_name, FINAL, series(&after.f_meas)),
            ],
        )?;
        let loops = |f: &[f64]| -> Vec<(f64, f64)> {
            range
                .clone()
                .map(|i| (rig.v_of_ydot(data.ydot[i]), f[i] * rig.load_n))
                .collect()
        };
        plot(
            &fig("force_velocity.svg"),
            "Force against measured velocity (three cycles)",
            "v (m/s)",
            "F (N)",
            &[
                ("measured", MEASURED, loops(fm)),
                ("base fit", BASE, loops(&before.f_meas)),
                (&final_name, FINAL, loops(&after.f_meas)),
            ],
        )?;
        figs.push("force.svg");
        figs.push("force_velocity.svg");
    }
    let mut h = String::new();
    let _ = write!(
        h,
        "<!doctype html>\n<html><head><meta charset=\"utf-8\"><title>tribo explain</title>\
         <style>body{{font-family:sans-serif;max-width:960px;margin:auto}}\
         td,th{{padding:2px 8px;border-bottom:1px solid #ccc}}</style></head><body>\n\
         <h1>tribo explain</h1>\n<p>Base law: <b>{}</b>. Gap {:.3e} &rarr; {:.3e}.</p>\n",
        ex.base, ex.gap_initial, ex.gap_final
    );
    let _ = writeln!(h, "<p><b>{}</b></p>", esc(&ex.answer()));
    if !ex.steps.is_empty() {
        h.push_str(
            "<table><tr><th>effect</th><th>gap before</th><th>gap after</th><th>evidence \
             (threshold)</th><th>parameters (± one standard error)</th></tr>\n",
        );
        for s in &ex.steps {
            let params: Vec<String> = s
                .params
                .iter()
                .map(|(k, v)| {
                    let se = s.params_se.get(k).copied().unwrap_or(f64::NAN);
                    format!("{k} = {v:.4e} ± {se:.1e}")
                })
                .collect();
            let _ = writeln!(
                h,
                "<tr><td>{}</td><td>{:.3e}</td><td>{:.3e}</td><td>{:.0} ({:.1})</td><td>{}</td></tr>",
                s.effect,
                s.gap_before,
                s.gap_after,
                s.evidence.value,
                s.evidence.threshold,
                esc(&params.join("<br>")).replace("&lt;br&gt;", "<br>")
            );
        }
        h.push_str("</table>\n");
    }
    for f in &figs {
        let _ = writeln!(h, "<p><img src=\"{f}\" alt=\"{f}\" width=\"900\"></p>");
    }
    let _ = writeln!(
        h,
        "<h2>Diagnostics</h2>\n<pre>{}</pre>\n</body></html>",
        serde_json::to_string_pretty(&ex.diagnostics).unwrap_or_default()
    );
    let page = dir.join("index.html");
    std::fs::write(&page, h).map_err(io)?;
    Ok(page)
}
