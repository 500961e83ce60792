//! MATLAB v5 ingestion. References: files written by scipy.io.savemat (script and scipy version in
//! tests/ref/make_mat_fixtures.py, values recomputed here in closed form), files assembled byte by
//! byte by an independent writer in this test from the published MAT-file Level 5 layout
//! (both byte orders, compressed and plain, small data elements, opaque class objects), and the
//! real motor-bench logs (values cross-checked with scipy.io.loadmat, skipped when absent).
use std::io::Write;
use std::path::{Path, PathBuf};

use ferrosid::io::{read_log, read_mat, LogSpec, MatFile, MatOptions};
use ferrosid::Error;

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

fn u_ref(k: usize) -> f64 {
    let k = k as f64;
    (0.1 * k).sin() + 0.5 * (0.37 * k).cos()
}

fn var_err(e: Error) -> (String, String) {
    match e {
        Error::MatVar { var, msg, .. } => (var, msg),
        other => panic!("expected MatVar, got {other:?}"),
    }
}

#[test]
fn scipy_written_files_read_back_exactly() {
    for f in ["io_small_v5_compressed.mat", "io_small_v5_plain.mat"] {
        let mf = MatFile::open(&fixture(f)).unwrap();
        let names: Vec<&str> = mf.variables().iter().map(|v| v.name.as_str()).collect();
        for n in ["u", "y", "ys", "t", "fs", "mat2", "z"] {
            assert!(names.contains(&n), "{f}: {n} missing from {names:?}");
        }
        let skipped: Vec<&str> = mf.skipped().iter().map(|s| s.name.as_str()).collect();
        for n in ["name", "st", "ce"] {
            assert!(skipped.contains(&n), "{f}: {n} not skipped: {skipped:?}");
        }
        let u = mf.vector("u").unwrap();
        assert_eq!(u.len(), 100);
        for (k, v) in u.iter().enumerate() {
            assert!((v - u_ref(k)).abs() < 1e-15, "{f} u[{k}]");
        }
        let y = mf.vector("y").unwrap();
        for (k, v) in y.iter().enumerate() {
            assert_eq!(*v, (1000.0 * (0.05 * k as f64).sin()).round(), "{f} y[{k}]");
        }
        let ys = mf.vector("ys").unwrap();
        for (k, v) in ys.iter().enumerate() {
            assert_eq!(*v, (0.25 * k as f64 - 3.0) as f32 as f64);
        }
        assert_eq!(mf.scalar("fs").unwrap(), 1000.0);
        let (dims, m) = mf.array("mat2").unwrap();
        assert_eq!(dims, vec![3, 4]);
        // Column-major: element (r, c) of arange(12).reshape(3, 4) is 4r + c.
        assert_eq!(m[1], 4.0);
        assert_eq!(m[3], 1.0);
        let info = mf.variables().iter().find(|v| v.name == "y").unwrap();
        assert_eq!(info.class, "int16");
        assert_eq!(info.dims, vec![100, 1]);

        // A log: fs from the scalar `fs` variable, or from the time variable.
        let opts = MatOptions {
            inputs: vec!["u".into()],
            outputs: vec!["y".into(), "ys".into()],
            ..MatOptions::default()
        };
        let log = read_mat(&fixture(f), &opts).unwrap();
        assert_eq!(log.ts, 1e-3);
        assert_eq!(log.outputs.len(), 2);
        let log_t = read_mat(
            &fixture(f),
            &MatOptions {
                time: Some("t".into()),
                fs: Some(1000.0),
                ..opts.clone()
            },
        )
        .unwrap();
        assert!((log_t.ts - 1e-3).abs() < 1e-15);
        let via_spec = read_log(
            &fixture(f),
            &LogSpec {
                inputs: vec!["u".into()],
                outputs: vec!["y".into(), "ys".into()],
                ..LogSpec::default()
            },
        )
        .unwrap();
        assert_eq!(via_spec, log);
    }
}

