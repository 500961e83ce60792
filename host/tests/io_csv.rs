//! CSV ingestion: happy paths and every bad-input case, each with the error's file/line.
use std::path::PathBuf;

use ferrosid::io::{read_csv, read_log, require_len, Checks, CsvOptions, LogSpec};
use ferrosid::Error;

/// Writes `content` to a fresh file in the cargo test temp dir.
fn file(name: &str, content: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("io_csv");
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join(name);
    std::fs::write(&p, content).unwrap();
    p
}

fn parse_line(e: Error) -> (usize, String) {
    match e {
        Error::Parse { line, msg, .. } => (line, msg),
        other => panic!("expected a Parse error, got {other:?}"),
    }
}

fn good_csv(n: usize) -> String {
    let mut s = String::from("# bench log\n# second comment\nt,u,y,extra\n");
    for k in 0..n {
        let t = k as f64 * 0.001;
        s += &format!(
            "{t},{},{},foo\n",
            (0.3 * k as f64).sin(),
            (0.2 * k as f64).cos()
        );
    }
    s
}

#[test]
fn reads_default_columns_with_comments_and_time() {
    let p = file("good.csv", &good_csv(50));
    let log = read_csv(&p, &CsvOptions::default()).unwrap();
    assert_eq!(log.len(), 50);
    assert!((log.ts - 0.001).abs() < 1e-15);
    assert_eq!(log.inputs[0].name, "u");
    assert_eq!(log.outputs[0].name, "y");
    assert_eq!(log.u()[7], (0.3f64 * 7.0).sin());
    assert_eq!(log.y()[49], (0.2f64 * 49.0).cos());
    assert!(log.warnings.is_empty(), "{:?}", log.warnings);
    assert_eq!(log.path, p);
}

#[test]
fn selects_other_columns_delimiters_and_fs() {
    let p = file(
        "multi.csv",
        "a; b ; c;d\n1;2;3;4\n2;4;1;0\n3;1;5;2\n1;9;9;9\n",
    );
    let log = read_csv(
        &p,
        &CsvOptions {
            inputs: vec!["a".into(), "b".into()],
            outputs: vec!["d".into(), "c".into()],
            fs: Some(100.0),
            ..CsvOptions::default()
        },
    )
    .unwrap();
    assert_eq!(log.inputs.len(), 2);
    assert_eq!(log.outputs[1].name, "c");
    assert_eq!(log.outputs[1].data, vec![3.0, 1.0, 5.0, 9.0]);
    assert_eq!(log.inputs[1].data, vec![2.0, 4.0, 1.0, 9.0]);
    assert!((log.fs() - 100.0).abs() < 1e-12);

    // read_log dispatches on the extension with the same semantics.
    let log2 = read_log(
        &p,
        &LogSpec {
            inputs: vec!["a".into(), "b".into()],
            outputs: vec!["d".into(), "c".into()],
            fs: Some(100.0),
            ..LogSpec::default()
        },
    )
    .unwrap();
    assert_eq!(log, log2);
}

#[test]
fn time_in_other_units_and_consistency_with_fs() {
    let mut s = String::from("time_us,u,y\n");
    for k in 0..20 {
        s += &format!("{},{},{}\n", 400 * k, k % 3, k * k);
    }
    let p = file("us.csv", &s);
    let opts = CsvOptions {
        time: Some("time_us".into()),
        time_scale: 1e-6,
        fs: Some(2500.0),
        ..CsvOptions::default()
    };
    let log = read_csv(&p, &opts).unwrap();
    assert!((log.ts - 400e-6).abs() < 1e-18);
    // Disagreeing fs: an error that names both.
    let e = read_csv(
        &p,
        &CsvOptions {
            fs: Some(1000.0),
            ..opts
        },
    )
    .unwrap_err();
    let msg = e.to_string();
    assert!(msg.contains("2500") && msg.contains("1000"), "{msg}");
}

