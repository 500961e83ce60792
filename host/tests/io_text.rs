//! Headerless whitespace-separated text (DaISy .dat) ingestion and its bad-input cases.
use std::path::PathBuf;

use ferrosid::io::{read_columns, read_log, LogSpec, TextOptions};
use ferrosid::Error;

fn file(name: &str, content: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("io_text");
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join(name);
    std::fs::write(&p, content).unwrap();
    p
}

fn opts(fs: f64) -> TextOptions {
    TextOptions {
        fs: Some(fs),
        ..TextOptions::default()
    }
}

#[test]
fn reads_columns_tabs_spaces_comments() {
    let p = file(
        "ok.dat",
        "% daisy-like\n   2.2e-01\t  -1.7e-01\t\n  3.9e-02\t-1.1e-01\n\n# c\n-5.0e-02   -1.7e-02\n",
    );
    let log = read_columns(&p, &opts(10.0)).unwrap();
    assert_eq!(log.u(), &[0.22, 0.039, -0.05]);
    assert_eq!(log.y(), &[-0.17, -0.11, -0.017]);
    assert_eq!(log.inputs[0].name, "col1");
    assert!((log.ts - 0.1).abs() < 1e-16);
}

#[test]
fn mimo_column_selection_and_read_log() {
    let p = file("mimo.dat", "1 2 3 4\n2 1 4 3\n3 5 1 2\n4 0 0 1\n");
    let o = TextOptions {
        input_cols: vec![1, 2],
        output_cols: vec![4, 3],
        fs: Some(1.0),
        ..TextOptions::default()
    };
    let log = read_columns(&p, &o).unwrap();
    assert_eq!(log.inputs[1].data, vec![2.0, 1.0, 5.0, 0.0]);
    assert_eq!(log.outputs[0].data, vec![4.0, 3.0, 2.0, 1.0]);
    assert_eq!(log.outputs[1].name, "col3");
    let log2 = read_log(
        &p,
        &LogSpec {
            inputs: vec!["1".into(), "2".into()],
            outputs: vec!["4".into(), "3".into()],
            fs: Some(1.0),
            ..LogSpec::default()
        },
    )
    .unwrap();
    assert_eq!(log, log2);
    // Column names that are not numbers are rejected for text logs.
    let e = read_log(
        &p,
        &LogSpec {
            inputs: vec!["u".into()],
            fs: Some(1.0),
            ..LogSpec::default()
        },
    )
    .unwrap_err();
    assert!(matches!(e, Error::InvalidArgument(_)), "{e:?}");
}

#[test]
fn bad_inputs_name_the_line() {
    let cases = [
        ("fields.dat", "1 2\n3 4\n5\n6 7\n", 3, "expected 2 fields"),
        ("nonnum.dat", "1 2\n3 4\n5 a6\n", 3, "not a number"),
        ("nan.dat", "1 2\n3 4\n5 6\nNaN 8\n", 4, "not finite"),
        ("inf.dat", "1 2\n3 inf\n", 2, "not finite"),
        ("cols.dat", "# c\n1\n", 2, "column 2 requested"),
    ];
    for (name, content, line_expected, what) in cases {
        let p = file(name, content);
        match read_columns(&p, &opts(1.0)).unwrap_err() {
            Error::Parse { line, msg, file } => {
                assert_eq!(line, line_expected, "{name}: {msg}");
                assert!(msg.contains(what), "{name}: {msg}");
                assert!(file.ends_with(name));
            }
            other => panic!("{name}: expected Parse, got {other:?}"),
        }
    }
}

#[test]
fn empty_constant_and_missing_fs() {
    let p = file("empty.dat", "% only comments\n\n");
    let e = read_columns(&p, &opts(1.0)).unwrap_err();
    assert!(
        matches!(e, Error::Data { .. }) && e.to_string().contains("no data"),
        "{e}"
    );

    let p = file("const.dat", "1 2\n1 3\n1 4\n");
    let e = read_columns(&p, &opts(1.0)).unwrap_err();
    assert!(e.to_string().contains("constant"), "{e}");

    let p = file("nofs.dat", "1 2\n2 3\n");
    let e = read_columns(&p, &TextOptions::default()).unwrap_err();
    assert!(matches!(e, Error::InvalidArgument(_)), "{e:?}");
    for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        assert!(read_columns(&p, &opts(bad)).is_err());
    }
    let e = read_columns(
        &p,
        &TextOptions {
            input_cols: vec![0],
            ..opts(1.0)
        },
    )
    .unwrap_err();
    assert!(matches!(e, Error::InvalidArgument(_)), "{e:?}");
}
