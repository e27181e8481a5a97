//! `--report DIR`: before/after figures (SVG) and an HTML page that embeds them.

use crate::model::{simulate_spec, Prepared, Simulated};
use crate::{ExplainError, Explanation};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// An RGB colour.
type Rgb = (u8, u8, u8);
const BLACK: Rgb = (0, 0, 0);
const RED: Rgb = (200, 30, 30);
const BLUE: Rgb = (30, 70, 200);

type Series<'a> = (&'a str, Rgb, Vec<(f64, f64)>);

fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// Tick positions: about five "nice" values covering `[lo, hi]`.
fn ticks(lo: f64, hi: f64) -> Vec<f64> {
    let span = (hi - lo).max(1e-300);
    let raw = span / 5.0;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * mag);
    let mut v = Vec::new();
    let mut t = (lo / step).ceil() * step;
    while t <= hi + 1e-9 * span && v.len() < 20 {
        v.push(if t.abs() < 1e-12 * span { 0.0 } else { t });
        t += step;
    }
    v
}

/// A line chart as a standalone SVG document (no font needed: text is left to the viewer).
fn plot(path: &Path, title: &str, xl: &str, yl: &str, series: &[Series]) -> Result<(), String> {
    let (w, h) = (900.0, 420.0);
    let (ml, mr, mt, mb) = (80.0, 20.0, 36.0, 50.0);
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(x, y) in series.iter().flat_map(|s| s.2.iter()) {
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
    if x1 <= x0 {
        x1 = x0 + 1.0;
    }
    let pad = ((y1 - y0) * 0.05).max(1e-12 * y1.abs().max(1.0));
    let (y0, y1) = (y0 - pad, y1 + pad);
    let px = |x: f64| ml + (x - x0) / (x1 - x0) * (w - ml - mr);
    let py = |y: f64| mt + (y1 - y) / (y1 - y0) * (h - mt - mb);
    let mut s = String::new();
    let _ = writeln!(
        s,
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w}\" height=\"{h}\" \
         viewBox=\"0 0 {w} {h}\" font-family=\"sans-serif\" font-size=\"12\">\n\
         <rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n\
         <text x=\"{}\" y=\"22\" text-anchor=\"middle\" font-size=\"16\">{}</text>",
        w / 2.0,
        esc(title)
    );
    let _ = writeln!(
        s,
        "<rect x=\"{ml}\" y=\"{mt}\" width=\"{}\" height=\"{}\" fill=\"none\" stroke=\"black\"/>",
        w - ml - mr,
        h - mt - mb
    );
    for t in ticks(x0, x1) {
        let x = px(t);
        let _ = writeln!(
            s,
            "<line x1=\"{x:.1}\" y1=\"{mt}\" x2=\"{x:.1}\" y2=\"{:.1}\" stroke=\"#ddd\"/>\
             <text x=\"{x:.1}\" y=\"{:.1}\" text-anchor=\"middle\">{t:.3}</text>",
            h - mb,
            h - mb + 16.0
        );
    }
    for t in ticks(y0, y1) {
        let y = py(t);
        let _ = writeln!(
            s,
            "<line x1=\"{ml}\" y1=\"{y:.1}\" x2=\"{:.1}\" y2=\"{y:.1}\" stroke=\"#ddd\"/>\
             <text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"end\">{t:.3e}</text>",
            w - mr,
            ml - 4.0,
            y + 4.0
        );
    }
    let _ = writeln!(
        s,
        "<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\">{}</text>\n\
         <text x=\"14\" y=\"{:.1}\" text-anchor=\"middle\" transform=\"rotate(-90 14 {:.1})\">{}</text>",
        (ml + w - mr) / 2.0,
        h - 10.0,
        esc(xl),
        (mt + h - mb) / 2.0,
        (mt + h - mb) / 2.0,
        esc(yl)
    );
    for (k, (name, (r, g, b), pts)) in series.iter().enumerate() {
        let mut d = String::new();
        for &(x, y) in pts.iter().filter(|p| p.0.is_finite() && p.1.is_finite()) {
            let _ = write!(d, "{:.2},{:.2} ", px(x), py(y));
        }
        let ly = mt + 14.0 + 16.0 * k as f64;
        let _ = writeln!(
            s,
            "<polyline fill=\"none\" stroke=\"rgb({r},{g},{b})\" stroke-width=\"1.2\" points=\"{}\"/>\n\
             <line x1=\"{:.1}\" y1=\"{ly:.1}\" x2=\"{:.1}\" y2=\"{ly:.1}\" stroke=\"rgb({r},{g},{b})\" stroke-width=\"2\"/>\
             <text x=\"{:.1}\" y=\"{:.1}\">{}</text>",
            d.trim_end(),
            w - mr - 230.0,
            w - mr - 205.0,
            w - mr - 200.0,
            ly + 4.0,
            esc(name)
        );
    }
    s.push_str("</svg>\n");
    std::fs::write(path, s).map_err(|e| format!("{}: {e}", path.display()))
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
            range.clone().map(|i| (t(i), f[i] * rig.load_n)).collect()
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
