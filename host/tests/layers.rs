//! The host crate's import arrows point down the chain (issue 11, `docs/architecture.md`):
//! log → signals → spectra → model → validation → bound → controller + receipts → gap
//! diagnosis → commands → pipeline → report → output files → front ends.
//!
//! How it is checked: every `.rs` file under `host/src/` is scanned (comments and string
//! literals removed) for `crate::<module>` paths, including grouped `crate::{a, b}` ones. The
//! file's own top-level module is its first path component below `src/`. Each import must go
//! to a module of the same or a lower layer of [`LAYERS`], and two top-level modules may not
//! import each other (a cycle inside one layer is one concept split wrongly). A new top-level
//! module fails the test until it is placed in the table. Cross-module paths are written
//! `crate::...` throughout the crate (`super::` never leaves a top-level module), so this scan
//! sees every arrow; `main.rs` is the binary and uses only `ferrosid::cli`.
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The layer table, bottom (1) to top. An import may point to the same layer or below.
const LAYERS: &[(&str, u8)] = &[
    // 1. In-memory logs, errors, readers, wire formats, SVG plot primitives: no numerics.
    ("error", 1),
    ("data", 1),
    ("io", 1),
    ("target_frame", 1),
    ("plot", 1),
    // 2. Signal conditioning, spectra, LTI algebra, the operating point of a log.
    ("preprocess", 2),
    ("spectral", 2),
    ("lti", 2),
    ("operating_point", 2),
    ("optim", 2),
    // 3. Models from data and their validation.
    ("n4sid", 3),
    ("closed_loop", 3),
    ("greybox", 3),
    ("rational_fit", 3),
    ("validate", 3),
    // 4. Bounds and controllers: audit, W_m, norms, PID tuning, receipts.
    ("robust", 4),
    // 5. Sim-to-real diagnosis, limit cycles, compensation design.
    ("gap", 5),
    ("limit_cycle", 5),
    ("synth", 5),
    ("compensation", 5),
    // 6. Each command's whole job as a library call (typed options in, typed result out).
    ("ops", 6),
    // 7. The pipeline: the ops composed into one typed run.
    ("pipeline", 7),
    // 8. HTML report and SVG figures of a finished run.
    ("report", 8),
    // 9. Writing a run's output directory; many units' runs and their directories.
    ("output", 9),
    ("fleet", 9),
    // 10. Front ends: argument mapping, rendering, exit codes.
    ("cli", 10),
];

/// Known arrows that break the table, each with the reason it is still there. The test fails
/// when one of them disappears, so the list cannot outlive the problem.
const KNOWN_UPWARD: &[(&str, &str, &str)] = &[];

/// Removes comments, string and char literals from Rust source, keeping line structure.
fn strip_comments_and_strings(src: &str) -> String {
    let b: Vec<char> = src.chars().collect();
    let mut out = String::with_capacity(src.len());
    let mut i = 0;
    while i < b.len() {
        let c = b[i];
        let next = b.get(i + 1).copied();
        if c == '/' && next == Some('/') {
            while i < b.len() && b[i] != '\n' {
                i += 1;
            }
        } else if c == '/' && next == Some('*') {
            let mut depth = 0;
            while i < b.len() {
                if b[i] == '/' && b.get(i + 1) == Some(&'*') {
                    depth += 1;
                    i += 2;
                } else if b[i] == '*' && b.get(i + 1) == Some(&'/') {
                    depth -= 1;
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    if b[i] == '\n' {
                        out.push('\n');
                    }
                    i += 1;
                }
            }
        } else if c == 'r'
            && (next == Some('"') || next == Some('#'))
            && (i == 0 || !(b[i - 1].is_alphanumeric() || b[i - 1] == '_'))
        {
            // Raw string r"..." / r#"..."#.
            let mut j = i + 1;
            let mut hashes = 0;
            while b.get(j) == Some(&'#') {
                hashes += 1;
                j += 1;
            }
            if b.get(j) != Some(&'"') {
                out.push(c);
                i += 1;
                continue;
            }
            j += 1;
            loop {
                if j >= b.len() {
                    break;
                }
                if b[j] == '"' && (0..hashes).all(|k| b.get(j + 1 + k) == Some(&'#')) {
                    j += 1 + hashes;
                    break;
                }
                if b[j] == '\n' {
                    out.push('\n');
                }
                j += 1;
            }
            out.push_str("\"\"");
            i = j;
        } else if c == '"' {
            i += 1;
            while i < b.len() && b[i] != '"' {
                if b[i] == '\\' {
                    i += 1;
                } else if b[i] == '\n' {
                    out.push('\n');
                }
                i += 1;
            }
            out.push_str("\"\"");
            i += 1;
        } else if c == '\''
            && (matches!((next, b.get(i + 2)), (Some(_), Some('\''))) || next == Some('\\'))
        {
            // A char literal ('x' or '\n'), not a lifetime.
            i += 1;
            while i < b.len() && b[i] != '\'' {
                if b[i] == '\\' {
                    i += 1;
                }
                i += 1;
            }
            out.push_str("' '");
            i += 1;
        } else {
            out.push(c);
            i += 1;
        }
    }
    out
}