#[test]
fn no_time_column_needs_fs() {
    let p = file("notime.csv", "u,y\n1,2\n2,3\n3,5\n");
    let (line, msg) = parse_line(read_csv(&p, &CsvOptions::default()).unwrap_err());
    assert_eq!(line, 1);
    assert!(msg.contains("sample rate"), "{msg}");
    let log = read_csv(
        &p,
        &CsvOptions {
            fs: Some(8.0),
            ..CsvOptions::default()
        },
    )
    .unwrap();
    assert_eq!(log.ts, 0.125);
}

#[test]
fn wrong_field_count_names_line() {
    let p = file("fields.csv", "# c\nt,u,y\n0,1,2\n0.1,2\n0.2,3,4\n");
    let (line, msg) = parse_line(read_csv(&p, &CsvOptions::default()).unwrap_err());
    assert_eq!(line, 4);
    assert!(msg.contains("expected 3 fields"), "{msg}");
}

#[test]
fn non_numeric_names_line_and_column() {
    let p = file("text.csv", "t,u,y\n0,1,2\n0.1,2,3\n0.2,x3,4\n");
    let (line, msg) = parse_line(read_csv(&p, &CsvOptions::default()).unwrap_err());
    assert_eq!(line, 4);
    assert!(msg.contains("`u`") && msg.contains("x3"), "{msg}");
}

#[test]
fn nan_and_inf_name_line_and_column() {
    for (bad, name) in [("NaN", "nan"), ("inf", "inf"), ("-Infinity", "minf")] {
        let p = file(
            &format!("{name}.csv"),
            &format!("t,u,y\n0,1,2\n0.1,2,3\n0.2,3,4\n0.3,4,{bad}\n"),
        );
        let (line, msg) = parse_line(read_csv(&p, &CsvOptions::default()).unwrap_err());
        assert_eq!(line, 5, "{bad}");
        assert!(msg.contains("`y`") && msg.contains("not finite"), "{msg}");
    }
}

#[test]
fn non_monotonic_time_names_line() {
    let p = file("back.csv", "t,u,y\n0,1,2\n0.1,2,3\n0.1,3,4\n0.3,4,5\n");
    let (line, msg) = parse_line(read_csv(&p, &CsvOptions::default()).unwrap_err());
    assert_eq!(line, 4);
    assert!(msg.contains("not strictly increasing"), "{msg}");
}

#[test]
fn time_stamps_printed_to_nine_digits_late_in_a_long_log_are_read_on_their_grid() {
    // 10 kHz from t = 1000 s, stamps printed with 9 significant digits (%.8e): the last digit
    // is 1e-5 s, so intervals jitter by up to 1e-1 of the 1e-4 s interval — far beyond the
    // interval rule's 1e-3, yet every stamp is within its printed rounding of the grid.
    let rows = |shift: Option<(usize, f64)>, drop: Option<usize>| -> String {
        let mut text = String::from("t,u,y\n");
        for k in 0..400usize {
            if Some(k) == drop {
                continue;
            }
            let mut t = 1000.0 + k as f64 * 1e-4;
            if let Some((ks, dt)) = shift {
                if k == ks {
                    t += dt;
                }
            }
            let u = (0.37 * k as f64).sin();
            text.push_str(&format!("{t:.8e},{u},{}\n", 0.5 * u));
        }
        text
    };
    let p = file("late_nine_digits.csv", &rows(None, None));
    let log = read_csv(&p, &CsvOptions::default()).unwrap();
    assert!((log.ts - 1e-4).abs() <= 1e-4 * 1e-6, "ts = {}", log.ts);
    // A dropped sample (file line 202) is refused: a grid residual of half an interval.
    let p = file("late_dropped.csv", &rows(None, Some(200)));
    let (line, msg) = parse_line(read_csv(&p, &CsvOptions::default()).unwrap_err());
    assert!(msg.contains("non-uniform"), "{msg}");
    assert!((201..=203).contains(&line), "line {line}: {msg}");
    // A stamp shifted by 3e-5 s (3 units in its last digit, 0.3 interval) is refused too.
    let p = file("late_shifted.csv", &rows(Some((150, 3e-5)), None));
    let (line, msg) = parse_line(read_csv(&p, &CsvOptions::default()).unwrap_err());
    assert!(msg.contains("non-uniform"), "{msg}");
    assert!((151..=153).contains(&line), "line {line}: {msg}");
}

