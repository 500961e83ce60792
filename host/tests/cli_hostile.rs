//! Issue 30 (hardening, round 2) through the command line, table-driven: a failed or closed
//! stdout, every numeric flag of every command against the sweep 0, −0, −1, 1e-308, 1e308, nan,
//! inf, every output flag against files ferrosid did not write (user files, symbolic links,
//! device nodes, FIFOs, its own inputs), non-regular and oversized inputs, foreign encodings and
//! repeated JSON keys. Every case asserts the exit code and the message; none may panic.
//!
//! Run: `cargo test -p ferrosid --test integration cli_hostile::`.
mod cli_support;
use cli_support::{
    expect, ferrosid, ferrosid_to as run_with, no_panic, s, scratch, write_csv, Rng, Run,
};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_ferrosid"))
}

/// Runs `f` on cases in two threads (the binary is the cost; two cores).
fn par<T: Sync>(cases: &[T], f: impl Fn(&T) + Sync) {
    let next = std::sync::atomic::AtomicUsize::new(0);
    std::thread::scope(|sc| {
        for _ in 0..2 {
            sc.spawn(|| loop {
                let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                match cases.get(i) {
                    Some(c) => f(c),
                    None => break,
                }
            });
        }
    });
}

/// Inputs of every command, small enough that a full run in the debug build is quick.
struct Kit {
    dir: PathBuf,
    log: String,
    log2: String,
    val: String,
    sim: String,
    model: String,
    pid: String,
    wm: String,
    frame: String,
    out: String,
    /// An empty fleet directory.
    fleet: String,
}

fn kit(name: &str) -> Kit {
    let dir = scratch(name);
    let mut rng = Rng::new(30);
    let mut log = |name: &str, n: usize, amp: f64| {
        let u = rng.noise(n, amp);
        let mut y = vec![0.0; n];
        for k in 1..n {
            y[k] = 0.9 * y[k - 1] + 0.1 * u[k - 1];
        }
        let e = rng.noise(n, 0.001);
        let y: Vec<f64> = y.iter().zip(&e).map(|(a, b)| a + b).collect();
        let p = dir.join(name);
        write_csv(&p, 1e-3, &u, &y);
        s(&p).to_string()
    };
    let (l1, l2, v) = (
        log("a.csv", 1200, 1.0),
        log("b.csv", 1200, 2.0),
        log("v.csv", 1200, 1.5),
    );
    let w = |name: &str, text: &str| {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        s(&p).to_string()
    };
    let sim = w(
        "sim.json",
        r#"{"ts": 0.001, "a": [[0.9]], "b": [[0.1]], "c": [[1.0]], "d": [[0.0]]}"#,
    );
    let model = sim.clone();
    let pid = w(
        "pid.json",
        r#"{"kp": 0.8, "ki": 4.0, "kd": 0.01, "tau_f": 0.002, "rolloff": null}"#,
    );
    let wm = w(
        "wm.json",
        r#"{"order": 1, "num": [0.5, 20.0], "den": [1.0, 400.0]}"#,
    );
    let frame = w("frame.log", &frame_text());
    let out = s(&dir.join("out")).to_string();
    let fleet = dir.join("fleet");
    std::fs::create_dir_all(&fleet).unwrap();
    let fleet = s(&fleet).to_string();
    Kit {
        dir,
        log: l1,
        log2: l2,
        val: v,
        sim,
        model,
        pid,
        wm,
        frame,
        out,
        fleet,
    }
}

fn frame_text() -> String {
    let mut t = String::from("FRAME_BEGIN fs=1000 n=64 averages=4 gate=0.9\n");
    for b in 0..=32 {
        let f = b as f64 / 64.0;
        let q = num_complex::Complex64::from_polar(1.0, -2.0 * std::f64::consts::PI * f);
        let h = q / (1.0 - 0.5 * q);
        let suu = if b == 0 { 0.0 } else { 1.0 };
        t.push_str(&format!(
            "FRAME {b} {suu} {} {} {} {}\n",
            h.norm_sqr() * suu,
            h.re * suu,
            h.im * suu,
            if b == 0 { 0.0 } else { 0.99 }
        ));
    }
    t.push_str("FRAME_END bins=33\n");
    t
}

impl Kit {
    /// The base command line of each command (without the flag under test).
    fn base(&self, cmd: &str) -> Vec<String> {
        let v: Vec<&str> = match cmd {
            "identify" => vec!["identify", &self.log, "--order", "1"],
            "frf" => vec!["frf", &self.log],
            "gap" => vec![
                "gap",
                "--sim",
                &self.sim,
                "--real",
                &self.log,
                "--real",
                &self.log2,
                "--validate",
                &self.val,
            ],
            "codegen" => vec![
                "codegen",
                "--model",
                &self.model,
                "--pid",
                &self.pid,
                "--wm",
                &self.wm,
                "--out-dir",
                &self.out,
            ],
            "reidentify" => vec!["reidentify", &self.frame, "--na", "1", "--nb", "0"],
            "fleet" => vec!["fleet", &self.fleet],
            other => panic!("no base for {other}"),
        };
        v.into_iter().map(String::from).collect()
    }
}

// ---- 1. A failed stdout is exit 3 with a message; a closed pipe ends quietly ---------------

fn stdout_cases(k: &Kit) -> Vec<(&'static str, Vec<String>)> {
    let tpl = s(&k.dir.join("tpl")).to_string();
    let mut c = vec![
        ("codegen", k.base("codegen")),
        (
            "codegen --json",
            [k.base("codegen"), vec!["--json".into()]].concat(),
        ),
        (
            "codegen --write-templates",
            vec!["codegen".into(), "--write-templates".into(), tpl],
        ),
        ("reidentify", k.base("reidentify")),
        (
            "reidentify --json",
            [k.base("reidentify"), vec!["--json".into()]].concat(),
        ),
        ("frf", k.base("frf")),
        ("--help", vec!["--help".into()]),
        ("identify --help", vec!["identify".into(), "--help".into()]),
        ("--version", vec!["--version".into()]),
    ];
    c.push((
        "identify --json",
        [k.base("identify"), vec!["--json".into()]].concat(),
    ));
    c
}