#[test]
fn bad_variables_are_named() {
    let p = fixture("io_small_v5_compressed.mat");
    let base = MatOptions {
        inputs: vec!["u".into()],
        outputs: vec!["y".into()],
        ..MatOptions::default()
    };
    let with = |inputs: &[&str], outputs: &[&str]| MatOptions {
        inputs: inputs.iter().map(|s| s.to_string()).collect(),
        outputs: outputs.iter().map(|s| s.to_string()).collect(),
        ..base.clone()
    };
    // Missing: the message lists what exists.
    let (var, msg) = var_err(read_mat(&p, &with(&["u"], &["nope"])).unwrap_err());
    assert_eq!(var, "nope");
    assert!(msg.contains("not found") && msg.contains("u, "), "{msg}");
    // Skipped char / struct / cell variables.
    for (v, what) in [("name", "char"), ("st", "struct"), ("ce", "cell")] {
        let (var, msg) = var_err(read_mat(&p, &with(&["u"], &[v])).unwrap_err());
        assert_eq!(var, v);
        assert!(msg.contains(what), "{msg}");
    }
    // Complex, matrix, NaN.
    let (_, msg) = var_err(read_mat(&p, &with(&["u"], &["z"])).unwrap_err());
    assert!(msg.contains("complex"), "{msg}");
    let (_, msg) = var_err(read_mat(&p, &with(&["u"], &["mat2"])).unwrap_err());
    assert!(msg.contains("3×4") && msg.contains("vector"), "{msg}");
    let (var, msg) = var_err(read_mat(&p, &with(&["u"], &["y_nan"])).unwrap_err());
    assert_eq!(var, "y_nan");
    assert!(msg.contains("sample 18") && msg.contains("NaN"), "{msg}");
    // Mismatched lengths name both variables and lengths.
    let e = read_mat(&p, &with(&["u"], &["y_short"])).unwrap_err();
    assert!(matches!(e, Error::Data { .. }));
    let msg = e.to_string();
    assert!(
        msg.contains("`u` 100") && msg.contains("`y_short` 99"),
        "{msg}"
    );
    // Constant input.
    let e = read_mat(&p, &with(&["u_const"], &["y"])).unwrap_err();
    assert!(e.to_string().contains("`u_const` is constant"), "{e}");
    // Non-monotonic time variable: variable and sample named.
    let (var, msg) = var_err(
        read_mat(
            &p,
            &MatOptions {
                time: Some("t_back".into()),
                ..base.clone()
            },
        )
        .unwrap_err(),
    );
    assert_eq!(var, "t_back");
    assert!(
        msg.contains("sample 51") && msg.contains("not strictly increasing"),
        "{msg}"
    );
    // Time variable disagreeing with an explicit fs.
    let e = read_mat(
        &p,
        &MatOptions {
            time: Some("t".into()),
            fs: Some(2000.0),
            ..base.clone()
        },
    )
    .unwrap_err();
    assert!(e.to_string().contains("2000"), "{e}");
    // A non-scalar sample-rate variable.
    let (var, msg) = var_err(
        read_mat(
            &p,
            &MatOptions {
                fs_var: Some("u".into()),
                ..base.clone()
            },
        )
        .unwrap_err(),
    );
    assert_eq!(var, "u");
    assert!(msg.contains("scalar"), "{msg}");
    // No input named.
    assert!(matches!(
        read_mat(&p, &with(&[], &["y"])).unwrap_err(),
        Error::InvalidArgument(_)
    ));
}

// ---- An independent MAT v5 writer (MAT-File Format, Level 5, as published by MathWorks) ----

struct W {
    big: bool,
}

impl W {
    fn u32(&self, v: u32) -> [u8; 4] {
        if self.big {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        }
    }
    /// A data element; `small` uses the 8-byte compressed-tag form for payloads <= 4 bytes.
    fn elem(&self, ty: u32, payload: &[u8], small: bool) -> Vec<u8> {
        let mut out = Vec::new();
        if small && payload.len() <= 4 {
            out.extend(self.u32(((payload.len() as u32) << 16) | ty));
            let mut p = payload.to_vec();
            p.resize(4, 0);
            out.extend(p);
            return out;
        }
        out.extend(self.u32(ty));
        out.extend(self.u32(payload.len() as u32));
        out.extend(payload);
        while out.len() % 8 != 0 {
            out.push(0);
        }
        out
    }
    fn flags(&self, class: u32) -> Vec<u8> {
        let mut p = self.u32(class).to_vec();
        p.extend(self.u32(0));
        self.elem(6, &p, false)
    }
    /// miMATRIX payload of a numeric array stored with data type `ty` and raw `data` bytes.
    fn matrix(&self, class: u32, dims: &[i32], name: &str, ty: u32, data: &[u8]) -> Vec<u8> {
        let mut p = self.flags(class);
        let d: Vec<u8> = dims.iter().flat_map(|&x| self.u32(x as u32)).collect();
        p.extend(self.elem(5, &d, false));
        p.extend(self.elem(1, name.as_bytes(), true));
        p.extend(self.elem(ty, data, true));
        p
    }
    fn f64s(&self, v: &[f64]) -> Vec<u8> {
        v.iter()
            .flat_map(|x| {
                if self.big {
                    x.to_be_bytes()
                } else {
                    x.to_le_bytes()
                }
            })
            .collect()
    }
    fn top(&self, payload: &[u8], compress: bool) -> Vec<u8> {
        let plain = self.elem(14, payload, false);
        if !compress {
            return plain;
        }
        let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
        z.write_all(&plain).unwrap();
        let z = z.finish().unwrap();
        let mut out = self.u32(15).to_vec();
        out.extend(self.u32(z.len() as u32));
        out.extend(z);
        out
    }
    fn header(&self) -> Vec<u8> {
        let mut h = b"MATLAB 5.0 MAT-file, written by the ferrosid io_mat test".to_vec();
        h.resize(116, b' ');
        h.extend([0u8; 8]);
        if self.big {
            h.extend(0x0100u16.to_be_bytes());
            h.extend(*b"MI");
        } else {
            h.extend(0x0100u16.to_le_bytes());
            h.extend(*b"IM");
        }
        h
    }
}