/// Top-level modules named by `crate::` paths in (stripped) source, with the line of each.
fn crate_imports(code: &str) -> Vec<(String, usize)> {
    let mut found = Vec::new();
    for (ln, line) in code.lines().enumerate() {
        let mut rest = line;
        while let Some(p) = rest.find("crate::") {
            let before = rest[..p].chars().next_back();
            rest = &rest[p + "crate::".len()..];
            if before.is_some_and(|c| c.is_alphanumeric() || c == '_') {
                continue; // e.g. `ferrosid_crate::`
            }
            if let Some(group) = rest.strip_prefix('{') {
                // `crate::{a, b::c, self}`: the first identifier of each top-level item.
                let mut depth = 0;
                let mut item_start = true;
                let mut ident = String::new();
                for ch in group.chars() {
                    match ch {
                        '{' => depth += 1,
                        '}' if depth == 0 => break,
                        '}' => depth -= 1,
                        ',' if depth == 0 => {
                            if !ident.is_empty() {
                                found.push((std::mem::take(&mut ident), ln + 1));
                            }
                            item_start = true;
                            continue;
                        }
                        _ => {}
                    }
                    if item_start && depth == 0 {
                        if ch.is_alphanumeric() || ch == '_' {
                            ident.push(ch);
                            continue;
                        } else if !ident.is_empty() {
                            found.push((std::mem::take(&mut ident), ln + 1));
                            item_start = false;
                        }
                    }
                }
                if !ident.is_empty() {
                    found.push((ident, ln + 1));
                }
            } else {
                let ident: String = rest
                    .chars()
                    .take_while(|c| c.is_alphanumeric() || *c == '_')
                    .collect();
                if !ident.is_empty() {
                    found.push((ident, ln + 1));
                }
            }
        }
    }
    found
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).expect("read src dir") {
        let p = e.expect("dir entry").path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// The top-level module a file belongs to (`None` for the crate root files).
fn top_module(src: &Path, file: &Path) -> Option<String> {
    let rel = file.strip_prefix(src).expect("file under src");
    let first = rel
        .components()
        .next()?
        .as_os_str()
        .to_string_lossy()
        .into_owned();
    match first.as_str() {
        "lib.rs" | "main.rs" => None,
        f => Some(f.trim_end_matches(".rs").to_string()),
    }
}

/// Every (from, to) arrow between top-level modules, with one example location each.
fn arrows(src: &Path) -> BTreeMap<(String, String), String> {
    let mut files = Vec::new();
    rust_files(src, &mut files);
    files.sort();
    let mut arrows = BTreeMap::new();
    for f in &files {
        let Some(from) = top_module(src, f) else {
            continue;
        };
        let code = strip_comments_and_strings(&std::fs::read_to_string(f).expect("read"));
        for (to, line) in crate_imports(&code) {
            if to != from && to != "self" {
                let at = format!("{}:{line}", f.strip_prefix(src).unwrap().display());
                arrows.entry((from.clone(), to)).or_insert(at);
            }
        }
    }
    arrows
}

/// Violations of the table (unknown modules, upward arrows, two-way arrows), as messages.
fn violations(
    arrows: &BTreeMap<(String, String), String>,
    modules: &BTreeSet<String>,
) -> Vec<String> {
    let layer: BTreeMap<&str, u8> = LAYERS.iter().copied().collect();
    let mut bad = Vec::new();
    for m in modules {
        if !layer.contains_key(m.as_str()) {
            bad.push(format!(
                "module `{m}` is not in the layer table of tests/layers.rs"
            ));
        }
    }
    for ((from, to), at) in arrows {
        let known = KNOWN_UPWARD.iter().any(|(f, t, _)| f == from && t == to);
        // Unknown modules are reported above; a `crate::X` that is no module (a root
        // re-export such as `crate::Error`) has no layer of its own.
        let (Some(&lf), Some(&lt)) = (layer.get(from.as_str()), layer.get(to.as_str())) else {
            continue;
        };
        if lt > lf && !known {
            bad.push(format!(
                "{at}: `{from}` (layer {lf}) imports `{to}` (layer {lt}), which is above it"
            ));
        }
        if from < to && arrows.contains_key(&(to.clone(), from.clone())) && !known {
            bad.push(format!(
                "`{from}` and `{to}` import each other ({at} and {})",
                arrows[&(to.clone(), from.clone())]
            ));
        }
    }
    bad
}

fn src_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("src")
}

