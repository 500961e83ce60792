//! Runs the two-family gap benchmark and prints the markdown summary.
//!
//! `cargo run --release -p ferrosid-gapsim --example gap_benchmark -- [--family same|indep|all|null]
//! [--filter TEXT] [--seed-offset K] [--n SAMPLES] [--lead K] [--verbose] [--jobs J]`
//!
//! `--family` (default `all`): the first family (`ferrosid_sim::benchmark`, same equations as
//! the candidates), the independent one (this crate's simulator), both, or `null` (the
//! effect-free set of `ferrosid_gapsim::null`, for the false-positive rate); `--filter` keeps cases
//! whose id contains TEXT; `--seed-offset` adds K to every seed (fresh nominal mismatch,
//! excitation and noise: a held-out draw); `--n` samples per log (default 16384); `--verbose`
//! prints each report's JSON to stderr; `--lead K` advances every logged output by K samples
//! (0–3: a logger that stores y[k] at the end of u[k]'s period); `--jobs` runs cases on J threads (default 1).
use ferrosid::gap::GapOptions;
use ferrosid_gapsim::bench::{all_cases, run_all};
use ferrosid_gapsim::score::markdown;

fn usage(msg: &str) -> ! {
    eprintln!(
        "{msg}\nusage: gap_benchmark [--family same|indep|all|null] [--filter TEXT] [--seed-offset K] \
         [--n SAMPLES] [--lead K] [--verbose] [--jobs J]"
    );
    std::process::exit(2)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut family = "all".to_string();
    let mut filter = String::new();
    let mut seed_offset = 0u64;
    let mut n = 16384usize;
    let mut verbose = false;
    let mut jobs = 1usize;
    let mut lead = 0usize;
    let mut i = 0;
    let value = |i: usize, what: &str| -> String {
        args.get(i + 1)
            .cloned()
            .unwrap_or_else(|| usage(&format!("{} needs {what}", args[i])))
    };
    while i < args.len() {
        match args[i].as_str() {
            "--family" => {
                family = value(i, "same, indep, all or null");
                if !["same", "indep", "all", "null"].contains(&family.as_str()) {
                    usage(&format!("--family: unknown family {family:?}"));
                }
                i += 1;
            }
            "--filter" => {
                filter = value(i, "a text");
                i += 1;
            }
            "--seed-offset" => {
                seed_offset = value(i, "a non-negative integer")
                    .parse()
                    .unwrap_or_else(|_| usage("--seed-offset needs a non-negative integer"));
                i += 1;
            }
            "--n" => {
                n = value(i, "a number of samples")
                    .parse()
                    .unwrap_or_else(|_| usage("--n needs a number of samples"));
                i += 1;
            }
            "--jobs" => {
                jobs = value(i, "a number of threads")
                    .parse()
                    .ok()
                    .filter(|&j: &usize| j >= 1)
                    .unwrap_or_else(|| usage("--jobs needs a number of threads >= 1"));
                i += 1;
            }
            "--lead" => {
                lead = value(i, "a number of samples")
                    .parse()
                    .ok()
                    .filter(|&k: &usize| k <= 3)
                    .unwrap_or_else(|| usage("--lead needs a number of samples from 0 to 3"));
                i += 1;
            }
            "--verbose" => verbose = true,
            other => usage(&format!("unknown argument {other}")),
        }
        i += 1;
    }
    let mut cases = all_cases(&family);
    cases.retain(|c| c.id().contains(&filter));
    for c in &mut cases {
        c.offset_seed(seed_offset);
    }
    if cases.is_empty() {
        usage("no case matches");
    }
    eprintln!("{} cases, {n} samples per log, {jobs} job(s)", cases.len());
    let opts = GapOptions::default();
    let described: std::collections::HashMap<String, String> =
        cases.iter().map(|c| (c.id(), c.describe())).collect();
    let outcomes = run_all(&cases, (n, lead), jobs, &opts, &|o, v| {
        if verbose {
            if let Some(v) = v {
                eprintln!("{}", serde_json::to_string_pretty(v).unwrap_or_default());
            }
        }
        let pe: Vec<String> = o
            .param_errors
            .iter()
            .map(|(k, v)| format!("{k} {:.1}%", 100.0 * v))
            .collect();
        eprintln!(
            "{:<44} {:<8} {} expected {:<24} verdict {:<24} place {:<5} gaps {:.3} {:.3} {:.3} floor {:.4}  {}  {:.2} s  {}",
            o.id,
            o.split.name(),
            if o.verdict_right { "ok " } else { "BAD" },
            o.expected,
            o.verdict,
            match o.place_right {
                Some(true) => "ok",
                Some(false) => "WRONG",
                None => "-",
            },
            o.gaps[0],
            o.gaps[1],
            o.gaps[2],
            o.noise_floor,
            pe.join(" "),
            o.seconds,
            described.get(&o.id).map_or("", String::as_str)
        );
    });
    println!("{}", markdown(&outcomes));
}
