//! `ferrosid-qemu`: build, run and measure the firmware images of `tests/qemu` under QEMU.
//!
//! ```text
//! ferrosid-qemu run [--icount] [--timeout SECS] IMAGE [ARG...]   build, run, print decoded log;
//!                                                                exits with the image's code
//!                                                                (IMAGE with a '/' is an ELF path:
//!                                                                run as is, not built)
//! ferrosid-qemu size IMAGE                                       llvm-size figures of IMAGE
//! ferrosid-qemu report                                           bench (-icount) + sizeprobe:
//!                                                                markdown table for README.md
//! ```
//! Used by `scripts/bench-firmware.sh`.

use std::process::ExitCode;
use std::time::Duration;

use ferrosid_tests::{
    build_images, decode_defmt, documented_figures, image_size, repo_root, run_qemu, Error,
    RunOptions, PERFORMANCE_DOC,
};

/// Welch segment length whose figures the issue's bars refer to.
const BAR_N: u64 = 1024;
/// Bar (issue 33): mean instructions per input sample of `Welch::push` at N = 1024.
const BAR_INSTR_PER_SAMPLE: f64 = 120.0;
/// Bar (issue 33): instructions of the largest single `Welch::push` at N = 1024.
const BAR_MAX_PUSH: f64 = 5000.0;
/// Bar: static RAM (data + bss) in bytes = 24 N + 2 KiB at N = 1024.
const BAR_RAM: u64 = 24 * BAR_N + 2048;
/// Bar: flash (text + data) in bytes.
const BAR_FLASH: u64 = 32 * 1024;

fn usage() -> ExitCode {
    eprintln!(
        "usage: ferrosid-qemu run [--icount] [--timeout SECS] IMAGE [ARG...]\n       \
         ferrosid-qemu size IMAGE\n       ferrosid-qemu report"
    );
    ExitCode::from(2)
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args.first().map(String::as_str) {
        Some("run") => cmd_run(&args[1..]),
        Some("size") if args.len() == 2 => cmd_size(&args[1]),
        Some("report") if args.len() == 1 => cmd_report(),
        _ => return usage(),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(2)
        }
    }
}

fn cmd_run(args: &[String]) -> Result<ExitCode, Error> {
    let mut opts = RunOptions::default();
    let mut rest = args.iter();
    let mut image = None;
    while let Some(a) = rest.next() {
        match a.as_str() {
            "--icount" => opts.icount = true,
            "--timeout" => match rest.next().and_then(|s| s.parse::<u64>().ok()) {
                Some(s) => opts.timeout = Duration::from_secs(s),
                None => return Ok(usage()),
            },
            _ => {
                image = Some(a.clone());
                break;
            }
        }
    }
    let Some(image) = image else {
        return Ok(usage());
    };
    opts.args = rest.cloned().collect();
    // A path runs that ELF as is; a bare name builds that image of tests/qemu first.
    let elf = if image.contains('/') {
        std::path::PathBuf::from(&image)
    } else {
        build_images(&[&image])?.remove(0)
    };
    let run = run_qemu(&elf, &opts)?;
    for line in decode_defmt(&elf, &run.stdout)? {
        println!("{line}");
    }
    if !run.stderr.is_empty() {
        eprint!("{}", run.stderr);
    }
    eprintln!("{image}: exit code {}", run.exit_code);
    Ok(ExitCode::from(u8::try_from(run.exit_code).unwrap_or(255)))
}

fn cmd_size(image: &str) -> Result<ExitCode, Error> {
    let elf = build_images(&[image])?.remove(0);
    let s = image_size(&elf)?;
    println!(
        "{image}: text {} data {} bss {} => flash (text+data) {} B, static RAM (data+bss) {} B",
        s.text,
        s.data,
        s.bss,
        s.flash(),
        s.ram()
    );
    Ok(ExitCode::SUCCESS)
}

/// One `BENCH <name> <value> <unit>` line of the bench image.
struct BenchLine {
    name: String,
    value: f64,
    unit: String,
}

fn parse_bench(text: &str) -> Option<BenchLine> {
    let mut it = text.split_whitespace();
    if it.next()? != "BENCH" {
        return None;
    }
    let name = it.next()?.to_string();
    let value = it.next()?.parse().ok()?;
    let unit = it.collect::<Vec<_>>().join(" ");
    Some(BenchLine { name, value, unit })
}

fn verdict(ok: bool) -> &'static str {
    if ok {
        "met"
    } else {
        "NOT met"
    }
}