/// A file shaped like the motor-bench logs: an opaque MCOS object first, then numeric data in
/// mixed storage types, a function handle, and an unnamed trailing uint8 block.
fn synthetic(big: bool, compress: bool) -> (Vec<u8>, Vec<f64>, Vec<f64>) {
    let w = W { big };
    let n: usize = 40;
    let u: Vec<f64> = (0..n).map(|k| (0.3 * k as f64).sin()).collect();
    let y: Vec<f64> = (0..n).map(|k| (k as f32 * 0.5 - 1.0) as f64).collect();
    let mut f = w.header();
    // mxOPAQUE (class 17) object `BA` of class `tf`, as MATLAB writes MCOS objects.
    let mut op = w.flags(17);
    op.extend(w.elem(1, b"BA", true));
    op.extend(w.elem(1, b"MCOS", true));
    op.extend(w.elem(1, b"tf", true));
    op.extend(w.elem(14, &w.matrix(13, &[6, 1], "", 6, &[7u8; 24]), false));
    f.extend(w.top(&op, compress));
    // Double vector u stored as miDOUBLE.
    f.extend(w.top(&w.matrix(6, &[n as i32, 1], "u", 9, &w.f64s(&u)), compress));
    // Double y stored as miSINGLE (row vector).
    let ys: Vec<u8> = y
        .iter()
        .flat_map(|&v| {
            if big {
                (v as f32).to_be_bytes()
            } else {
                (v as f32).to_le_bytes()
            }
        })
        .collect();
    f.extend(w.top(&w.matrix(6, &[1, n as i32], "y", 7, &ys), compress));
    // Scalar fs = 2500 stored as a small miUINT16 element, like MATLAB does.
    let fsb = if big {
        2500u16.to_be_bytes()
    } else {
        2500u16.to_le_bytes()
    };
    f.extend(w.top(&w.matrix(6, &[1, 1], "fs", 4, &fsb), compress));
    // Time in microseconds stored as miINT32.
    let tb: Vec<u8> = (0..n).flat_map(|k| w.u32(400 * k as u32)).collect();
    f.extend(w.top(&w.matrix(6, &[n as i32, 1], "time", 5, &tb), compress));
    // Function handle (class 16): skipped.
    let mut fh = w.flags(16);
    fh.extend(w.elem(5, &[w.u32(1), w.u32(1)].concat(), false));
    fh.extend(w.elem(1, b"cb", true));
    f.extend(w.top(&fh, compress));
    // Unnamed uint8 block (MATLAB's function workspace), plain as MATLAB writes it.
    f.extend(w.top(&w.matrix(9, &[1, 16], "", 2, &[1u8; 16]), false));
    (f, u, y)
}

fn write_tmp(name: &str, bytes: &[u8]) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("io_mat");
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

#[test]
fn hand_built_files_both_byte_orders_compressed_and_plain() {
    for big in [false, true] {
        for compress in [false, true] {
            let (bytes, u, y) = synthetic(big, compress);
            let p = write_tmp(&format!("synthetic_{big}_{compress}.mat"), &bytes);
            let mf = MatFile::open(&p).unwrap();
            let names: Vec<&str> = mf.variables().iter().map(|v| v.name.as_str()).collect();
            assert_eq!(
                names,
                vec!["u", "y", "fs", "time"],
                "big={big} z={compress}"
            );
            let sk: Vec<(&str, &str)> = mf
                .skipped()
                .iter()
                .map(|s| (s.name.as_str(), s.reason.as_str()))
                .collect();
            assert_eq!(sk.len(), 3, "{sk:?}");
            assert_eq!(sk[0].0, "BA");
            assert!(
                sk[0].1.contains("class object") && sk[0].1.contains("`tf`"),
                "{sk:?}"
            );
            assert!(sk[1].1.contains("function handle"), "{sk:?}");
            assert_eq!(sk[2].0, "");
            let opts = MatOptions {
                inputs: vec!["u".into()],
                outputs: vec!["y".into()],
                ..MatOptions::default()
            };
            let log = read_mat(&p, &opts).unwrap();
            assert_eq!(log.u(), &u[..]);
            assert_eq!(log.y(), &y[..]);
            assert_eq!(log.fs(), 2500.0);
            let log_t = read_mat(
                &p,
                &MatOptions {
                    time: Some("time".into()),
                    time_scale: 1e-6,
                    ..opts.clone()
                },
            )
            .unwrap();
            assert!((log_t.ts - 4e-4).abs() < 1e-18);
            // The object itself cannot be read as data, with a clear reason.
            let (var, msg) = var_err(mf.vector("BA").unwrap_err());
            assert_eq!(var, "BA");
            assert!(msg.contains("class object"), "{msg}");
        }
    }
}

