//! `--report DIR`: before/after figures (SVG) and an HTML page that embeds them.

use crate::model::{simulate_spec, Prepared, Simulated};
use crate::{ExplainError, Explanation};
use plotters::prelude::*;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

type Series<'a> = (&'a str, RGBColor, Vec<(f64, f64)>);

fn plot(path: &Path, title: &str, xl: &str, yl: &str, series: &[Series]) -> Result<(), String> {
    let pts = series.iter().flat_map(|s| s.2.iter());
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(x, y) in pts {
        if x.is_finite() && y.is_finite() {
            x0 = x0.min(x);
            x1 = x1.max(x);
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
    }
    if x0 > x1 {
        (x0, x1, y0, y1) = (0.0, 1.0, 0.0, 1.0);
    }
    if x1 - x0 <= 0.0 {
        x1 = x0 + 1.0;
    }
    let pad = ((y1 - y0) * 0.05).max(1e-12);
    let e = |e: &dyn std::fmt::Display| e.to_string();
    let root = SVGBackend::new(path, (900, 420)).into_drawing_area();
    root.fill(&WHITE).map_err(|x| e(&x))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 18))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(x0..x1, (y0 - pad)..(y1 + pad))
        .map_err(|x| e(&x))?;
    chart
        .configure_mesh()
        .x_desc(xl)
        .y_desc(yl)
        .draw()
        .map_err(|x| e(&x))?;
    for (name, color, s) in series {
        let c = *color;
        chart
            .draw_series(LineSeries::new(s.iter().copied(), c))
            .map_err(|x| e(&x))?
            .label(*name)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c));
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(|x| e(&x))?;
    root.present().map_err(|x| e(&x))?;
    Ok(())
}

/// Writes `envelope.svg`, `residual.svg`, `force.svg` (if the record has a force channel) and
/// `index.html` into `dir` (created if needed). Returns the page's path.
pub fn write_report(
    data: &Prepared,
    ex: &Explanation,
    dir: &Path,
) -> Result<PathBuf, ExplainError> {
    let io = |e: std::io::Error| ExplainError(format!("{}: {e}", dir.display()));
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
    let err = |e: String| ExplainError(format!("figure: {e}"));
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
            ("measured", BLACK, meas.clone()),
            ("base fit", RED, env(&before)),
            (&final_name, BLUE, env(&after)),
        ],
    )
    .map_err(err)?;
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
            ("base fit", RED, resid(&before)),
            (&final_name, BLUE, resid(&after)),
        ],
    )
    .map_err(err)?;
    let mut figs = vec!["envelope.svg", "residual.svg"];
    if let Some(fm) = &data.f_meas {
        // Three cycles from the middle of the motion.
        let n = data.tau.len();
        let mid = n / 3;
        let span = ((3.0 * 2.0 * std::f64::consts::PI / data.dtau) as usize).max(8);
        let range = mid..(mid + span).min(n);
        let series = |f: &[f64]| -> Vec<(f64, f64)> {
            range
                .clone()
                .map(|i| (t(i), f[i] * rig.load_n))
                .collect()
        };
        plot(
            &fig("force.svg"),
            "Friction force channel (three cycles)",
            "t (s)",
            "F (N)",
            &[
                ("measured", BLACK, series(fm)),
                ("base fit", RED, series(&before.f_meas)),
                (&final_name, BLUE, series(&after.f_meas)),
            ],
        )
        .map_err(err)?;
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
                ("measured", BLACK, loops(fm)),
                ("base fit", RED, loops(&before.f_meas)),
                (&final_name, BLUE, loops(&after.f_meas)),
            ],
        )
        .map_err(err)?;
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
    if ex.steps.is_empty() {
        h.push_str("<p>No missing effect: the base law explains the record.</p>\n");
    } else {
        h.push_str(
            "<table><tr><th>effect</th><th>gap before</th><th>gap after</th><th>ΔBIC</th>\
             <th>parameters</th></tr>\n",
        );
        for s in &ex.steps {
            let params: Vec<String> = s.params.iter().map(|(k, v)| format!("{k} = {v:.4e}")).collect();
            let _ = writeln!(
                h,
                "<tr><td>{}</td><td>{:.3e}</td><td>{:.3e}</td><td>{:.0}</td><td>{}</td></tr>",
                s.effect,
                s.gap_before,
                s.gap_after,
                s.delta_bic,
                params.join("<br>")
            );
        }
        h.push_str("</table>\n");
    }
    if !ex.ambiguous.is_empty() {
        let _ = writeln!(
            h,
            "<p>Unresolved: {} explain the remainder about equally well.</p>",
            ex.ambiguous.join(", ")
        );
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
