//! Lists the independent family's cases with their ground truth and what generating them cost
//! (integration steps, events, output scale), without running the diagnosis.
//!
//! `cargo run --release -p ferrosid-gapsim --example gapsim_cases -- [--filter TEXT] [--n SAMPLES]`
use ferrosid_gapsim::cases::{cases, generate};
use ferrosid_gapsim::excite::rms;

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut filter = String::new();
    let mut n = 16384usize;
    let mut i = 0;
    while i < args.len() {
        match (args[i].as_str(), args.get(i + 1)) {
            ("--filter", Some(v)) => filter = v.clone(),
            ("--n", Some(v)) => {
                n = v.parse().unwrap_or_else(|_| {
                    eprintln!("--n needs a number of samples");
                    std::process::exit(2)
                })
            }
            (other, _) => {
                eprintln!(
                    "unknown argument {other}; usage: gapsim_cases [--filter TEXT] [--n SAMPLES]"
                );
                std::process::exit(2)
            }
        }
        i += 2;
    }
    let all: Vec<_> = cases()
        .into_iter()
        .filter(|c| c.id.contains(&filter))
        .collect();
    println!("{} cases", all.len());
    for c in &all {
        let t0 = std::time::Instant::now();
        match generate(c, n) {
            Ok(d) => {
                let truth: Vec<String> = d
                    .truth
                    .iter()
                    .map(|t| {
                        let p: Vec<String> = t
                            .params
                            .iter()
                            .map(|(k, v)| format!("{k}={v:.4e}"))
                            .collect();
                        format!(
                            "{}@{}{{{}}}{}",
                            t.name,
                            t.place,
                            p.join(","),
                            if t.cross_family { "*" } else { "" }
                        )
                    })
                    .collect();
                println!(
                    "{:<44} {:<5} y_rms low/high/val {:.3e} {:.3e} {:.3e} (means {:.1e} {:.1e} {:.1e}) floor {:.4} steps {:>6} {:>6} {:>6} events {:>5} {:>5} {:>5} band-held {} {} {} {:.2} s  {}",
                    c.id,
                    if c.periodic { "per" } else { "noise" },
                    rms(d.train[0].y()),
                    rms(d.train[1].y()),
                    rms(d.validate.y()),
                    mean(d.train[0].y()),
                    mean(d.train[1].y()),
                    mean(d.validate.y()),
                    d.noise_floor,
                    d.stats[0].steps,
                    d.stats[1].steps,
                    d.stats[2].steps,
                    d.stats[0].events,
                    d.stats[1].events,
                    d.stats[2].events,
                    d.stats[0].band_held_samples,
                    d.stats[1].band_held_samples,
                    d.stats[2].band_held_samples,
                    t0.elapsed().as_secs_f64(),
                    truth.join(" + ")
                );
            }
            Err(e) => println!("{:<44} ERROR {e}", c.id),
        }
    }
}