#[test]
fn corrupt_and_foreign_files_are_clear_errors() {
    let (bytes, _, _) = synthetic(false, true);
    // Truncated in the middle of an element.
    let p = write_tmp("truncated.mat", &bytes[..bytes.len() - 30]);
    let e = MatFile::open(&p).unwrap_err();
    assert!(matches!(e, Error::Data { .. }), "{e:?}");
    assert!(e.to_string().contains("truncated"), "{e}");
    // Corrupt zlib stream of the first element (bytes 136.. are its compressed payload).
    let mut bad = bytes.clone();
    for b in &mut bad[136..150] {
        *b ^= 0x5a;
    }
    let p = write_tmp("badzlib.mat", &bad);
    let e = MatFile::open(&p).unwrap_err();
    assert!(e.to_string().contains("byte 128"), "{e}");
    // v7.3 (HDF5).
    let mut h = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, HDF5 schema 1.00 .".to_vec();
    h.resize(600, 0);
    let p = write_tmp("v73.mat", &h);
    let e = MatFile::open(&p).unwrap_err();
    assert!(e.to_string().contains("HDF5"), "{e}");
    // Not a MAT file at all, and a header-only file.
    let p = write_tmp("text.mat", b"t,u,y\n0,1,2\n");
    assert!(MatFile::open(&p)
        .unwrap_err()
        .to_string()
        .contains("not a MATLAB v5"));
    let w = W { big: false };
    let p = write_tmp("header_only.mat", &w.header());
    let mf = MatFile::open(&p).unwrap();
    assert!(mf.variables().is_empty());
    let (_, msg) = var_err(mf.vector("u").unwrap_err());
    assert!(msg.contains("not found"), "{msg}");
    // Missing file.
    let e = MatFile::open(Path::new("/nonexistent/x.mat")).unwrap_err();
    assert!(matches!(e, Error::Io { .. }));
}

/// Real data: the motor-bench logs (values cross-checked with scipy.io.loadmat 1.17.1).
#[test]
fn motor_bench_files_read_and_objects_skipped() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/motor-bench");
    if !dir.exists() {
        eprintln!("skipping: {} not present", dir.display());
        return;
    }
    // (file, iq_refx[0], iq_refx[12345], omega_max[12345], sum(theta_mx))
    let refs = [
        (
            "MultisineTypeA.mat",
            12.97525,
            -3.878988,
            0.6035963,
            -371289.81515100005,
        ),
        (
            "MultisineTypeB.mat",
            9.993205,
            -13.06132,
            0.2114176,
            179376.18068700001,
        ),
    ];
    for (f, iq0, iq1, om, th_sum) in refs {
        let p = dir.join(f);
        let mf = MatFile::open(&p).unwrap();
        let skipped: Vec<&str> = mf.skipped().iter().map(|s| s.name.as_str()).collect();
        for n in ["ctp", "itp", "stp"] {
            assert!(skipped.contains(&n), "{f}: {n} not skipped ({skipped:?})");
        }
        assert!(
            mf.skipped().iter().any(|s| s.reason.contains("opaque")),
            "{:?}",
            mf.skipped()
        );
        let log = read_mat(
            &p,
            &MatOptions {
                inputs: vec!["iq_refx".into()],
                outputs: vec!["omega_max".into(), "theta_mx".into()],
                time: Some("time".into()),
                time_scale: 1e-6,
                fs: Some(2500.0),
                ..MatOptions::default()
            },
        )
        .unwrap();
        assert_eq!(log.len(), 50_000);
        assert!((log.fs() - 2500.0).abs() < 1e-9);
        assert_eq!(log.u()[0], iq0);
        assert_eq!(log.u()[12345], iq1);
        assert_eq!(log.y()[12345], om);
        let s: f64 = log.outputs[1].data.iter().sum();
        assert!((s - th_sum).abs() < 1e-6 * th_sum.abs(), "{s} vs {th_sum}");
        assert!(log.warnings.is_empty(), "{:?}", log.warnings);
        assert_eq!(mf.scalar("fs").unwrap(), 2500.0);
        assert_eq!(mf.scalar("nrofs").unwrap(), 2500.0);
    }
}