#[test]
fn non_uniform_time_names_line_and_tolerance_is_adjustable() {
    // 1e-2 relative jitter on the interval into line 5: beyond the default 1e-3, and beyond
    // the rounding of stamps printed to 5 significant digits. (Printed as `3.01` among `0, 1,
    // 2, 4` it would be within the rounding of a 3-digit column and accepted on its grid.)
    let p = file(
        "jitter.csv",
        "t,u,y\n0.0000,1,2\n1.0000,2,3\n2.0000,3,4\n3.0100,4,5\n4.0000,5,6\n",
    );
    let (line, msg) = parse_line(read_csv(&p, &CsvOptions::default()).unwrap_err());
    assert_eq!(line, 5);
    assert!(msg.contains("non-uniform"), "{msg}");
    // The message names both options that fix the file.
    assert!(
        msg.contains("--time-jitter") && msg.contains("--fs"),
        "{msg}"
    );
    // A looser, explicit tolerance accepts it.
    let log = read_csv(
        &p,
        &CsvOptions {
            checks: Checks {
                time_jitter_rel: 2e-2,
                ..Checks::default()
            },
            ..CsvOptions::default()
        },
    )
    .unwrap();
    assert_eq!(log.len(), 5);
    // Jitter below the tolerance (1e-8 relative) is accepted by default.
    let p = file(
        "small_jitter.csv",
        "t,u,y\n0,1,2\n1,2,3\n2.00000001,3,4\n3,4,5\n",
    );
    assert!(read_csv(&p, &CsvOptions::default()).is_ok());
    // Rounding of real time vectors (2.4e-4 of the interval, issue 10) is accepted by default,
    // and the sample time is the mean interval, not a rounded one.
    let p = file(
        "rounded.csv",
        "t,u,y\n0,1,2\n0.001,2,3\n0.00200024,3,4\n0.003,4,5\n0.004,5,6\n",
    );
    let log = read_csv(&p, &CsvOptions::default()).unwrap();
    assert!((log.ts - 0.001).abs() < 1e-15, "{}", log.ts);
}

#[test]
fn empty_file_header_only_and_missing_column() {
    let p = file("empty.csv", "");
    let e = read_csv(&p, &CsvOptions::default()).unwrap_err();
    assert!(matches!(e, Error::Data { .. }), "{e:?}");
    assert!(e.to_string().contains("empty"), "{e}");

    let p = file("comments_only.csv", "# nothing\n\n# here\n");
    let e = read_csv(&p, &CsvOptions::default()).unwrap_err();
    assert!(e.to_string().contains("empty"), "{e}");

    let p = file("header_only.csv", "# c\nt,u,y\n");
    let e = read_csv(&p, &CsvOptions::default()).unwrap_err();
    assert!(matches!(e, Error::Data { .. }), "{e:?}");
    assert!(e.to_string().contains("no data rows"), "{e}");

    let p = file("missing.csv", "# c\nt,u,x\n0,1,2\n");
    let (line, msg) = parse_line(read_csv(&p, &CsvOptions::default()).unwrap_err());
    assert_eq!(line, 2);
    assert!(
        msg.contains("`y` not found") && msg.contains("t, u, x"),
        "{msg}"
    );

    let p = file("dup.csv", "t,u,y,y\n0,1,2,3\n");
    let (_, msg) = parse_line(read_csv(&p, &CsvOptions::default()).unwrap_err());
    assert!(msg.contains("2 times"), "{msg}");
}

#[test]
fn constant_input_is_an_error() {
    let p = file("const.csv", "t,u,y\n0,1,2\n1,1,3\n2,1,1\n");
    let e = read_csv(&p, &CsvOptions::default()).unwrap_err();
    assert!(matches!(e, Error::Data { .. }), "{e:?}");
    let msg = e.to_string();
    assert!(
        msg.contains("const.csv") && msg.contains("`u` is constant"),
        "{msg}"
    );
}