#[test]
fn a_full_stdout_is_exit_3_and_a_closed_pipe_is_quiet() {
    let k = kit("stdout");
    if !Path::new("/dev/full").exists() {
        eprintln!("notice: no /dev/full here; the full-stdout cases are skipped");
    }
    let cases = stdout_cases(&k);
    par(&cases, |(what, args)| {
        let a: Vec<&str> = args.iter().map(String::as_str).collect();
        if let Ok(full) = std::fs::OpenOptions::new().write(true).open("/dev/full") {
            let r = run_with(&a, Stdio::from(full));
            expect(
                &r,
                3,
                &["<stdout>", "No space left"],
                &format!("{what} > /dev/full"),
            );
        }
        // A closed pipe: the reading end is gone before the command writes.
        let mut child = bin()
            .args(&a)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        drop(child.stdout.take());
        let out = child.wait_with_output().unwrap();
        let r = Run {
            code: out.status.code().unwrap_or(-1),
            stdout: String::new(),
            stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
            stdout_bytes: Vec::new(),
        };
        expect(&r, 0, &[], &format!("{what} | (closed)"));
        assert!(
            r.stderr.is_empty(),
            "{what} | (closed): quiet, got {}",
            r.stderr
        );
    });
}

// ---- 2. Every numeric flag × the sweep -----------------------------------------------------

const SWEEP: [&str; 7] = ["0", "-0", "-1", "1e-308", "1e308", "nan", "inf"];

/// (command, flag, extra arguments the flag needs).
const NUMERIC_FLAGS: &[(&str, &str, &[&str])] = &[
    ("identify", "--order", &[]),
    ("identify", "--time-scale", &[]),
    ("identify", "--fs", &[]),
    ("identify", "--time-jitter", &[]),
    ("identify", "--block-rows", &[]),
    ("identify", "--stable-margin", &[]),
    ("identify", "--decimate", &[]),
    ("identify", "--crossover-hz", &[]),
    ("identify", "--phase-tol", &[]),
    ("identify", "--max-lag", &[]),
    ("identify", "--overlap", &[]),
    ("identify", "--period", &[]),
    ("identify", "--skip-periods", &["--period", "100"]),
    ("identify", "--gate", &[]),
    ("identify", "--nperseg", &[]),
    ("frf", "--time-scale", &[]),
    ("frf", "--fs", &[]),
    ("frf", "--time-jitter", &[]),
    ("frf", "--nperseg", &[]),
    ("frf", "--overlap", &[]),
    ("frf", "--period", &[]),
    ("frf", "--skip-periods", &["--period", "100"]),
    ("frf", "--gate", &[]),
    ("gap", "--time-scale", &[]),
    ("gap", "--fs", &[]),
    ("gap", "--time-jitter", &[]),
    ("gap", "--margin", &[]),
    ("gap", "--threshold", &[]),
    ("gap", "--gate", &[]),
    ("gap", "--warmup", &[]),
    ("gap", "--nperseg", &[]),
    ("gap", "--decimate", &[]),
    ("codegen", "--ts", &[]),
    ("codegen", "--prewarp-hz", &[]),
    ("codegen", "--wm-level", &[]),
    ("codegen", "--check-hz", &[]),
    ("codegen", "--welch-n", &[]),
    ("codegen", "--averages", &[]),
    ("codegen", "--settle-periods", &[]),
    ("codegen", "--gate", &[]),
    ("codegen", "--excitation-rms", &[]),
    ("codegen", "--excitation-max-hz", &[]),
    ("codegen", "--min-checked", &[]),
    ("reidentify", "--na", &[]),
    ("reidentify", "--nb", &[]),
    ("reidentify", "--min-delay", &[]),
    ("reidentify", "--max-delay", &[]),
    ("reidentify", "--gate", &[]),
    ("reidentify", "--min-rel-suu", &[]),
    ("fleet", "--jobs", &[]),
];

/// True when `text` holds a run of more than 24 decimal digits (a huge f64 printed in full).
fn has_long_number(text: &str) -> bool {
    let mut run = 0;
    for b in text.bytes() {
        if b.is_ascii_digit() {
            run += 1;
            if run > 24 {
                return true;
            }
        } else if b != b'.' {
            run = 0;
        }
    }
    false
}

/// Values no flag accepts: they must be usage errors naming the flag.
fn never_valid(v: &str) -> bool {
    matches!(v, "nan" | "inf")
}

