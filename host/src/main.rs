//! `ferrosid` command-line entry point; all logic lives in the library (`ferrosid::cli`).
use clap::Parser;

fn main() {
    let cli = ferrosid::cli::Cli::parse();
    match ferrosid::cli::run(&cli) {
        Ok(code) => std::process::exit(code as i32),
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(ferrosid::cli::exit_code_for(&e));
        }
    }
}
