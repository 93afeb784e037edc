//! `amrepro`: the command line. Thin glue over the library crates: it parses
//! arguments, assembles the stage registry, and turns typed library errors into
//! messages with context and a non-zero exit code.

mod cli;
mod commands;

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    let args = cli::Cli::parse();
    match commands::dispatch(args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("error: {err:#}");
            ExitCode::FAILURE
        }
    }
}