fn top_modules(src: &Path) -> BTreeSet<String> {
    let mut files = Vec::new();
    rust_files(src, &mut files);
    files.iter().filter_map(|f| top_module(src, f)).collect()
}

#[test]
fn imports_point_down_the_layer_table() {
    let src = src_dir();
    let arrows = arrows(&src);
    let bad = violations(&arrows, &top_modules(&src));
    assert!(bad.is_empty(), "layer violations:\n{}", bad.join("\n"));
}

#[test]
fn known_upward_arrows_are_still_there() {
    // When one of these is cut, delete it from KNOWN_UPWARD.
    let arrows = arrows(&src_dir());
    for (from, to, why) in KNOWN_UPWARD {
        assert!(
            arrows.contains_key(&(from.to_string(), to.to_string())),
            "`{from}` → `{to}` is gone; remove it from KNOWN_UPWARD ({why})"
        );
    }
}

#[test]
fn every_table_entry_is_unique() {
    let names: BTreeSet<&str> = LAYERS.iter().map(|(n, _)| *n).collect();
    assert_eq!(names.len(), LAYERS.len());
}

#[test]
fn the_scanner_finds_real_imports_and_ignores_comments_and_strings() {
    let code = strip_comments_and_strings(
        "//! see [`crate::report`]\n\
         use crate::lti::StateSpace; // crate::pipeline\n\
         let s = \"crate::cli\"; let r = r#\"crate::fleet\"#; let c = '\"';\n\
         /* crate::output */ use crate::{error::Result, spectral, self};\n\
         fn f<'a>(x: &'a str) { crate::gap::rng::x(); }\n",
    );
    let mods: Vec<String> = crate_imports(&code).into_iter().map(|(m, _)| m).collect();
    assert_eq!(mods, ["lti", "error", "spectral", "self", "gap"]);
}

