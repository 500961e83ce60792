//! Bad input through the command line: every class gives exit code 3 (input data error) with a
//! message naming the file and, for text logs, the line; usage errors give 2. Nothing panics.
mod cli_support;
use cli_support::{ferrosid, s, scratch, Run};
use std::path::{Path, PathBuf};

fn good_rows(n: usize) -> String {
    rows_from(0, n)
}

/// Rows for samples `start..start + n` at 1 kHz.
fn rows_from(start: usize, n: usize) -> String {
    (start..start + n)
        .map(|k| {
            let u = (0.3 * k as f64).sin() + 0.2 * (1.7 * k as f64).cos();
            let y = 0.5 * u + 0.1 * (0.05 * k as f64).sin();
            format!("{},{u},{y}\n", k as f64 * 0.001)
        })
        .collect()
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).expect("write");
    p
}

/// Asserts exit 3, no panic, and that stderr names `file` (and `line` when given).
fn assert_data_error(r: &Run, file: &Path, line: Option<usize>, what: &str) {
    assert_eq!(r.code, 3, "exit code for {what}; stderr: {}", r.stderr);
    assert!(
        !r.stderr.contains("panicked"),
        "{what} panicked: {}",
        r.stderr
    );
    let name = s(file);
    assert!(
        r.stderr.contains(name),
        "{what}: error does not name {name}: {}",
        r.stderr
    );
    if let Some(l) = line {
        assert!(
            r.stderr.contains(&format!("{name}:{l}:")),
            "{what}: error does not name line {l}: {}",
            r.stderr
        );
    }
}

#[test]
fn malformed_csv_row_names_file_and_line() {
    let d = scratch("malformed");
    let mut text = format!("t,u,y\n{}", good_rows(50));
    text.push_str("0.05,1.0\n"); // line 52: two fields instead of three
    text.push_str(&rows_from(51, 60));
    let p = write(&d, "bad.csv", &text);
    for cmd in ["frf", "identify"] {
        let r = ferrosid(&[cmd, s(&p)]);
        assert_data_error(&r, &p, Some(52), &format!("{cmd} malformed row"));
        assert!(r.stderr.contains("fields"), "{}", r.stderr);
    }
}

#[test]
fn non_numeric_value_names_file_and_line() {
    let d = scratch("nonnumeric");
    let rows = good_rows(80);
    let mut lines: Vec<String> = rows.lines().map(str::to_string).collect();
    lines[9] = "0.009,0.3,abc".into(); // file line 11 (header is line 1)
    let p = write(&d, "text.csv", &format!("t,u,y\n{}\n", lines.join("\n")));
    let r = ferrosid(&["frf", s(&p)]);
    assert_data_error(&r, &p, Some(11), "non-numeric value");
}

#[test]
fn nan_and_inf_name_file_and_line() {
    let d = scratch("nan");
    for (bad, name) in [("NaN", "nan.csv"), ("inf", "inf.csv")] {
        let rows = good_rows(80);
        let mut lines: Vec<String> = rows.lines().map(str::to_string).collect();
        lines[20] = format!("0.02,{bad},0.1"); // file line 22
        let p = write(&d, name, &format!("t,u,y\n{}\n", lines.join("\n")));
        for cmd in ["frf", "identify"] {
            let r = ferrosid(&[cmd, s(&p)]);
            assert_data_error(&r, &p, Some(22), &format!("{cmd} {bad}"));
            assert!(r.stderr.contains("not finite"), "{}", r.stderr);
        }
    }
}

#[test]
fn non_monotonic_time_names_file_and_line() {
    let d = scratch("time");
    let rows = good_rows(80);
    let mut lines: Vec<String> = rows.lines().map(str::to_string).collect();
    // Sample 30 (file line 32) goes back in time.
    let parts: Vec<String> = lines[30].split(',').map(str::to_string).collect();
    lines[30] = format!("0.0285,{},{}", parts[1], parts[2]);
    let p = write(&d, "time.csv", &format!("t,u,y\n{}\n", lines.join("\n")));
    for cmd in ["frf", "identify"] {
        let r = ferrosid(&[cmd, s(&p)]);
        assert_data_error(&r, &p, Some(32), &format!("{cmd} non-monotonic time"));
        assert!(r.stderr.contains("increasing"), "{}", r.stderr);
    }
}

#[test]
fn non_uniform_time_names_file_and_line() {
    let d = scratch("jitter");
    let rows = good_rows(80);
    let mut lines: Vec<String> = rows.lines().map(str::to_string).collect();
    let parts: Vec<String> = lines[40].split(',').map(str::to_string).collect();
    lines[40] = format!("0.0402,{},{}", parts[1], parts[2]); // file line 42
    let p = write(&d, "jitter.csv", &format!("t,u,y\n{}\n", lines.join("\n")));
    let r = ferrosid(&["frf", s(&p)]);
    assert_data_error(&r, &p, Some(42), "non-uniform time");
}

