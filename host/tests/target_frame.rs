//! Reading a target's spectra frame: the format of `firmware/app` (`powerup`), prefixes
//! tolerated, every malformed line named by file and line, and the gated H1 selection.
use ferrosid::target_frame::TargetFrame;
use ferrosid::Error;
use num_complex::Complex64;
use std::path::Path;

/// A frame for N = 64 at 1 kHz whose cross spectrum is S_uy = H(k)·S_uu with a known H, and a
/// receipt, with log-level prefixes on some lines like a decoder may add.
fn frame_text(h: impl Fn(usize) -> Complex64) -> String {
    let mut s = String::from("POWERUP sha256=abc states=2 fs=1000.0 n=64\n");
    s.push_str("RECEIPT 3 46.875 0.99 1.0 -0.5 1.01 -0.49 0.012 0.05 0.0036 PASS\n");
    s.push_str("RECEIPT 5 78.125 0.5 0.1 0.0 0.2 0.0 NaN NaN 0.35 SKIP\n");
    s.push_str(
        "INFO  FRAME_BEGIN fs=1000.0 n=64 averages=4 dropped=0 window=rectangular overlap=0 \
         detrend=mean excited_max_bin=20 gate=0.9\n",
    );
    for k in 0..=32 {
        let excited = (1..=20).contains(&k);
        let suu = if excited { 1e-3 } else { 1e-15 };
        let hk = h(k);
        let suy = hk * suu;
        let coh = if k == 7 {
            0.5
        } else if excited {
            0.999
        } else {
            0.2
        };
        let prefix = if k % 2 == 0 { "[INFO ] " } else { "" };
        s.push_str(&format!(
            "{prefix}FRAME {k} {suu:e} {} {} {} {coh}\n",
            hk.norm_sqr() * suu,
            suy.re,
            suy.im
        ));
    }
    s.push_str("FRAME_END bins=33\nSTACK 1000\nVERDICT FAIL checked=1/2 failed_hz=[46.875]\n");
    s
}

fn h_true(k: usize) -> Complex64 {
    Complex64::new(1.0, 0.0) / Complex64::new(1.0 - 0.01 * k as f64, 0.05 * k as f64)
}

#[test]
fn parses_the_frame_and_the_receipt() {
    let f = TargetFrame::parse(&frame_text(h_true), Path::new("t.log")).unwrap();
    assert_eq!(
        (f.fs_hz, f.n, f.averages, f.excited_max_bin),
        (1000.0, 64, Some(4), Some(20))
    );
    assert_eq!(f.gate, Some(0.9));
    assert_eq!(f.bins.len(), 33);
    assert_eq!(f.receipt.len(), 2);
    assert_eq!(f.receipt[0].verdict, "PASS");
    assert_eq!(f.receipt[0].sigma, 0.0036);
    assert!((f.receipt[0].g0 - Complex64::new(1.0, -0.5)).norm() == 0.0);
    assert!(f.receipt[1].rel_error.is_nan());
    assert_eq!(f.verdict.as_deref(), Some("FAIL"));
    assert_eq!(f.bin_hz(4), 62.5);

    // Gated H1: bins 1..=20 except 7 (coherence 0.5); not 0, not beyond the excitation.
    let p = f.gated_h1(0.9, 1e-6);
    let want: Vec<usize> = (1..=20).filter(|&k| k != 7).collect();
    assert_eq!(p.bins, want);
    for (k, h) in p.bins.iter().zip(&p.h) {
        // The frame carries the text rendering of f64 values: relative 1e-15.
        assert!((h - h_true(*k)).norm() <= 1e-12 * h.norm(), "bin {k}");
    }
}

fn parse_err(text: &str) -> Error {
    TargetFrame::parse(text, Path::new("bad.log")).unwrap_err()
}

fn assert_line(e: Error, line: usize, needle: &str) {
    match e {
        Error::Parse { file, line: l, msg } => {
            assert_eq!(file, Path::new("bad.log"));
            assert_eq!(l, line, "{msg}");
            assert!(msg.contains(needle), "{msg:?} lacks {needle:?}");
        }
        other => panic!("expected a parse error at line {line}, got {other:?}"),
    }
}

/// The good frame with line `line` (1-based) replaced by `with`.
fn with_line(line: usize, with: &str) -> String {
    let t = frame_text(h_true);
    let mut lines: Vec<String> = t.lines().map(str::to_string).collect();
    lines[line - 1] = with.to_string();
    lines.join("\n")
}

#[test]
fn malformed_lines_are_named() {
    // Line 4 is FRAME_BEGIN, lines 5..=37 the bins (bin k on line 5 + k), 38 FRAME_END.
    for (line, text, needle) in [
        (4, "FRAME_BEGIN fs=abc n=64", "fs"),
        (4, "FRAME_BEGIN fs=-1 n=64", "fs"),
        (4, "FRAME_BEGIN fs=1000 n=100", "n = 100"),
        (4, "FRAME_BEGIN fs=1000 n=64 oops", "key=value"),
        (4, "FRAME_BEGIN n=64", "missing fs"),
        (9, "FRAME 4 1e-3 1e-3 0.1", "6 fields"),
        (9, "FRAME 5 1e-3 1e-3 0.1 0.1 0.9", "out of order"),
        (9, "FRAME 4 1e-3 x 0.1 0.1 0.9", "S_yy"),
        (9, "FRAME 4 1e-3 inf 0.1 0.1 0.9", "not finite"),
        (9, "FRAME 4 -1e-3 1 0.1 0.1 0.9", "negative"),
        (9, "FRAME 4 1e-3 1 0.1 0.1 1.5", "coherence"),
        (38, "FRAME_END bins=40", "expected 33"),
        (2, "RECEIPT 3 46.875 0.99", "11 fields"),
        // A FRAME line before any FRAME_BEGIN.
        (1, "FRAME 0 1 1 0 0 1", "outside"),
    ] {
        assert_line(parse_err(&with_line(line, text)), line, needle);
    }
    // A second frame.
    let mut two = frame_text(h_true);
    two.push_str("FRAME_BEGIN fs=1000 n=64\n");
    assert_line(parse_err(&two), 41, "second FRAME_BEGIN");
    // Too few bins before FRAME_END.
    let t = frame_text(h_true);
    let short: Vec<&str> = t.lines().filter(|l| !l.contains("FRAME 32 ")).collect();
    assert_line(parse_err(&short.join("\n")), 37, "holds 32 bins");
}

#[test]
fn missing_or_truncated_frames_are_data_errors() {
    match parse_err("POWERUP x\nVERDICT PASS\n") {
        Error::Data { file, msg } => {
            assert_eq!(file, Path::new("bad.log"));
            assert!(msg.contains("no FRAME_BEGIN"), "{msg}");
        }
        other => panic!("{other:?}"),
    }
    let t = frame_text(h_true);
    let cut: String = t.lines().take(20).collect::<Vec<_>>().join("\n");
    match parse_err(&cut) {
        Error::Data { msg, .. } => assert!(msg.contains("truncated"), "{msg}"),
        other => panic!("{other:?}"),
    }
    match TargetFrame::read(Path::new("/nonexistent/target.log")) {
        Err(Error::Io { file, .. }) => assert_eq!(file, Path::new("/nonexistent/target.log")),
        other => panic!("{other:?}"),
    }
}