#[test]
fn an_upward_arrow_and_a_cycle_are_reported() {
    let mut arrows = BTreeMap::new();
    arrows.insert(("lti".into(), "report".into()), "lti/x.rs:3".to_string());
    arrows.insert(
        ("spectral".into(), "preprocess".into()),
        "spectral.rs:1".to_string(),
    );
    arrows.insert(
        ("preprocess".into(), "spectral".into()),
        "preprocess.rs:2".to_string(),
    );
    let modules: BTreeSet<String> = ["lti", "report", "spectral", "preprocess", "widgets"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    let bad = violations(&arrows, &modules);
    assert_eq!(bad.len(), 3, "{bad:#?}");
    assert!(bad[0].contains("`widgets` is not in the layer table"));
    assert!(bad
        .iter()
        .any(|m| m.contains("`lti` (layer 2) imports `report` (layer 8)")));
    assert!(bad
        .iter()
        .any(|m| m.contains("`preprocess` and `spectral` import each other")));
}

/// The dev crate `ferrosid-sim` (the same-law plant simulator, the gap benchmark harness and the
/// seeded RNG) is not in the library (issue 11): `host/src` holds none of its files, only
/// `gap/simulator.rs` includes them (`#[path]`), that module is declared `#[cfg(test)]`, and
/// the crate is a dev-dependency of `ferrosid`, never a dependency.
#[test]
fn the_simulator_is_not_in_the_library() {
    let src = src_dir();
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    for f in &files {
        let rel = f
            .strip_prefix(&src)
            .unwrap()
            .to_string_lossy()
            .replace('\\', "/");
        assert!(
            !["gap/plant.rs", "gap/benchmark.rs", "gap/rng.rs"].contains(&rel.as_str()),
            "{rel} is back in the library (it lives in sim/src)"
        );
        let text = std::fs::read_to_string(f).expect("read");
        if rel != "gap/simulator.rs" {
            assert!(
                !text.contains("sim/src/") || !text.contains("#[path"),
                "{rel} includes the simulator's files; only gap/simulator.rs may (test builds)"
            );
        }
    }
    let gap_mod = std::fs::read_to_string(src.join("gap/mod.rs")).expect("read gap/mod.rs");
    let lines: Vec<&str> = gap_mod.lines().map(str::trim).collect();
    let at = lines
        .iter()
        .position(|l| l.ends_with("mod simulator;"))
        .expect("gap/mod.rs declares the test-only `simulator` module");
    assert!(
        at > 0 && lines[at - 1] == "#[cfg(test)]",
        "gap::simulator must be `#[cfg(test)]`"
    );
    let manifest =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("Cargo.toml"))
            .expect("read host/Cargo.toml");
    let mut section = "";
    for line in manifest.lines().map(str::trim) {
        if line.starts_with('[') {
            section = line;
        } else if line.starts_with("ferrosid-sim") {
            assert_eq!(
                section, "[dev-dependencies]",
                "ferrosid-sim must stay a dev-dependency of ferrosid"
            );
        }
    }
}

/// The workspace's one random-number generator: the firmware's SplitMix64.
const THE_RNG: &str = "firmware/src/rng.rs";

/// Files that still carry a generator of their own, each with the reason. The test fails when
/// one of them no longer does, so the list cannot outlive the problem.
const OTHER_GENERATORS: &[(&str, &str)] = &[(
    "gapsim/src/rng.rs",
    "the second benchmark family's xoshiro256** (SplitMix64-seeded): independent of the \
         first family's generator on purpose, so the two families share no code",
)];

/// `.rs` files under `dir`, skipping build output (`target*`) and hidden directories.
fn workspace_rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).expect("read dir") {
        let p = e.expect("dir entry").path();
        let name = p.file_name().map(|n| n.to_string_lossy().into_owned());
        let name = name.unwrap_or_default();
        if p.is_dir() {
            if !name.starts_with('.') && !name.starts_with("target") {
                workspace_rust_files(&p, out);
            }
        } else if name.ends_with(".rs") {
            out.push(p);
        }
    }
}