#[test]
fn every_numeric_flag_survives_the_sweep_and_names_itself() {
    let k = kit("sweep");
    let mut cases = Vec::new();
    for (cmd, flag, extra) in NUMERIC_FLAGS {
        for v in SWEEP {
            cases.push((*cmd, *flag, *extra, v));
        }
    }
    let fails = std::sync::Mutex::new(Vec::new());
    par(&cases, |(cmd, flag, extra, v)| {
        let mut args = k.base(cmd);
        args.extend(extra.iter().map(|e| e.to_string()));
        // A flag of the base command line (identify --order) is replaced.
        if let Some(i) = args.iter().position(|a| a == flag) {
            args.drain(i..i + 2);
        }
        args.push(format!("{flag}={v}"));
        if *cmd == "codegen" {
            // One output directory per case (two threads).
            let out = k.dir.join(format!("out{}", flag.trim_start_matches('-')));
            let i = args.iter().position(|a| a == "--out-dir").unwrap();
            args[i + 1] = s(&out).to_string();
        }
        let a: Vec<&str> = args.iter().map(String::as_str).collect();
        let r = ferrosid(&a);
        let what = format!("{cmd} {flag}={v}");
        let bad = if r.stderr.contains("panicked") || ![0, 1, 2, 3, 4].contains(&r.code) {
            Some(format!("panicked or killed (exit {})", r.code))
        } else if r.code == 2 && !r.stderr.contains(flag) {
            Some("usage error not naming the flag".to_string())
        } else if never_valid(v) && r.code != 2 {
            Some(format!("accepted (exit {})", r.code))
        } else if r.stderr.contains(" - Hz") || r.stderr.contains("inf rad/s") {
            Some("an unprintable number in the message".to_string())
        } else if has_long_number(&r.stderr) || has_long_number(&r.stdout) {
            Some("a number of more than 24 digits in the output".to_string())
        } else {
            None
        };
        if let Some(b) = bad {
            fails
                .lock()
                .unwrap()
                .push(format!("{what}: {b}: {}", r.stderr.trim()));
        }
    });
    let fails = fails.into_inner().unwrap();
    assert!(
        fails.is_empty(),
        "{} cases:\n{}",
        fails.len(),
        fails.join("\n")
    );
}

#[test]
fn flags_that_do_not_apply_or_overflow_are_usage_errors() {
    let k = kit("notapply");
    let mk = |base: Vec<String>, extra: &[&str]| -> Vec<String> {
        let mut v = base;
        v.extend(extra.iter().map(|e| e.to_string()));
        v
    };
    let cases: Vec<(Vec<String>, i32, Vec<&str>, &str)> = vec![
        (
            mk(
                vec![
                    "codegen".into(),
                    "--model".into(),
                    k.model.clone(),
                    "--wm-level".into(),
                    "0.2".into(),
                    "--out-dir".into(),
                    k.out.clone(),
                ],
                &["--prewarp-hz=100"],
            ),
            2,
            vec!["--prewarp-hz", "does not apply", "no --pid"],
            "codegen --prewarp-hz without a PID",
        ),
        (
            mk(k.base("codegen"), &["--ts=nan"]),
            2,
            vec!["--ts"],
            "codegen --ts=nan with a discrete model",
        ),
        (
            mk(k.base("identify"), &["--crossover-hz=1e308"]),
            2,
            vec!["--crossover-hz", "1e308"],
            "identify --crossover-hz 1e308",
        ),
        (
            mk(k.base("identify"), &["--crossover-hz=5e299"]),
            0,
            vec![],
            "identify --crossover-hz 5e299 (in range)",
        ),
        (
            mk(k.base("gap"), &["--time-scale=1e-308"]),
            2,
            vec!["--time-scale", "1e-308"],
            "gap --time-scale 1e-308",
        ),
        (
            mk(k.base("frf"), &["--fs=1e308"]),
            2,
            vec!["--fs", "1e308"],
            "frf --fs 1e308",
        ),
    ];
    par(&cases, |(args, code, needles, what)| {
        let a: Vec<&str> = args.iter().map(String::as_str).collect();
        let r = ferrosid(&a);
        expect(&r, *code, needles, what);
        assert!(!r.stderr.contains(" - Hz"), "{what}: {}", r.stderr);
        assert!(
            !has_long_number(&r.stdout) && !has_long_number(&r.stderr),
            "{what}: a 300-digit number: {}{}",
            r.stdout,
            r.stderr
        );
    });
}

// ---- 3. Data loss: outputs never replace what ferrosid did not write -----------------------

/// A character device like /dev/null (or /dev/full) made in `dir`; None when mknod is not
/// allowed here (then the device cases are skipped with a notice).
fn device(dir: &Path, name: &str, minor: u32) -> Option<PathBuf> {
    let p = dir.join(name);
    let ok = Command::new("mknod")
        .args([s(&p), "c", "1", &minor.to_string()])
        .status()
        .is_ok_and(|st| st.success());
    if ok {
        Some(p)
    } else {
        eprintln!("notice: mknod not permitted here; device-node cases skipped");
        None
    }
}

fn fifo(dir: &Path, name: &str) -> Option<PathBuf> {
    let p = dir.join(name);
    let ok = Command::new("mkfifo")
        .arg(s(&p))
        .status()
        .is_ok_and(|st| st.success());
    ok.then_some(p)
}

fn is_char_device(p: &Path) -> bool {
    use std::os::unix::fs::FileTypeExt as _;
    std::fs::symlink_metadata(p).is_ok_and(|m| m.file_type().is_char_device())
}

/// Output flags: (what, command line writing to `target`).
fn output_cases(k: &Kit, target: &str) -> Vec<(String, Vec<String>)> {
    let v = |a: &[&str]| a.iter().map(|x| x.to_string()).collect::<Vec<_>>();
    vec![
        (
            "identify --out".into(),
            [k.base("identify"), v(&["--out", target])].concat(),
        ),
        (
            "reidentify --out".into(),
            [k.base("reidentify"), v(&["--out", target])].concat(),
        ),
    ]
}