#[test]
fn constant_input_is_rejected_by_name() {
    let d = scratch("const");
    let text: String = (0..200)
        .map(|k| format!("{},1.5,{}\n", k as f64 * 0.001, (0.1 * k as f64).sin()))
        .collect();
    let p = write(&d, "const.csv", &format!("t,u,y\n{text}"));
    for cmd in ["frf", "identify"] {
        let r = ferrosid(&[cmd, s(&p)]);
        assert_data_error(&r, &p, None, &format!("{cmd} constant input"));
        assert!(r.stderr.contains("constant"), "{}", r.stderr);
        assert!(r.stderr.contains("`u`"), "names the channel: {}", r.stderr);
    }
}

#[test]
fn too_short_logs_are_rejected_by_name() {
    let d = scratch("short");
    let p = write(&d, "short.csv", &format!("t,u,y\n{}", good_rows(30)));
    // Welch with an explicit segment longer than the log.
    let r = ferrosid(&["frf", s(&p), "--nperseg", "64"]);
    assert_data_error(&r, &p, None, "frf too short");
    assert!(r.stderr.contains("too few samples"), "{}", r.stderr);
    // N4SID with 20 block rows needs far more than 30 samples.
    let r = ferrosid(&["identify", s(&p)]);
    assert_data_error(&r, &p, None, "identify too short");
    // Period-synchronous averaging needs two periods.
    let r = ferrosid(&["frf", s(&p), "--period", "20"]);
    assert_data_error(&r, &p, None, "periodic too short");
}

#[test]
fn missing_column_names_header_line() {
    let d = scratch("column");
    let p = write(&d, "cols.csv", &format!("t,u,y\n{}", good_rows(100)));
    let r = ferrosid(&["frf", s(&p), "--output", "speed"]);
    assert_data_error(&r, &p, Some(1), "missing column");
    assert!(r.stderr.contains("speed"), "{}", r.stderr);
}

#[test]
fn missing_file_is_a_data_error() {
    let d = scratch("missing");
    let p = d.join("does_not_exist.csv");
    let r = ferrosid(&["frf", s(&p)]);
    assert_data_error(&r, &p, None, "missing file");
}

#[test]
fn mismatched_sample_rates_name_the_second_log() {
    let d = scratch("rates");
    let a = write(&d, "a.csv", &format!("t,u,y\n{}", good_rows(300)));
    let text: String = good_rows(300)
        .lines()
        .enumerate()
        .map(|(k, l)| {
            let rest = l.split_once(',').map(|x| x.1).unwrap_or("");
            format!("{},{rest}\n", k as f64 * 0.002)
        })
        .collect();
    let b = write(&d, "b.csv", &format!("t,u,y\n{text}"));
    let r = ferrosid(&["frf", s(&a), s(&b), "--nperseg", "64"]);
    assert_data_error(&r, &b, None, "mismatched rates");
    assert!(r.stderr.contains("sample rate"), "{}", r.stderr);
}

#[test]
fn mat_variable_errors_name_the_variable() {
    let fixture =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/io_small_v5_compressed.mat");
    // NaN at sample 18 of `y_nan`.
    let r = ferrosid(&[
        "frf",
        s(&fixture),
        "--input",
        "u",
        "--output",
        "y_nan",
        "--nperseg",
        "16",
    ]);
    assert_data_error(&r, &fixture, None, ".mat NaN");
    assert!(r.stderr.contains("y_nan"), "{}", r.stderr);
    // Unknown variable.
    let r = ferrosid(&["frf", s(&fixture), "--input", "u", "--output", "nope"]);
    assert_data_error(&r, &fixture, None, ".mat missing variable");
    assert!(r.stderr.contains("nope"), "{}", r.stderr);
}

#[test]
fn bad_option_values_are_usage_errors() {
    let d = scratch("usage");
    let p = write(&d, "ok.csv", &format!("t,u,y\n{}", good_rows(400)));
    for args in [
        vec!["frf", s(&p), "--gate", "1.5"],
        vec!["frf", s(&p), "--nperseg", "4"],
        vec!["frf", s(&p), "--nperseg", "lots"],
        vec!["identify", s(&p), "--order-range", "5..2"],
        vec!["identify", s(&p), "--stable-margin", "2"],
        vec!["identify", s(&p), "--crossover-hz", "-3"],
    ] {
        let r = ferrosid(&args);
        assert_eq!(r.code, 2, "{args:?}: {}", r.stderr);
        assert!(!r.stderr.contains("panicked"), "{}", r.stderr);
    }
    // clap's own usage errors.
    let r = ferrosid(&["frf"]);
    assert_eq!(r.code, 2);
    let r = ferrosid(&["identify", s(&p), "--order", "3", "--order-range", "2..4"]);
    assert_eq!(r.code, 2);
}
