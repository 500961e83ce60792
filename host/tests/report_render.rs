//! The HTML report is self-contained and complete: every section is present, every figure is
//! well-formed SVG (parsed as XML) with real data paths, the same SVGs are written to
//! figures/, and nothing refers to the network or runs a script.
mod pipeline_support;

use ferrosid::output::write_outputs;
use ferrosid::pipeline::{run_pipeline, LoadedConfig};
use pipeline_support as sup;

const SECTIONS: [&str; 12] = [
    "verdict",
    "receipts",
    "frequency-response",
    "coherence",
    "order",
    "robustness",
    "sensitivity",
    "step",
    "audit",
    "validation",
    "controller",
    "provenance",
];

const FIGURES: [&str; 9] = [
    "bode",
    "coherence",
    "singular_values",
    "robustness",
    "uncertainty",
    "sensitivity",
    "step",
    "audit",
    "validation",
];

/// Number of drawn data points in an SVG: polyline vertices and circles.
fn svg_points(svg: &str) -> (usize, usize) {
    let doc =
        roxmltree::Document::parse(svg).unwrap_or_else(|e| panic!("SVG not well-formed: {e}"));
    let root = doc.root_element();
    assert_eq!(root.tag_name().name(), "svg");
    let mut lines = 0;
    let mut circles = 0;
    for n in doc.descendants() {
        match n.tag_name().name() {
            "polyline" => {
                let pts = n.attribute("points").unwrap_or("");
                let count = pts.split_whitespace().count();
                if count >= 2 {
                    lines += 1;
                }
                for p in pts.split_whitespace() {
                    let (x, y) = p.split_once(',').expect("x,y");
                    let x: f64 = x.parse().expect("x");
                    let y: f64 = y.parse().expect("y");
                    assert!(x.is_finite() && y.is_finite());
                }
            }
            "circle" => circles += 1,
            _ => {}
        }
    }
    (lines, circles)
}

#[test]
fn report_has_every_section_and_well_formed_figures() {
    let toml = sup::setup("report-render", "", "");
    let dir = toml.parent().expect("dir").join("out");
    let cfg = LoadedConfig::load(&toml).expect("load");
    let run = run_pipeline(&cfg, &|_| {}).expect("run");
    write_outputs(&run, &dir).expect("write");
    let html = std::fs::read_to_string(dir.join("report.html")).expect("html");

    assert!(html.starts_with("<!DOCTYPE html>"));
    assert!(html.trim_end().ends_with("</html>"));
    for s in SECTIONS {
        let tag = format!("id=\"{s}\"");
        assert_eq!(html.matches(&tag).count(), 1, "section {s}");
    }
    // Verdict banner and one table row per receipt.
    assert!(html.contains("class=\"banner pass\"") && html.contains("PASS — all"));
    let rows =
        html.matches("<tr class=\"pass\">").count() + html.matches("<tr class=\"fail\">").count();
    assert_eq!(rows, run.receipts.receipts.len());
    for r in &run.receipts.receipts {
        assert!(
            html.contains(&format!("<b>{}</b>", r.name)),
            "receipt {} not in the table",
            r.name
        );
    }
    // Self-contained: no scripts, no external resources.
    let lower = html.to_ascii_lowercase();
    assert!(!lower.contains("<script"));
    assert!(!lower.contains("<link") && !lower.contains("<img") && !lower.contains("@import"));
    let without_ns = lower.replace("xmlns=\"http://www.w3.org/2000/svg\"", "");
    assert!(!without_ns.contains("http://") && !without_ns.contains("https://"));
    // Provenance: every input's SHA-256.
    for f in &run.inputs {
        assert!(html.contains(&f.sha256), "hash of {} missing", f.path);
        assert_eq!(f.sha256.len(), 64);
    }

    // Every figure: inline in the HTML, identical to figures/<name>.svg, well-formed, with data.
    for name in FIGURES {
        let file = std::fs::read_to_string(dir.join("figures").join(format!("{name}.svg")))
            .unwrap_or_else(|e| panic!("figures/{name}.svg: {e}"));
        let start = html
            .find(&format!("<figure id=\"fig-{name}\">"))
            .unwrap_or_else(|| panic!("figure {name} not inline"));
        let body = &html[start..];
        let s0 = body.find("<svg").expect("svg start");
        let s1 = body.find("</svg>").expect("svg end") + "</svg>".len();
        let inline = &body[s0..s1];
        assert_eq!(
            inline.trim(),
            file.trim(),
            "inline {name} differs from the file"
        );
        let (lines, circles) = svg_points(&file);
        assert!(lines >= 1, "{name}: no data line drawn");
        if name == "bode" {
            // ETFE dots of the gated bins and the model line.
            assert!(circles >= 100, "bode: {circles} dots");
            assert!(lines >= 4);
        }
        // Axis labels are present.
        assert!(file.contains("<text"), "{name}: no text");
    }
    // The Bode figure names the model order and the gate.
    let bode = std::fs::read_to_string(dir.join("figures/bode.svg")).expect("bode");
    assert!(bode.contains("model, order 3") && bode.contains("coh ≥ 0.85"));
}

#[test]
fn failing_run_report_says_fail_and_explains_missing_sections() {
    let toml = sup::setup("report-fail", "ms_max = 1.01", "");
    let dir = toml.parent().expect("dir").join("out");
    let cfg = LoadedConfig::load(&toml).expect("load");
    let run = run_pipeline(&cfg, &|_| {}).expect("run");
    write_outputs(&run, &dir).expect("write");
    let html = std::fs::read_to_string(dir.join("report.html")).expect("html");
    assert!(html.contains("class=\"banner fail\"") && html.contains("FAIL — "));
    assert!(html.contains("controller_design"));
    for s in SECTIONS {
        assert!(html.contains(&format!("id=\"{s}\"")), "section {s}");
    }
    assert!(html.contains("No loop: no controller was tuned."));
    assert!(html.contains("<b>No controller.</b>"));
    // Loop figures are absent, the data figures are there and well-formed.
    for name in ["step", "sensitivity", "robustness"] {
        assert!(
            !dir.join("figures").join(format!("{name}.svg")).exists(),
            "{name}"
        );
    }
    for name in [
        "bode",
        "coherence",
        "singular_values",
        "uncertainty",
        "audit",
        "validation",
    ] {
        let svg = std::fs::read_to_string(dir.join("figures").join(format!("{name}.svg")))
            .expect("figure");
        assert!(svg_points(&svg).0 >= 1, "{name}");
    }
}