#[test]
fn outputs_refuse_files_ferrosid_did_not_write() {
    let k = kit("dataloss");
    let user = k.dir.join("thesis.txt");
    let link = k.dir.join("link.json");
    std::os::unix::fs::symlink(&user, &link).unwrap();
    let mut cases: Vec<(String, Vec<String>, PathBuf)> = Vec::new();
    for t in [&user, &link] {
        for (what, args) in output_cases(&k, s(t)) {
            cases.push((format!("{what} {}", t.display()), args, t.clone()));
        }
    }
    // gap --figures DIR holding the user's gap_overlay.svg; codegen --out-dir holding a
    // hand-written <prefix>.h, also with --prefix mod (mod.rs).
    let figs = k.dir.join("figs");
    std::fs::create_dir_all(&figs).unwrap();
    let overlay = figs.join("gap_overlay.svg");
    cases.push((
        "gap --figures".into(),
        [k.base("gap"), vec!["--figures".into(), s(&figs).into()]].concat(),
        overlay.clone(),
    ));
    let gen = k.dir.join("gen");
    std::fs::create_dir_all(&gen).unwrap();
    let mut cg = k.base("codegen");
    let i = cg.iter().position(|a| a == "--out-dir").unwrap();
    cg[i + 1] = s(&gen).into();
    cases.push((
        "codegen --out-dir (<prefix>.h)".into(),
        [cg.clone(), vec!["--prefix".into(), "axis".into()]].concat(),
        gen.join("axis.h"),
    ));
    cases.push((
        "codegen --out-dir --prefix mod".into(),
        [cg.clone(), vec!["--prefix".into(), "modx".into()]].concat(),
        gen.join("modx.rs"),
    ));
    for (_, _, file) in &cases {
        if !file.exists() || file.is_symlink() {
            let target = if file.is_symlink() {
                user.clone()
            } else {
                file.clone()
            };
            std::fs::write(&target, "my own words\n").unwrap();
        }
    }
    par(&cases, |(what, args, file)| {
        let a: Vec<&str> = args.iter().map(String::as_str).collect();
        let r = ferrosid(&a);
        expect(&r, 3, &["not written by ferrosid", "--force"], what);
        assert_eq!(
            std::fs::read_to_string(file).unwrap(),
            "my own words\n",
            "{what}: the user's file changed"
        );
    });
    assert!(link.is_symlink(), "the symbolic link was replaced");
    // With --force the user asked for it; the second run replaces ferrosid's own file quietly.
    let mut a = output_cases(&k, s(&user)).remove(1).1;
    a.push("--force".into());
    let a: Vec<&str> = a.iter().map(String::as_str).collect();
    expect(&ferrosid(&a), 0, &[], "reidentify --out --force");
    let a = output_cases(&k, s(&user)).remove(1).1;
    let a: Vec<&str> = a.iter().map(String::as_str).collect();
    expect(
        &ferrosid(&a),
        0,
        &[],
        "reidentify --out over its own output",
    );
    let a = [cg.clone(), vec!["--prefix".into(), "fresh".into()]].concat();
    let a: Vec<&str> = a.iter().map(String::as_str).collect();
    expect(&ferrosid(&a), 0, &[], "codegen into a fresh name");
    // gap replaces its own figures (marked inside the <svg> element) run after run.
    let own_figs = k.dir.join("own_figs");
    let g = [k.base("gap"), vec!["--figures".into(), s(&own_figs).into()]].concat();
    let g: Vec<&str> = g.iter().map(String::as_str).collect();
    expect(
        &ferrosid(&g),
        0,
        &[],
        "gap --figures into a fresh directory",
    );
    expect(&ferrosid(&g), 0, &[], "gap --figures over its own figures");
    let svg = std::fs::read_to_string(own_figs.join("gap_overlay.svg")).unwrap();
    assert!(svg.starts_with("<svg") && svg.contains("<!-- written by ferrosid -->"));
    std::fs::write(gen.join("fresh.h"), "/* edited */\n").unwrap();
    expect(
        &ferrosid(&a),
        3,
        &["fresh.h", "not written by ferrosid"],
        "codegen over an edit",
    );
}

#[test]
fn prefixes_that_shadow_headers_or_modules_are_refused() {
    let k = kit("prefix");
    let cases = [
        "stdint", "math", "mod", "lib", "std", "core", "fn", "string", "time",
    ];
    par(&cases, |p| {
        let mut a = k.base("codegen");
        a.extend(["--prefix".to_string(), p.to_string()]);
        let a: Vec<&str> = a.iter().map(String::as_str).collect();
        let r = ferrosid(&a);
        expect(
            &r,
            2,
            &["prefix", &format!("{p}.h")],
            &format!("--prefix {p}"),
        );
        assert!(!k.dir.join("out").join(format!("{p}.h")).exists());
    });
}

#[test]
fn device_nodes_and_fifos_are_never_replaced() {
    let k = kit("devices");
    let Some(null) = device(&k.dir, "null", 3) else {
        return;
    };
    let full = device(&k.dir, "full", 7).unwrap();
    let pipe = fifo(&k.dir, "pipe").unwrap();
    let cases: Vec<(String, Vec<String>, i32, Vec<&str>)> = vec![
        (
            "identify --out nulldev".into(),
            output_cases(&k, s(&null))[0].1.clone(),
            0,
            vec![],
        ),
        (
            "reidentify --out fulldev".into(),
            output_cases(&k, s(&full))[1].1.clone(),
            3,
            vec!["No space left"],
        ),
        (
            "identify --out fifo".into(),
            output_cases(&k, s(&pipe))[0].1.clone(),
            3,
            vec!["FIFO"],
        ),
    ];
    par(&cases, |(what, args, code, needles)| {
        let a: Vec<&str> = args.iter().map(String::as_str).collect();
        expect(&ferrosid(&a), *code, needles, what);
    });
    assert!(
        is_char_device(&null) && is_char_device(&full),
        "a device node was replaced"
    );
    assert!(std::fs::symlink_metadata(&pipe)
        .is_ok_and(|m| std::os::unix::fs::FileTypeExt::is_fifo(&m.file_type())));
}