fn cmd_report() -> Result<ExitCode, Error> {
    let elfs = build_images(&["bench", "sizeprobe"])?;
    let opts = RunOptions {
        icount: true,
        timeout: Duration::from_secs(600),
        ..RunOptions::default()
    };
    let run = run_qemu(&elfs[0], &opts)?;
    let lines = decode_defmt(&elfs[0], &run.stdout)?;
    for l in &lines {
        eprintln!("bench: {l}");
    }
    if run.exit_code != 0 {
        eprintln!("{}", run.stderr);
        eprintln!("bench image failed with exit code {}", run.exit_code);
        return Ok(ExitCode::FAILURE);
    }
    let bench: Vec<BenchLine> = lines.iter().filter_map(|l| parse_bench(&l.text)).collect();
    let size = image_size(&elfs[1])?;
    let probe = run_qemu(&elfs[1], &RunOptions::default())?;
    let probe_lines = decode_defmt(&elfs[1], &probe.stdout)?;
    for l in &probe_lines {
        eprintln!("sizeprobe: {l}");
    }
    if probe.exit_code != 0 {
        eprintln!("{}", probe.stderr);
        eprintln!("sizeprobe image failed with exit code {}", probe.exit_code);
        return Ok(ExitCode::FAILURE);
    }
    let stack = probe_lines.iter().find_map(|l| {
        let mut it = l.text.split_whitespace();
        (it.next() == Some("STACK"))
            .then(|| it.next().and_then(|v| v.parse::<u64>().ok()))
            .flatten()
    });

    println!("| Firmware figure (Cortex-M4F, `qemu -icount shift=0`) | Value | Bar |");
    println!("|---|---:|---|");
    let mut all_met = true;
    for b in &bench {
        let bar = if b.name == "welch_push_n1024" {
            let ok = b.value <= BAR_INSTR_PER_SAMPLE;
            all_met &= ok;
            format!("<= {BAR_INSTR_PER_SAMPLE} ({})", verdict(ok))
        } else if b.name == "welch_push_max_n1024" {
            let ok = b.value <= BAR_MAX_PUSH;
            all_met &= ok;
            format!("<= {BAR_MAX_PUSH} ({})", verdict(ok))
        } else {
            String::new()
        };
        let digits = if b.unit == "ratio" { 3 } else { 1 };
        println!("| {} | {:.*} {} | {bar} |", b.name, digits, b.value, b.unit);
    }
    let ram_ok = size.ram() <= BAR_RAM;
    let flash_ok = size.flash() <= BAR_FLASH;
    all_met &= ram_ok && flash_ok;
    println!(
        "| sizeprobe static RAM (data+bss), Welch<1024> | {} B | <= {BAR_RAM} B ({}) |",
        size.ram(),
        verdict(ram_ok)
    );
    println!(
        "| sizeprobe flash (text+data) | {} B | <= {BAR_FLASH} B ({}) |",
        size.flash(),
        verdict(flash_ok)
    );
    match stack {
        Some(st) => println!(
            "| sizeprobe stack high-water (painted) / static RAM + stack | {st} B / {} B | |",
            size.ram() + st
        ),
        None => println!("| sizeprobe stack high-water | not reported | |"),
    }
    println!(
        "\n(sizeprobe = PRBS + Welch<1024> (Hann, 50 % overlap) + coherence gate + H1, built with \
         opt-level 3 and LTO; sections: text {} B, data {} B, bss {} B. The stack is not in any \
         section (cortex-m-rt puts it at the top of RAM), hence measured separately.)",
        size.text, size.data, size.bss
    );
    if !bench.iter().any(|b| b.name == "welch_push_n1024") {
        eprintln!("bench printed no welch_push_n1024 figure");
        return Ok(ExitCode::FAILURE);
    }
    println!("\nAll bars met: {}", if all_met { "yes" } else { "NO" });

    // Every figure written in docs/firmware-performance.md must be what was just measured,
    // within the noise stated beside it: otherwise the document is stale (or the code
    // changed) and this command fails.
    let mut measured: Vec<(String, f64)> =
        bench.iter().map(|b| (b.name.clone(), b.value)).collect();
    measured.push(("sizeprobe_ram_bytes".into(), size.ram() as f64));
    measured.push(("sizeprobe_flash_bytes".into(), size.flash() as f64));
    let doc_path = repo_root().join(PERFORMANCE_DOC);
    let doc = std::fs::read_to_string(&doc_path).map_err(|source| Error::Io {
        context: format!("reading {}", doc_path.display()),
        source,
    })?;
    let documented = documented_figures(&doc);
    let mut stale = 0;
    for f in &documented {
        match measured.iter().find(|(n, _)| *n == f.name) {
            Some((_, v)) if (v - f.value).abs() <= f.noise => {}
            Some((_, v)) => {
                stale += 1;
                eprintln!(
                    "STALE {}: {PERFORMANCE_DOC} says {} (noise {}), measured {v}",
                    f.name, f.value, f.noise
                );
            }
            None => {
                stale += 1;
                eprintln!("STALE {}: in {PERFORMANCE_DOC} but not measured", f.name);
            }
        }
    }
    println!(
        "{PERFORMANCE_DOC}: {} figures, {} match what was measured within their stated noise",
        documented.len(),
        documented.len() - stale
    );
    if documented.is_empty() || stale > 0 {
        eprintln!("{PERFORMANCE_DOC} does not match the measurement: regenerate its figures");
        return Ok(ExitCode::FAILURE);
    }
    Ok(ExitCode::SUCCESS)
}