#[test]
fn too_few_samples() {
    let p = file("one.csv", "t,u,y\n0,1,2\n");
    let e = read_csv(
        &p,
        &CsvOptions {
            fs: Some(1.0),
            ..CsvOptions::default()
        },
    )
    .unwrap_err();
    assert!(e.to_string().contains("too few samples"), "{e}");

    let p = file("short.csv", &good_csv(50));
    let log = read_csv(&p, &CsvOptions::default()).unwrap();
    let e = require_len(&log, 256, "Welch with nperseg = 256").unwrap_err();
    let msg = e.to_string();
    assert!(
        msg.contains("short.csv") && msg.contains("256") && msg.contains("50"),
        "{msg}"
    );
    assert!(require_len(&log, 50, "x").is_ok());
}

#[test]
fn clipped_output_is_a_warning_not_an_error() {
    let mut s = String::from("t,u,y\n");
    for k in 0..200 {
        let u = (0.05 * k as f64).sin() * 2.0;
        let y = u.clamp(-1.5, 1.5);
        s += &format!("{k},{u},{y}\n");
    }
    let p = file("clip.csv", &s);
    let log = read_csv(&p, &CsvOptions::default()).unwrap();
    assert_eq!(log.warnings.len(), 1, "{:?}", log.warnings);
    let w = &log.warnings[0];
    assert!(w.contains("`y`") && w.contains("clipped"), "{w}");
    assert!(
        w.contains("maximum 1.5") && w.contains("minimum -1.5"),
        "{w}"
    );

    // The same signal unclipped: no warning. A run of 3 at the maximum stays below the rule.
    let mut s = String::from("t,u,y\n");
    for k in 0..200 {
        let u = (0.05 * k as f64).sin() * 2.0;
        let y = if (50..53).contains(&k) { 5.0 } else { u };
        s += &format!("{k},{u},{y}\n");
    }
    let p = file("noclip.csv", &s);
    let log = read_csv(&p, &CsvOptions::default()).unwrap();
    assert!(log.warnings.is_empty(), "{:?}", log.warnings);
}

#[test]
fn constant_output_is_a_warning() {
    let p = file("consty.csv", "t,u,y\n0,1,2\n1,2,2\n2,3,2\n");
    let log = read_csv(&p, &CsvOptions::default()).unwrap();
    assert_eq!(log.warnings.len(), 1);
    assert!(log.warnings[0].contains("constant"));
}

#[test]
fn missing_file_is_io_error() {
    let p = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("does/not/exist.csv");
    let e = read_csv(&p, &CsvOptions::default()).unwrap_err();
    assert!(matches!(e, Error::Io { .. }), "{e:?}");
    assert!(e.to_string().contains("exist.csv"));
}

#[test]
fn invalid_utf8_is_a_parse_error() {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("io_csv");
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join("latin1.csv");
    std::fs::write(&p, b"t,u,y\n0,1,2\n1,\xe92,3\n").unwrap();
    let e = read_csv(&p, &CsvOptions::default()).unwrap_err();
    assert!(matches!(e, Error::Parse { line: 3, .. }), "{e:?}");
}

#[test]
fn unknown_extension_is_rejected() {
    let p = file("log.xlsx", "whatever");
    let e = read_log(&p, &LogSpec::default()).unwrap_err();
    assert!(e.to_string().contains(".xlsx"), "{e}");
}

#[test]
fn line_numbers_count_blank_and_comment_lines() {
    let p = file(
        "blank.csv",
        "# a\n# b, c\n\n  \nt,u,y\n\n0,1,2\n# mid\n1,2,3\r\n\n\n2,3\n",
    );
    let (line, msg) = parse_line(read_csv(&p, &CsvOptions::default()).unwrap_err());
    assert_eq!(line, 12, "{msg}");
    let p = file("blank2.csv", "\n# a\n\nt,u,x\n0,1,2\n");
    let (line, _) = parse_line(read_csv(&p, &CsvOptions::default()).unwrap_err());
    assert_eq!(line, 4);
}