#[test]
fn fleet_merge_does_not_overwrite_its_own_input() {
    let d = scratch("merge_self");
    let sh = d.join("sh1");
    std::fs::create_dir_all(&sh).unwrap();
    std::fs::write(sh.join("fleet.json"), "{\"schema\": \"x\"}\n").unwrap();
    let r = ferrosid(&["fleet", "merge", s(&sh), s(&sh), "--out", s(&sh)]);
    expect(
        &r,
        2,
        &["--out", "input"],
        "fleet merge --out naming its input",
    );
    assert_eq!(
        std::fs::read_to_string(sh.join("fleet.json")).unwrap(),
        "{\"schema\": \"x\"}\n"
    );
}

#[test]
fn the_manifest_deletes_only_unchanged_files_of_its_own() {
    use ferrosid::io::file_safety::{OutputDir, MANIFEST_FILE};
    let d = scratch("manifest");
    {
        let mut o = OutputDir::acquire(&d).unwrap();
        o.write(Path::new("pid.json"), "ours\n").unwrap();
        o.write(Path::new("wm.json"), "ours too\n").unwrap();
    }
    // The user replaces pid.json by their own; a copied manifest names a file outside.
    std::fs::write(d.join("pid.json"), "the user's\n").unwrap();
    let outside = d
        .parent()
        .unwrap()
        .join(format!("outside-{}", std::process::id()));
    std::fs::write(&outside, "keep\n").unwrap();
    let mut m = std::fs::read_to_string(d.join(MANIFEST_FILE)).unwrap();
    m.push_str(&format!(
        "../{}\n",
        outside.file_name().unwrap().to_str().unwrap()
    ));
    m.push_str(&format!("{}\n", outside.display()));
    std::fs::write(d.join(MANIFEST_FILE), m).unwrap();
    {
        let mut o = OutputDir::acquire(&d).unwrap();
        assert!(o.check_replaceable([Path::new("pid.json")]).is_err());
        o.remove_stale(Path::new("pid.json")).unwrap();
        o.remove_stale(Path::new("wm.json")).unwrap();
        o.remove_stale(&PathBuf::from("..").join(outside.file_name().unwrap()))
            .unwrap();
        o.remove_stale(&outside).unwrap();
    }
    assert_eq!(
        std::fs::read_to_string(d.join("pid.json")).unwrap(),
        "the user's\n"
    );
    assert!(
        !d.join("wm.json").exists(),
        "its own unchanged file is removed"
    );
    assert_eq!(std::fs::read_to_string(&outside).unwrap(), "keep\n");
    let m = std::fs::read_to_string(d.join(MANIFEST_FILE)).unwrap();
    assert!(!m.contains("outside") && !m.contains("pid.json"), "{m}");
    let _ = std::fs::remove_file(&outside);
}

// ---- 4. Inputs: regular files only, size caps, encodings, one JSON rule --------------------

#[test]
fn non_regular_and_oversized_inputs_are_refused_quickly() {
    let k = kit("inputs");
    let pipe = fifo(&k.dir, "nowriter.csv").unwrap();
    let zero_csv = k.dir.join("zero.csv");
    std::os::unix::fs::symlink("/dev/zero", &zero_csv).unwrap();
    // Sparse files: no disk used, sizes above the caps.
    let big_csv = k.dir.join("big.csv");
    std::fs::File::create(&big_csv)
        .unwrap()
        .set_len(ferrosid::io::input::MAX_LOG_BYTES + 1)
        .unwrap();
    let big_json = k.dir.join("big.json");
    std::fs::File::create(&big_json)
        .unwrap()
        .set_len(ferrosid::io::input::MAX_DOC_BYTES + 1)
        .unwrap();
    let v = |a: &[&str]| a.iter().map(|x| x.to_string()).collect::<Vec<String>>();
    let with = |cmd: &str, flag: &str, new: &str| {
        let mut b = k.base(cmd);
        let i = b.iter().position(|a| a == flag).unwrap();
        b[i + 1] = new.into();
        b
    };
    let cases: Vec<(String, Vec<String>, Vec<&str>)> = vec![
        (
            "identify FIFO".into(),
            v(&["identify", s(&pipe)]),
            vec!["FIFO"],
        ),
        (
            "frf /dev/zero link".into(),
            v(&["frf", s(&zero_csv)]),
            vec!["character device"],
        ),
        (
            "identify too big".into(),
            v(&["identify", s(&big_csv)]),
            vec!["2 GiB"],
        ),
        (
            "gap --sim /dev/zero".into(),
            with("gap", "--sim", "/dev/zero"),
            vec!["character device"],
        ),
        (
            "gap --sim FIFO".into(),
            with("gap", "--sim", s(&pipe)),
            vec!["FIFO"],
        ),
        (
            "codegen --model /dev/zero".into(),
            with("codegen", "--model", "/dev/zero"),
            vec!["/dev/zero"],
        ),
        (
            "codegen --model big".into(),
            with("codegen", "--model", s(&big_json)),
            vec!["64 MiB"],
        ),
        (
            "codegen --receipts /dev/zero".into(),
            [k.base("codegen"), v(&["--receipts", "/dev/zero"])].concat(),
            vec!["character device"],
        ),
        (
            "codegen --source /dev/zero".into(),
            [k.base("codegen"), v(&["--source", "/dev/zero"])].concat(),
            vec!["character device"],
        ),
        (
            "reidentify /dev/zero".into(),
            v(&["reidentify", "/dev/zero"]),
            vec!["character device"],
        ),
        (
            "run /dev/zero".into(),
            v(&["run", "/dev/zero"]),
            vec!["character device"],
        ),
    ];
    par(&cases, |(what, args, needles)| {
        let a: Vec<&str> = args.iter().map(String::as_str).collect();
        let t0 = std::time::Instant::now();
        let r = ferrosid(&a);
        expect(&r, 3, needles, what);
        assert!(
            t0.elapsed().as_secs() < 20,
            "{what}: took {:?}",
            t0.elapsed()
        );
    });
}

