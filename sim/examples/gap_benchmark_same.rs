//! Runs the labelled sim-to-real gap benchmark (the same-law family only; both families: the
//! `gap_benchmark` example of ferrosid-gapsim) and prints the markdown summary for docs/gap-benchmark.md.
//!
//! `cargo run --release -p ferrosid-sim --example gap_benchmark_same [-- --n SAMPLES]
//! [--filter TEXT] [--seed-offset K] [--verbose]`
//! (default 16384 samples per log; `--filter` keeps cases whose id contains TEXT;
//! `--seed-offset` adds K to every case's seed — a fresh draw of nominal mismatch, excitation and
//! noise for the same effects, i.e. a held-out set for a diagnosis developed on the default
//! seeds; `--verbose` prints every report).
use ferrosid::gap::GapOptions;
use ferrosid_sim::benchmark::{cases, markdown, run_case};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let mut n = 16384usize;
    let mut filter = String::new();
    let mut verbose = false;
    let mut seed_offset = 0u64;
    let mut i = 1;
    while i < args.len() {
        match args[i].as_str() {
            "--n" if i + 1 < args.len() => {
                n = args[i + 1].parse().unwrap_or_else(|_| {
                    eprintln!("--n needs a number of samples");
                    std::process::exit(2)
                });
                i += 1;
            }
            "--filter" if i + 1 < args.len() => {
                filter = args[i + 1].clone();
                i += 1;
            }
            "--seed-offset" if i + 1 < args.len() => {
                seed_offset = args[i + 1].parse().unwrap_or_else(|_| {
                    eprintln!("--seed-offset needs a non-negative integer");
                    std::process::exit(2)
                });
                i += 1;
            }
            "--verbose" => verbose = true,
            other => {
                eprintln!("unknown argument {other}; usage: gap_benchmark_same [--n N] [--filter TEXT] [--seed-offset K] [--verbose]");
                std::process::exit(2);
            }
        }
        i += 1;
    }
    let opts = GapOptions::default();
    let mut outcomes = Vec::new();
    for mut case in cases().into_iter().filter(|c| c.id.contains(&filter)) {
        case.seed = case.seed.wrapping_add(seed_offset);
        match run_case(&case, n, &opts) {
            Ok((o, report)) => {
                if verbose {
                    eprintln!("{}", report.to_text());
                }
                let pe: Vec<String> = o
                    .param_errors
                    .iter()
                    .map(|(k, v)| format!("{k} {:.1}%", 100.0 * v))
                    .collect();
                eprintln!(
                    "{:<28} verdict {:<17} {} gaps {:.3} {:.3} {:.3}  {}  {:.2} s",
                    o.id,
                    o.verdict,
                    if o.correct() { "ok " } else { "BAD" },
                    o.gaps[0],
                    o.gaps[1],
                    o.gaps[2],
                    pe.join(" "),
                    o.seconds
                );
                outcomes.push(o);
            }
            Err(e) => eprintln!("{}: error: {e}", case.id),
        }
    }
    match markdown(&outcomes) {
        Ok(md) => println!("{md}"),
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(1);
        }
    }
}
