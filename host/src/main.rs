//! `ferrosid` command-line entry point; all logic lives in the library (`ferrosid::cli`).
use clap::Parser;

fn main() {
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
