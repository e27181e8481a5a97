//! The self-contained HTML page: inline CSS, inline SVG figures, no script, no external resource.

use crate::Report;
use std::fmt::Write as _;

/// Escapes text for HTML element content and attribute values.
pub fn esc(s: &str) -> String {
    let mut o = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => o.push_str("&amp;"),
            '<' => o.push_str("&lt;"),
            '>' => o.push_str("&gt;"),
            '"' => o.push_str("&quot;"),
            '\'' => o.push_str("&#39;"),
            c => o.push(c),
        }
    }
    o
}

/// A table: header row and body rows, cells given as plain text (escaped here).
pub fn table(head: &[&str], rows: &[Vec<String>]) -> String {
    let mut s = String::from("<table>\n<tr>");
    for h in head {
        let _ = write!(s, "<th>{}</th>", esc(h));
    }
    s.push_str("</tr>\n");
    for r in rows {
        s.push_str("<tr>");
        for c in r {
            let _ = write!(s, "<td>{}</td>", esc(c));
        }
        s.push_str("</tr>\n");
    }
    s.push_str("</table>\n");
    s
}

/// Drops the XML declaration of an SVG document so it can be inlined.
fn inline_svg(svg: &str) -> &str {
    match svg.find("<svg") {
        Some(i) => &svg[i..],
        None => svg,
    }
}

const STYLE: &str =
    "body{font-family:sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;color:#222}\
table{border-collapse:collapse;margin:0.5em 0 1.5em}\
td,th{border:1px solid #bbb;padding:0.25em 0.6em;text-align:left;font-variant-numeric:tabular-nums}\
th{background:#eee}figure{margin:1.5em 0}figcaption{margin-top:0.3em}\
.note{color:#8a4b00}svg{max-width:100%;height:auto}";

/// The whole page. `svgs[i]` is the rendering of `report.figures[i]`.
pub fn page(report: &Report, svgs: &[String]) -> String {
    let mut s = String::new();
    let _ = write!(
        s,
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>{}</title>\n<style>{STYLE}</style>\n</head>\n<body>\n<h1>{}</h1>\n",
        esc(&report.title),
        esc(&report.title)
    );
    s.push_str(&report.summary_html);
    if !report.notes.is_empty() {
        s.push_str("<h2>Notes</h2>\n<ul>\n");
        for n in &report.notes {
            let _ = writeln!(s, "<li class=\"note\">{}</li>", esc(n));
        }
        s.push_str("</ul>\n");
    }
    for (fig, svg) in report.figures.iter().zip(svgs) {
        let _ = write!(
            s,
            "<figure id=\"fig-{name}\">\n<h2>{title}</h2>\n{svg}\n<figcaption><b>What to look at:</b> {cap} <small>(files: {name}.svg{png})</small></figcaption>\n</figure>\n",
            name = esc(&fig.name),
            title = esc(&fig.title),
            svg = inline_svg(svg),
            cap = esc(&fig.caption),
            png = if report.png {
                format!(", {}.png", esc(&fig.name))
            } else {
                String::new()
            }
        );
    }
    s.push_str("</body>\n</html>\n");
    s
}
