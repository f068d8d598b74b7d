//! A single self-contained HTML page: every plot inlined as SVG, no script, no external
//! stylesheet or font, so the file can be mailed, archived or opened offline.

use std::fmt::Write as _;

/// One titled part of a report: a plot and the numbers behind it.
#[derive(Debug, Clone, PartialEq)]
pub struct Section {
    /// Heading.
    pub heading: String,
    /// One paragraph saying what is shown.
    pub caption: String,
    /// The plot as an SVG document (inlined as is).
    pub svg: String,
    /// Label/value rows shown beside the plot.
    pub rows: Vec<(String, String)>,
}

/// A whole report.
#[derive(Debug, Clone, PartialEq)]
pub struct Report {
    /// Page title and top heading.
    pub title: String,
    /// Facts about the subject (model, cohort, settings) shown first.
    pub facts: Vec<(String, String)>,
    /// The sections, in order.
    pub sections: Vec<Section>,
    /// Software version and units note in the footer.
    pub footer: String,
}

const STYLE: &str = "body{font-family:sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;color:#222}\
h1{font-size:1.6em}h2{font-size:1.2em;margin-top:2em;border-bottom:1px solid #ccc}\
.row{display:flex;flex-wrap:wrap;gap:1.5em;align-items:flex-start}\
table{border-collapse:collapse;font-size:.9em}td{padding:.15em .8em;border-bottom:1px solid #eee}\
td:first-child{color:#555}p.caption{color:#444;max-width:60em}footer{margin-top:3em;color:#777;font-size:.8em}";

/// Renders the report as one HTML document.
pub fn render_html(report: &Report) -> String {
    let mut out = String::with_capacity(64 * 1024);
    let _ = write!(
        out,
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{t}</title><style>{STYLE}</style></head><body>\n<h1>{t}</h1>\n",
        t = escape(&report.title)
    );
    table(&mut out, &report.facts);
    for s in &report.sections {
        let _ = write!(
            out,
            "<section><h2>{}</h2><p class=\"caption\">{}</p><div class=\"row\"><div>{}</div>",
            escape(&s.heading),
            escape(&s.caption),
            strip_xml_declaration(&s.svg)
        );
        table(&mut out, &s.rows);
        out.push_str("</div></section>\n");
    }
    let _ = write!(
        out,
        "<footer>{}</footer>\n</body></html>\n",
        escape(&report.footer)
    );
    out
}

fn table(out: &mut String, rows: &[(String, String)]) {
    if rows.is_empty() {
        return;
    }
    out.push_str("<table>");
    for (k, v) in rows {
        let _ = write!(out, "<tr><td>{}</td><td>{}</td></tr>", escape(k), escape(v));
    }
    out.push_str("</table>\n");
}

/// An SVG document embedded in HTML must not carry its own XML declaration.
fn strip_xml_declaration(svg: &str) -> &str {
    match svg.trim_start().strip_prefix("<?xml") {
        Some(rest) => rest
            .split_once("?>")
            .map_or(svg, |(_, body)| body.trim_start()),
        None => svg,
    }
}

/// Escapes text for HTML element content and attribute values.
pub fn escape(text: &str) -> String {
    let mut s = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => s.push_str("&amp;"),
            '<' => s.push_str("&lt;"),
            '>' => s.push_str("&gt;"),
            '"' => s.push_str("&quot;"),
            '\'' => s.push_str("&#39;"),
            c => s.push(c),
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_is_escaped_and_svg_inlined_without_declaration() {
        let report = Report {
            title: "Model <m&1>".into(),
            facts: vec![("id".into(), "\"x\"".into())],
            sections: vec![Section {
                heading: "CD".into(),
                caption: "a < b".into(),
                svg: "<?xml version=\"1.0\"?>\n<svg width=\"1\"></svg>".into(),
                rows: vec![("median".into(), "1e-4".into())],
            }],
            footer: "v0".into(),
        };
        let html = render_html(&report);
        assert!(html.contains("<title>Model &lt;m&amp;1&gt;</title>"));
        assert!(html.contains("&quot;x&quot;"));
        assert!(html.contains("a &lt; b"));
        assert!(html.contains("<div><svg width=\"1\"></svg>"));
        assert!(!html.contains("<?xml"));
        assert!(!html.contains("<script") && !html.contains(" src=") && !html.contains("href="));
    }
}
