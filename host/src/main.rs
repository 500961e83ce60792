//! `ferrosid` command-line entry point; all logic lives in the library (`ferrosid::cli`).
use clap::Parser;

fn main() {
    raise_malloc_thresholds();
    let cli = ferrosid::cli::Cli::parse();
    match ferrosid::cli::run(&cli) {
        Ok(code) => std::process::exit(code as i32),
        Err(e) => {
            // Bounded and printable whatever the input was (no 50 MB field on the terminal).
            let msg = e.to_string();
            let lines: Vec<String> = msg
                .lines()
                .take(60)
                .map(|l| ferrosid::error::excerpt_n(l, 2000))
                .collect();
            eprintln!("error: {}", lines.join("\n"));
            std::process::exit(ferrosid::cli::exit_code_for(&e));
        }
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
