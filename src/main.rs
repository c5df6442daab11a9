//! `skinbox`: one command for the interface box of an event-based robot skin.

mod commands;

use clap::Parser;

fn main() -> std::process::ExitCode {
    let cli = commands::Cli::parse();
    match commands::run(cli) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("skinbox: error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
