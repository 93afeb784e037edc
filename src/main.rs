//! `amrepro`: the command line. Thin glue over the library crates: it parses
//! arguments, assembles the stage registry, and turns typed library errors into
//! messages with context and a non-zero exit code. A panic anywhere becomes such a
//! message too (`pipeline::panic`), never a Rust panic report. Output goes through
//! `outln!`/`out!` (`out`): a reader that closes standard output early
//! (`amrepro stages | head`) ends the command quietly with status 0.

#[macro_use]
mod out;

mod cli;
#[cfg(test)]
mod code_fingerprint;
mod commands;
mod nightly_run;
mod outputs;
mod pressure_advance;
mod scale;

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    let args = cli::Cli::parse();
    match pipeline::panic::catch(|| commands::dispatch(args)) {
        Ok(Ok(())) => ExitCode::SUCCESS,
        Ok(Err(err)) if out::is_closed(&err) => ExitCode::SUCCESS,
        Ok(Err(err)) => {
            eprintln!("error: {}", chain(&err));
            match err.is::<nightly_run::Regressed>() {
                true => ExitCode::from(nightly_run::REGRESSION_EXIT),
                false => ExitCode::FAILURE,
            }
        }
        Err(panic) => {
            eprintln!(
                "error: internal error, a bug in amrepro (please report it with the input that caused it): {panic}"
            );
            ExitCode::FAILURE
        }
    }
}

/// The error and its causes, `: `-separated, leaving out a cause whose text the
/// message already holds (typed errors often print their source themselves).
fn chain(err: &anyhow::Error) -> String {
    let mut text = String::new();
    for cause in err.chain() {
        let part = cause.to_string();
        if text.contains(&part) {
            continue;
        }
        if !text.is_empty() {
            text += ": ";
        }
        text += &part;
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, thiserror::Error)]
    #[error("stage `a` failed: {source}")]
    struct Outer {
        source: std::io::Error,
    }

    #[test]
    fn a_cause_the_message_already_holds_is_said_once() {
        let err = anyhow::Error::new(Outer { source: std::io::Error::other("disk full") }).context("run of x failed");
        assert_eq!(chain(&err), "run of x failed: stage `a` failed: disk full");
    }
}