#[test]
fn foreign_encodings_and_repeated_keys_get_one_clear_rule() {
    let k = kit("encodings");
    let text = std::fs::read_to_string(&k.log).unwrap();
    let mut utf16 = vec![0xFF, 0xFE];
    for u in text.encode_utf16() {
        utf16.extend_from_slice(&u.to_le_bytes());
    }
    let bom = k.dir.join("u16.csv");
    std::fs::write(&bom, &utf16).unwrap();
    let nobom = k.dir.join("u16nobom.csv");
    std::fs::write(&nobom, &utf16[2..]).unwrap();
    let toml16 = k.dir.join("p16.toml");
    let mut t16 = vec![0xFF, 0xFE];
    for u in "[signals]\ninput = \"u\"\n".encode_utf16() {
        t16.extend_from_slice(&u.to_le_bytes());
    }
    std::fs::write(&toml16, &t16).unwrap();
    let dup = k.dir.join("dup.json");
    std::fs::write(
        &dup,
        "{\"ts\": 0.001, \"a\": [[0.9]], \"b\": [[0.1]], \"c\": [[1.0]],\n \"d\": [[0.0]], \"a\": [[0.5]]}",
    )
    .unwrap();
    let with = |cmd: &str, flag: &str, new: &str| {
        let mut b = k.base(cmd);
        let i = b.iter().position(|a| a == flag).unwrap();
        b[i + 1] = new.into();
        b
    };
    let cases: Vec<(String, Vec<String>, Vec<&str>)> = vec![
        (
            "frf UTF-16".into(),
            vec!["frf".into(), s(&bom).into()],
            vec!["UTF-16", "UTF-8"],
        ),
        (
            "frf UTF-16 without BOM".into(),
            vec!["frf".into(), s(&nobom).into()],
            vec!["UTF-16"],
        ),
        (
            "run UTF-16 pipeline".into(),
            vec!["run".into(), s(&toml16).into()],
            vec!["UTF-16"],
        ),
        (
            "gap --sim dup".into(),
            with("gap", "--sim", s(&dup)),
            vec!["dup.json:2", "duplicate key `a`"],
        ),
        (
            "codegen --model dup".into(),
            with("codegen", "--model", s(&dup)),
            vec!["duplicate key `a`"],
        ),
    ];
    par(&cases, |(what, args, needles)| {
        let a: Vec<&str> = args.iter().map(String::as_str).collect();
        expect(&ferrosid(&a), 3, needles, what);
    });
}

#[test]
fn gap_bounds_its_cost_by_order_and_sample_time() {
    let k = kit("gapcost");
    let n = 22;
    let mut a = vec![vec![0.0; n]; n];
    for (i, row) in a.iter_mut().enumerate() {
        row[i] = -1.0 - i as f64;
    }
    let sim = serde_json::json!({
        "ts": 0.0, "a": a, "b": vec![vec![1.0]; n], "c": [vec![1.0; n]], "d": [[0.0]]
    });
    let p = k.dir.join("big_sim.json");
    std::fs::write(&p, sim.to_string()).unwrap();
    let with = |flag: &str, new: &str| {
        let mut b = k.base("gap");
        let i = b.iter().position(|a| a == flag).unwrap();
        b[i + 1] = new.into();
        b
    };
    let mut slow = k.base("gap");
    slow.push("--time-scale=1e4".into());
    let cases: Vec<(Vec<String>, i32, Vec<&str>, &str)> = vec![
        (
            with("--sim", s(&p)),
            3,
            vec!["22 states", "at most 20"],
            "gap 22-state sim",
        ),
        (
            slow,
            2,
            vec!["--time-scale", "outside gap's range"],
            "gap 10 s per sample",
        ),
    ];
    par(&cases, |(args, code, needles, what)| {
        let a: Vec<&str> = args.iter().map(String::as_str).collect();
        let t0 = std::time::Instant::now();
        expect(&ferrosid(&a), *code, needles, what);
        assert!(t0.elapsed().as_secs() < 20, "{what}: {:?}", t0.elapsed());
    });
}

// ---- 5. A full disk leaves the previous outputs intact -------------------------------------

/// A small tmpfs mounted for the test (unmounted on drop); None where mounting is not allowed.
struct Tmpfs(PathBuf);

impl Tmpfs {
    fn mount(dir: &Path, size: &str) -> Option<Tmpfs> {
        std::fs::create_dir_all(dir).ok()?;
        let ok = Command::new("mount")
            .args([
                "-t",
                "tmpfs",
                "-o",
                &format!("size={size}"),
                "tmpfs",
                s(dir),
            ])
            .stderr(Stdio::null())
            .status()
            .is_ok_and(|st| st.success());
        if ok {
            Some(Tmpfs(dir.to_path_buf()))
        } else {
            eprintln!("notice: cannot mount a tmpfs here; the full-disk cases are skipped");
            None
        }
    }
}

impl Drop for Tmpfs {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg(s(&self.0)).status();
    }
}

fn snapshot(dir: &Path) -> std::collections::BTreeMap<PathBuf, Vec<u8>> {
    let mut out = std::collections::BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.insert(p.clone(), std::fs::read(&p).unwrap());
            }
        }
    }
    out
}

/// Fills the file system of `dir` and then frees `keep` bytes.
fn fill(dir: &Path, keep: u64) {
    use std::io::Write as _;
    let p = dir.join("filler");
    let mut f = std::fs::File::create(&p).unwrap();
    let chunk = vec![0x55u8; 64 << 10];
    while f.write_all(&chunk).is_ok() {}
    let _ = f.flush();
    let len = f.metadata().unwrap().len();
    f.set_len(len.saturating_sub(keep)).unwrap();
}

