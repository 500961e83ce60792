//! Shared helpers of the `cli_*` tests: run the built `ferrosid` binary, scratch directories,
//! CSV writing, a seeded RNG, and an independent frequency-response evaluator for state-space
//! matrices read back from JSON (complex Gaussian elimination, written here on purpose so the
//! checks do not go through the library's evaluator).
#![allow(dead_code)]
use num_complex::Complex64;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;

/// Result of one run of the binary.
pub struct Run {
    pub code: i32,
    pub stdout: String,
    pub stderr: String,
    pub stdout_bytes: Vec<u8>,
}

/// Runs `ferrosid` with `args` (stderr is a pipe, so progress bars are hidden).
pub fn ferrosid(args: &[&str]) -> Run {
    ferrosid_to(args, std::process::Stdio::piped())
}

/// [`ferrosid`] with stdout sent to `stdout` (a full device, a closed pipe, ...).
pub fn ferrosid_to(args: &[&str], stdout: std::process::Stdio) -> Run {
    let out = Command::new(env!("CARGO_BIN_EXE_ferrosid"))
        .args(args)
        .stdout(stdout)
        .stderr(std::process::Stdio::piped())
        .output()
        .expect("the ferrosid binary runs");
    Run {
        code: out.status.code().unwrap_or(-1),
        stdout: String::from_utf8_lossy(&out.stdout).into_owned(),
        stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
        stdout_bytes: out.stdout,
    }
}

/// Asserts that a run neither panicked nor was killed (exit 101, 134 or a signal).
pub fn no_panic(r: &Run, what: &str) {
    assert!(
        !r.stderr.contains("panicked") && ![101, 134, -1].contains(&r.code),
        "{what} panicked or was killed (exit {}): {}",
        r.code,
        r.stderr
    );
}

/// Asserts no panic, the exit `code`, and every needle in stderr.
pub fn expect(r: &Run, code: i32, needles: &[&str], what: &str) {
    no_panic(r, what);
    assert_eq!(r.code, code, "{what}: exit code; stderr: {}", r.stderr);
    for n in needles {
        assert!(
            r.stderr.contains(n),
            "{what}: stderr lacks `{n}`: {}",
            r.stderr
        );
    }
}

/// A fresh, empty scratch directory unique to this test binary and `name`.
pub fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("ferrosid-cli-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("scratch directory");
    d
}

/// Path as &str (scratch paths are UTF-8).
pub fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

/// Writes a `t,u,y` CSV with sample time `ts` seconds, full f64 precision.
pub fn write_csv(path: &Path, ts: f64, u: &[f64], y: &[f64]) {
    let mut text = String::from("t,u,y\n");
    for (k, (a, b)) in u.iter().zip(y).enumerate() {
        let _ = writeln!(text, "{:e},{:e},{:e}", k as f64 * ts, a, b);
    }
    std::fs::write(path, text).expect("write csv");
}

#[allow(unused_imports)] // not every test that declares this module draws noise
pub use ferrosid_sim::rng::Rng;

/// Row-major real matrix from JSON rows.
pub fn rows(v: &serde_json::Value) -> Vec<Vec<f64>> {
    v.as_array()
        .expect("matrix rows")
        .iter()
        .map(|r| {
            r.as_array()
                .expect("row")
                .iter()
                .map(|x| x.as_f64().expect("number"))
                .collect()
        })
        .collect()
}

/// A discrete SISO model's response at `f_hz`: C (zI − A)⁻¹ B + D with z = exp(j 2π f ts),
/// by Gaussian elimination with partial pivoting on the complex system.
pub fn discrete_response(
    a: &[Vec<f64>],
    b: &[Vec<f64>],
    c: &[Vec<f64>],
    d: &[Vec<f64>],
    ts: f64,
    f_hz: f64,
) -> Complex64 {
    let n = a.len();
    let z = Complex64::from_polar(1.0, 2.0 * std::f64::consts::PI * f_hz * ts);
    let mut m: Vec<Vec<Complex64>> = (0..n)
        .map(|i| {
            let mut row: Vec<Complex64> = (0..n)
                .map(|j| {
                    let v = Complex64::new(-a[i][j], 0.0);
                    if i == j {
                        v + z
                    } else {
                        v
                    }
                })
                .collect();
            row.push(Complex64::new(b[i][0], 0.0));
            row
        })
        .collect();
    for col in 0..n {
        let piv = (col..n)
            .max_by(|&p, &q| m[p][col].norm().total_cmp(&m[q][col].norm()))
            .expect("pivot");
        m.swap(col, piv);
        let pivot_row = m[col].clone();
        for row in m.iter_mut().skip(col + 1) {
            let f = row[col] / pivot_row[col];
            for (x, &p) in row.iter_mut().zip(&pivot_row).skip(col) {
                *x -= f * p;
            }
        }
    }
    let mut x = vec![Complex64::new(0.0, 0.0); n];
    for i in (0..n).rev() {
        let mut acc = m[i][n];
        for k in i + 1..n {
            acc -= m[i][k] * x[k];
        }
        x[i] = acc / m[i][i];
    }
    let mut g = Complex64::new(d[0][0], 0.0);
    for j in 0..n {
        g += c[0][j] * x[j];
    }
    g
}

/// Logarithmically spaced frequencies from `lo` to `hi` Hz (inclusive), `n >= 2` points.
pub fn logspace(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    (0..n)
        .map(|k| lo * (hi / lo).powf(k as f64 / (n - 1) as f64))
        .collect()
}
