//! The report's HTML escaping, one definition for the templates and for Rust callers:
//! [`ReportHtml`] is the escaper askama applies to every `{{ … }}` of a `.html` template
//! (`host/askama.toml`, `[[escaper]]`), and [`esc`] runs it on a string.
//!
//! `&`, `<`, `>`, `"` and `'` become `&amp;`, `&lt;`, `&gt;`, `&quot;` and `&#39;`; control
//! characters other than `\n` and `\t` become U+FFFD (XML/HTML text cannot hold them, and a
//! log's name or an error message may carry one). askama's own HTML escaper writes numeric
//! entities (`&#38;`) and keeps control characters, so the report brings its own.
use std::fmt::{self, Write};

/// The report's HTML escaper (see the module docs).
#[derive(Debug, Clone, Copy, Default)]
pub struct ReportHtml;

impl askama::filters::Escaper for ReportHtml {
    fn write_escaped_str<W: Write>(&self, mut dest: W, s: &str) -> fmt::Result {
        // Copy the runs between characters that need escaping in one piece.
        let mut start = 0;
        for (i, ch) in s.char_indices() {
            let rep = match ch {
                '&' => "&amp;",
                '<' => "&lt;",
                '>' => "&gt;",
                '"' => "&quot;",
                '\'' => "&#39;",
                c if c.is_control() && !matches!(c, '\n' | '\t') => "\u{FFFD}",
                _ => continue,
            };
            dest.write_str(&s[start..i])?;
            dest.write_str(rep)?;
            start = i + ch.len_utf8();
        }
        dest.write_str(&s[start..])
    }
}

/// HTML-escapes text with [`ReportHtml`].
pub fn esc(s: &str) -> String {
    use askama::filters::Escaper as _;
    let mut o = String::with_capacity(s.len());
    // Writing into a String cannot fail.
    let _ = ReportHtml.write_escaped_str(&mut o, s);
    o
}

#[cfg(test)]
mod tests {
    use super::esc;
    use askama::Template;

    /// The escaping as the report did it before the templates (a `write!` per character),
    /// kept here as the reference.
    fn reference(s: &str) -> String {
        let mut o = String::new();
        for ch in s.chars() {
            match ch {
                '&' => o.push_str("&amp;"),
                '<' => o.push_str("&lt;"),
                '>' => o.push_str("&gt;"),
                '"' => o.push_str("&quot;"),
                '\'' => o.push_str("&#39;"),
                c if c.is_control() && !matches!(c, '\n' | '\t') => o.push('\u{FFFD}'),
                c => o.push(c),
            }
        }
        o
    }

    #[derive(Template)]
    #[template(source = "[{{ s }}]", ext = "html")]
    struct One<'a> {
        s: &'a str,
    }

    const HOSTILE: [&str; 9] = [
        "",
        "plain text, no markup",
        "<script>alert('x')</script>",
        "a & b \"quoted\" 'single' <b>bold</b> &amp; already",
        "ctl \u{0}\u{1}\u{7}\u{8}\u{b}\u{c}\r\u{1b}\u{7f}\u{80}\u{9f} end",
        "keep\nnewline\tand tab",
        "non-ASCII: é ∞ γ² ‖W_m T‖∞ 𝄞 — ±",
        "\u{85}\u{2028}\u{feff}\u{fffd}",
        "<&>\"'<&>\"'",
    ];

    #[test]
    fn template_escaper_equals_esc_and_the_reference_on_hostile_strings() {
        for s in HOSTILE {
            let rendered = One { s }.render().expect("render");
            assert_eq!(rendered, format!("[{}]", esc(s)), "{s:?}");
            assert_eq!(esc(s), reference(s), "{s:?}");
        }
        // Spelled out, so that the reference cannot drift with the code under test.
        assert_eq!(
            esc("<a href='x'>&\"\u{1}\n\t</a>"),
            "&lt;a href=&#39;x&#39;&gt;&amp;&quot;\u{FFFD}\n\t&lt;/a&gt;"
        );
    }

    #[test]
    fn every_character_below_0x3000_escapes_as_the_reference() {
        let all: String = (0u32..0x3000).filter_map(char::from_u32).collect();
        assert_eq!(esc(&all), reference(&all));
        let rendered = One { s: &all }.render().expect("render");
        assert_eq!(rendered, format!("[{}]", reference(&all)));
    }

    #[test]
    fn only_the_inlined_svg_is_unescaped_in_the_report_templates() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("templates/report");
        let mut unescaped = Vec::new();
        for entry in std::fs::read_dir(&dir).expect("templates/report") {
            let path = entry.expect("entry").path();
            let text = std::fs::read_to_string(&path).expect("template");
            for (i, line) in text.lines().enumerate() {
                for (at, _) in line.match_indices("|safe") {
                    let start = line[..at].rfind("{{").unwrap_or(0);
                    let expr = line[start..at].trim_start_matches("{{").trim();
                    if expr != "f.svg" {
                        unescaped.push(format!("{}:{}: {expr}", path.display(), i + 1));
                    }
                }
            }
        }
        assert!(unescaped.is_empty(), "unescaped: {unescaped:#?}");
    }
}
