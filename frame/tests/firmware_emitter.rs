//! The power-up firmware writes its frame lines with defmt, whose format strings must be
//! literals: in `firmware/app/src/main.rs`, and the `RECEIPT`/`VERDICT` lines in
//! `firmware/app/src/receipt_log.rs` (shared with the closed-loop image). This test reads those
//! literals and checks them
//! against this crate's definition, so the emitter and the host parser cannot drift apart:
//! every frame keyword is emitted, the header keys come in [`HEADER_KEYS`] order, and the
//! `FRAME`/`RECEIPT` lines carry exactly [`BIN_FIELDS`]/[`RECEIPT_FIELDS`] fields.
use ferrosid_frame::{
    header_field, split_line, Keyword, BIN_FIELDS, END_COUNT_PREFIX, HEADER_KEYS, RECEIPT_FIELDS,
};

/// The emitter's sources: every frame line is written in exactly one of them.
const EMITTER: [&str; 2] = [
    include_str!("../../firmware/app/src/main.rs"),
    include_str!("../../firmware/app/src/receipt_log.rs"),
];

/// The first string literal of every `defmt::println!` call.
fn println_literals(src: &str) -> Vec<String> {
    let mut out = Vec::new();
    for (at, _) in src.match_indices("defmt::println!(") {
        let rest = &src[at..];
        let Some(open) = rest.find('"') else { continue };
        let body = &rest[open + 1..];
        let Some(close) = body.find('"') else {
            continue;
        };
        out.push(body[..close].to_string());
    }
    out
}

/// A defmt format string with sample values in place of its `{=type}` parameters.
fn instantiate(fmt: &str) -> String {
    let mut s = String::new();
    let mut rest = fmt;
    while let Some(open) = rest.find('{') {
        s.push_str(&rest[..open]);
        let close = rest[open..].find('}').expect("unclosed defmt parameter") + open;
        s.push_str(match &rest[open + 1..close] {
            "=f32" => "0.5",
            "=str" => "PASS",
            "=[?]" => "[]",
            _ => "7",
        });
        rest = &rest[close + 1..];
    }
    s.push_str(rest);
    s
}

fn emitted(k: Keyword) -> Vec<Vec<String>> {
    EMITTER
        .iter()
        .flat_map(|src| println_literals(src))
        .map(|f| instantiate(&f))
        .filter_map(|line| {
            let (kw, rest) = split_line(&line)?;
            (kw == k && line.starts_with(k.as_str())).then(|| rest.map(str::to_string).collect())
        })
        .collect()
}

#[test]
fn the_emitter_writes_every_frame_line_once() {
    for k in Keyword::ALL {
        assert_eq!(
            emitted(k).len(),
            1,
            "{} lines in main.rs and receipt_log.rs",
            k.as_str()
        );
    }
}

#[test]
fn header_keys_match_the_definition_in_order() {
    let fields = &emitted(Keyword::Begin)[0];
    let keys: Vec<&str> = fields
        .iter()
        .map(|t| header_field(t).expect("FRAME_BEGIN field is key=value").0)
        .collect();
    assert_eq!(keys, HEADER_KEYS);
}

#[test]
fn bin_receipt_and_end_lines_have_the_defined_fields() {
    assert_eq!(emitted(Keyword::Bin)[0].len(), BIN_FIELDS.len());
    assert_eq!(emitted(Keyword::Receipt)[0].len(), RECEIPT_FIELDS.len());
    let end = &emitted(Keyword::End)[0];
    assert_eq!(end.len(), 1);
    assert!(end[0].starts_with(END_COUNT_PREFIX), "{end:?}");
}

#[test]
fn the_literal_reader_sees_a_changed_field_count() {
    // The checks above can fail: a FRAME line with one field fewer is seen as such.
    let src = r#"defmt::println!("FRAME {=usize} {=f32}", k, x);"#;
    let lits = println_literals(src);
    let line = instantiate(&lits[0]);
    let (k, rest) = split_line(&line).unwrap();
    assert_eq!((k, rest.count()), (Keyword::Bin, 2));
}
