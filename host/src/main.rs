//! `ferrosid` command-line entry point; all logic lives in the library (`ferrosid::cli`).
use clap::Parser;
use std::io::{IsTerminal as _, Write as _};

fn main() {
    raise_malloc_thresholds();
    let cli = match ferrosid::cli::Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => exit_after_clap(&e),
    };
    match ferrosid::cli::run(&cli) {
        Ok(code) => std::process::exit(code as i32),
        Err(e) => fail(&e),
    }
}

/// Prints an error (bounded and printable whatever the input was: no 50 MB field on the
/// terminal) and exits with its documented code. A closed stderr is not a reason to panic.
fn fail(e: &ferrosid::Error) -> ! {
    let msg = ferrosid::cli::tidy_numbers(&e.to_string());
    let lines: Vec<String> = msg
        .lines()
        .take(60)
        .map(|l| ferrosid::error::excerpt_n(l, 2000))
        .collect();
    let _ = writeln!(std::io::stderr().lock(), "error: {}", lines.join("\n"));
    std::process::exit(ferrosid::cli::exit_code_for(e));
}

/// `--help`, `--version` and usage errors from clap. Help and version go to stdout through
/// the one stdout writer of every command ([`ferrosid::cli::output::emit`]): a closed pipe
/// ends quietly, any other write error (a full disk) exits 3 with a message instead of 0.
fn exit_after_clap(e: &clap::Error) -> ! {
    let code = e.exit_code();
    if e.use_stderr() {
        let _ = e.print();
        std::process::exit(code);
    }
    if std::io::stdout().is_terminal() {
        // Coloured as clap draws it on a terminal.
        let _ = e.print();
        let _ = std::io::stdout().flush();
        std::process::exit(code);
    }
    match ferrosid::cli::output::emit(&e.render().to_string()) {
        Ok(()) => std::process::exit(code),
        Err(err) => fail(&err),
    }
}
/// Lets freed memory be reused instead of returned to the system and faulted in again.
///
/// glibc's malloc serves blocks above its mmap threshold (128 KiB at start) with a fresh
/// `mmap` and unmaps them when freed, so every 100k-sample column (800 KB) that a command
/// allocates after another was freed arrives as new pages, each a page fault (about 3 µs on
/// the benchmark machine). Freeing an mmapped block raises the threshold to that block's size
/// and the heap's trim threshold to twice it (mallopt(3), "dynamic mmap threshold"): one
/// untouched 16 MiB block, allocated and freed here, makes blocks up to 16 MiB come from the
/// heap, where freed memory is kept and reused. No page of it is touched. Other allocators
/// just allocate and free it. On the 100k-sample peer log, `identify` had about 5,200 page
/// faults without it and 4,200 with it (perf stat), with the same output.
fn raise_malloc_thresholds() {
    let block: Vec<u8> = Vec::with_capacity(16 << 20);
    // Not optimised away: the allocation and its free are the point.
    drop(std::hint::black_box(block));
}