#[test]
fn a_full_disk_leaves_the_previous_run_intact() {
    let d = scratch("fulldisk");
    let Some(mnt) = Tmpfs::mount(&d.join("mnt"), "6m") else {
        return;
    };
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/data");
    let pipeline = |ms_max: &str| {
        let text = format!(
            "[signals]\ninput = \"u\"\noutput = \"y\"\ntime = \"t\"\n\
             [[runs]]\nname = \"low\"\nfile = \"{}\"\namplitude = 0.05\n\
             [[runs]]\nname = \"high\"\nfile = \"{}\"\namplitude = 0.15\n\
             [validation]\nfile = \"{}\"\n[etfe]\nnperseg = 500\n\
             [control]\ncrossover_hz = 8.0\nrolloff_ratio = 4.0\nms_max = {ms_max}\n\
             actuator_limit = 0.3\nreference_amplitude = 5.0\n",
            s(&data.join("two_mass_low.csv")),
            s(&data.join("two_mass_high.csv")),
            s(&data.join("two_mass_validate.csv")),
        );
        let p = d.join(format!("pipeline-{ms_max}.toml"));
        std::fs::write(&p, text).unwrap();
        p
    };
    let out = mnt.0.join("out");
    let r = ferrosid(&["run", s(&pipeline("1.6")), "--out", s(&out)]);
    assert!(r.code == 0 || r.code == 1, "first run: {}", r.stderr);
    let before = snapshot(&out);
    let model = mnt.0.join("model.json");
    let k = kit("fulldisk_kit");
    let id = [k.base("identify"), vec!["--out".into(), s(&model).into()]].concat();
    let id: Vec<&str> = id.iter().map(String::as_str).collect();
    expect(&ferrosid(&id), 0, &[], "identify --out on the tmpfs");
    let model_before = std::fs::read(&model).unwrap();
    // Room for the small JSON files, not for the report.
    fill(&mnt.0, 24 << 10);
    let r = ferrosid(&["run", s(&pipeline("1.7")), "--out", s(&out)]);
    expect(&r, 3, &["No space left"], "run on a full disk");
    let after = snapshot(&out);
    let changed: Vec<_> = before
        .iter()
        .filter(|(p, b)| after.get(*p) != Some(*b))
        .map(|(p, _)| p.display().to_string())
        .chain(
            after
                .keys()
                .filter(|p| !before.contains_key(*p))
                .map(|p| format!("new {}", p.display())),
        )
        .collect();
    assert!(
        changed.is_empty(),
        "a full disk changed the previous run: {changed:?}"
    );
    std::fs::remove_file(mnt.0.join("filler")).unwrap();
    fill(&mnt.0, 0);
    expect(
        &ferrosid(&id),
        3,
        &["No space left"],
        "identify --out on a full disk",
    );
    assert_eq!(std::fs::read(&model).unwrap(), model_before);
}

// ---- 6. The output table: every output flag × hostile targets ------------------------------

#[derive(Clone, Copy, Debug)]
enum Target {
    UserFile,
    SymlinkToUserFile,
    OwnInput,
    Directory,
}

#[test]
fn every_output_flag_against_hostile_targets() {
    let k = kit("outtable");
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/data");
    let toml = k.dir.join("pipeline.toml");
    std::fs::write(
        &toml,
        format!(
            "[signals]\ninput = \"u\"\noutput = \"y\"\ntime = \"t\"\n\
             [[runs]]\nname = \"low\"\nfile = \"{}\"\namplitude = 0.05\n\
             [validation]\nfile = \"{}\"\n",
            s(&data.join("two_mass_low.csv")),
            s(&data.join("two_mass_validate.csv")),
        ),
    )
    .unwrap();
    // File outputs: (what, command line without the output, the flag, the command's input).
    let file_outputs: Vec<(&str, Vec<String>, &str, String)> = vec![
        ("identify --out", k.base("identify"), "--out", k.log.clone()),
        (
            "identify --params-out",
            [
                k.base("identify"),
                ["--structure", "stage", "--known", "Kf=4"]
                    .map(String::from)
                    .to_vec(),
            ]
            .concat(),
            "--params-out",
            k.log.clone(),
        ),
        (
            "reidentify --out",
            k.base("reidentify"),
            "--out",
            k.frame.clone(),
        ),
    ];
    let mut cases = Vec::new();
    for (i, (what, base, flag, input)) in file_outputs.iter().enumerate() {
        for t in [
            Target::UserFile,
            Target::SymlinkToUserFile,
            Target::OwnInput,
            Target::Directory,
        ] {
            cases.push((i, *what, base.clone(), *flag, input.clone(), t));
        }
    }
    par(&cases, |(i, what, base, flag, input, t)| {
        let d = k.dir.join(format!("case-{i}-{t:?}"));
        std::fs::create_dir_all(&d).unwrap();
        let user = d.join("mine.json");
        std::fs::write(&user, "my own words\n").unwrap();
        let target = match t {
            Target::UserFile => user.clone(),
            Target::SymlinkToUserFile => {
                let l = d.join("link.json");
                std::os::unix::fs::symlink(&user, &l).unwrap();
                l
            }
            Target::OwnInput => PathBuf::from(input),
            Target::Directory => d.clone(),
        };
        let input_before = std::fs::read(input).unwrap();
        let mut a = base.clone();
        a.extend([flag.to_string(), s(&target).to_string()]);
        let a: Vec<&str> = a.iter().map(String::as_str).collect();
        let r = ferrosid(&a);
        let what = format!("{what} → {t:?}");
        match t {
            Target::UserFile | Target::SymlinkToUserFile => {
                expect(&r, 3, &["not written by ferrosid"], &what)
            }
            Target::OwnInput => expect(&r, 2, &["input"], &what),
            Target::Directory => expect(&r, 3, &["directory"], &what),
        }
        assert_eq!(
            std::fs::read_to_string(&user).unwrap(),
            "my own words\n",
            "{what}"
        );
        assert_eq!(
            std::fs::read(input).unwrap(),
            input_before,
            "{what}: input changed"
        );
    });
    // Directory outputs over a regular user file, and over a directory holding user files of
    // the names they write.
    let dir_outputs: Vec<(&str, Vec<String>, &str, &str)> = vec![
        (
            "gap --figures",
            k.base("gap"),
            "--figures",
            "gap_overlay.svg",
        ),
        (
            "codegen --out-dir",
            k.base("codegen"),
            "--out-dir",
            "ferrosid.h",
        ),
        (
            "run --out",
            vec!["run".into(), s(&toml).into()],
            "--out",
            "report.html",
        ),
    ];
    par(&dir_outputs, |(what, base, flag, name)| {
        let d = k.dir.join(format!("dir-{}", flag.trim_start_matches('-')));
        std::fs::create_dir_all(&d).unwrap();
        let holder = d.join("holder");
        std::fs::create_dir_all(&holder).unwrap();
        std::fs::write(holder.join(name), "my own words\n").unwrap();
        let plain = d.join("plain.txt");
        std::fs::write(&plain, "my own words\n").unwrap();
        for (target, label) in [
            (&holder, "a directory holding user files"),
            (&plain, "a file"),
        ] {
            let mut a: Vec<String> = base.clone();
            match a.iter().position(|x| x == flag) {
                Some(i) => a[i + 1] = s(target).into(),
                None => a.extend([flag.to_string(), s(target).to_string()]),
            }
            let a: Vec<&str> = a.iter().map(String::as_str).collect();
            let r = ferrosid(&a);
            expect(&r, 3, &[], &format!("{what} → {label}"));
        }
        assert_eq!(
            std::fs::read_to_string(holder.join(name)).unwrap(),
            "my own words\n"
        );
        assert_eq!(std::fs::read_to_string(&plain).unwrap(), "my own words\n");
    });
}