/// What makes `src` a pseudo-random generator (comments and strings ignored, digit separators
/// and whitespace removed): SplitMix64's finaliser multipliers, the MMIX LCG multiplier,
/// xorshift*'s output multiplier, or an xorshift step `x ^= x << k` / `x ^= x >> k`.
/// Seeds that happen to be such constants are not steps and are not reported.
fn generator_marks(src: &str) -> Vec<&'static str> {
    let code: String = strip_comments_and_strings(src)
        .chars()
        .filter(|c| !c.is_whitespace() && *c != '_')
        .collect::<String>()
        .to_lowercase();
    let mut marks = Vec::new();
    for (needle, what) in [
        ("wrappingmul(0xbf58476d1ce4e5b9", "SplitMix64 finaliser"),
        ("wrappingmul(0x94d049bb133111eb", "SplitMix64 finaliser"),
        ("wrappingmul(6364136223846793005", "MMIX LCG"),
        ("wrappingmul(0x5851f42d4c957f2d", "MMIX LCG"),
        ("wrappingmul(0x2545f4914f6cdd1d", "xorshift*"),
    ] {
        if code.contains(needle) && !marks.contains(&what) {
            marks.push(what);
        }
    }
    let is_ident = |c: char| c.is_ascii_alphanumeric() || c == '.' || c == '[' || c == ']';
    for (at, _) in code.match_indices("^=") {
        let lhs_start = code[..at]
            .char_indices()
            .rev()
            .take_while(|&(_, c)| is_ident(c))
            .last()
            .map_or(at, |(i, _)| i);
        let lhs = &code[lhs_start..at];
        let rhs = &code[at + 2..];
        if !lhs.is_empty()
            && rhs.starts_with(lhs)
            && (rhs[lhs.len()..].starts_with("<<") || rhs[lhs.len()..].starts_with(">>"))
            && !marks.contains(&"xorshift step")
        {
            marks.push("xorshift step");
        }
    }
    marks
}

/// Issue 11: one RNG. Every `.rs` file of the workspace (all crates, tests, benches, examples,
/// the QEMU images) is scanned; only `firmware/src/rng.rs` may implement a generator, apart from
/// the listed exceptions. `ferrosid_sim::rng::Rng` builds its uniform and normal draws on it.
#[test]
fn one_rng_in_the_workspace() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("workspace root")
        .to_path_buf();
    let mut files = Vec::new();
    workspace_rust_files(&root, &mut files);
    assert!(files.len() > 100, "{} files: wrong root?", files.len());
    let mut found = BTreeMap::new();
    for f in &files {
        let rel = f
            .strip_prefix(&root)
            .unwrap()
            .to_string_lossy()
            .replace('\\', "/");
        let text = std::fs::read_to_string(f).expect("read");
        let marks = generator_marks(&text);
        if !marks.is_empty() {
            found.insert(rel, marks);
        }
    }
    assert!(
        found.contains_key(THE_RNG),
        "{THE_RNG} is not a generator any more: {found:?}"
    );
    let mut bad = Vec::new();
    for (rel, marks) in &found {
        if rel != THE_RNG && !OTHER_GENERATORS.iter().any(|(f, _)| f == rel) {
            bad.push(format!(
                "{rel}: {marks:?} (use ferrosid_sim::rng::Rng or {THE_RNG})"
            ));
        }
    }
    for (f, why) in OTHER_GENERATORS {
        if !found.contains_key(*f) {
            bad.push(format!(
                "{f} has no generator any more: drop it from the list ({why})"
            ));
        }
    }
    assert!(bad.is_empty(), "{}", bad.join("\n"));
}

#[test]
fn the_generator_scanner_finds_copies_and_ignores_seeds_and_comments() {
    let splitmix = "fn n(s: &mut u64) -> u64 { *s = s.wrapping_add(0x9E37_79B9_7F4A_7C15);\n\
                    let z = (*s ^ (*s >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9); z }";
    assert_eq!(generator_marks(splitmix), ["SplitMix64 finaliser"]);
    let xorshift = "fn n(&mut self) -> u64 { self.0 ^= self.0 << 13; self.0 ^= self.0 >> 7; 0 }";
    assert_eq!(generator_marks(xorshift), ["xorshift step"]);
    let lcg = "s = s\n    .wrapping_mul(6364136223846793005)\n    .wrapping_add(1);";
    assert_eq!(generator_marks(lcg), ["MMIX LCG"]);
    let clean = "// x ^= x << 13; wrapping_mul(6364136223846793005)\n\
                 let r = Rng::new(0x9E37_79B9_7F4A_7C15); let s = \"x ^= x << 13\";\n\
                 let m = a ^= b << 2; let y = z ^ (z >> 31);";
    assert!(
        generator_marks(clean).is_empty(),
        "{:?}",
        generator_marks(clean)
    );
}