#[test]
fn fs_takes_precedence_over_rounded_repeated_stamps() {
    let d = scratch("rounded");
    let mut rng = Rng::new(31);
    let n = 4000;
    let u = rng.noise(n, 1.0);
    let mut text = String::from("t,u,y\n");
    let mut y = 0.0;
    for (k, uk) in u.iter().enumerate() {
        // 2 kHz printed with 3 decimals: every other stamp repeats its neighbour.
        text.push_str(&format!(
            "{:.3},{uk:e},{y:e}\n",
            (k as f64 * 5e-4 * 1e3).floor() / 1e3
        ));
        y = 0.9 * y + 0.1 * uk;
    }
    let p = d.join("rounded.csv");
    std::fs::write(&p, text).unwrap();
    let r = ferrosid(&["frf", s(&p)]);
    expect(
        &r,
        3,
        &["not strictly increasing", "--fs"],
        "rounded stamps without --fs",
    );
    let r = ferrosid(&["frf", s(&p), "--fs", "2000"]);
    expect(
        &r,
        0,
        &["repeats", "fs = 2000 Hz"],
        "rounded stamps with --fs",
    );
    let r = ferrosid(&["frf", s(&p), "--fs", "1000"]);
    expect(
        &r,
        3,
        &["fs = 1000 Hz was given"],
        "rounded stamps with a wrong --fs",
    );
}

/// Runs the binary, killing it after `secs` seconds (then the case fails instead of hanging).
fn ferrosid_within(args: &[&str], secs: u64) -> Run {
    let mut child = bin()
        .args(args)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let t0 = std::time::Instant::now();
    loop {
        if let Some(_status) = child.try_wait().unwrap() {
            let out = child.wait_with_output().unwrap();
            return Run {
                code: out.status.code().unwrap_or(-1),
                stdout: String::new(),
                stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
                stdout_bytes: Vec::new(),
            };
        }
        if t0.elapsed().as_secs() >= secs {
            let _ = child.kill();
            let _ = child.wait();
            panic!("{args:?} did not finish within {secs} s");
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
}

#[test]
fn outputs_linked_to_endless_devices_never_block() {
    let k = kit("endless");
    let gen = k.dir.join("gen");
    std::fs::create_dir_all(&gen).unwrap();
    std::os::unix::fs::symlink("/dev/zero", gen.join("ferrosid.h")).unwrap();
    let mut a = k.base("codegen");
    let i = a.iter().position(|x| x == "--out-dir").unwrap();
    a[i + 1] = s(&gen).into();
    let a: Vec<&str> = a.iter().map(String::as_str).collect();
    // The header goes to the device (as to /dev/null); the link stays a link.
    expect(
        &ferrosid_within(&a, 20),
        0,
        &[],
        "codegen --out-dir with a header linked to /dev/zero",
    );
    assert!(gen.join("ferrosid.h").is_symlink());
    let tpl = k.dir.join("tpl");
    std::fs::create_dir_all(&tpl).unwrap();
    std::os::unix::fs::symlink("/dev/zero", tpl.join("model.h")).unwrap();
    let r = ferrosid_within(&["codegen", "--write-templates", s(&tpl)], 20);
    expect(
        &r,
        3,
        &["model.h", "--force"],
        "--write-templates over a link to /dev/zero",
    );
    // A FIFO planted as the output directory's lock file.
    let out = k.dir.join("run_out");
    std::fs::create_dir_all(&out).unwrap();
    if let Some(_lock) = fifo(&out, ".ferrosid.lock") {
        let toml = k.dir.join("p.toml");
        std::fs::write(&toml, "[signals]\ninput = \"u\"\n").unwrap();
        let r = ferrosid_within(&["run", s(&toml), "--out", s(&out)], 20);
        no_panic(&r, "run with a FIFO as the lock");
        assert_eq!(r.code, 3, "{}", r.stderr);
    }
}
