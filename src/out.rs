//! Printing to standard output without a panic on a closed pipe.
//!
//! `amrepro stages | head` closes the pipe after ten lines, and the next write fails with
//! a broken pipe (Rust ignores SIGPIPE, so the write returns EPIPE). `println!` panics on
//! that, which the CLI reported as an internal error. [`outln!`] and [`out!`] return it
//! instead, as [`StdoutClosed`]: `main` ends the command there quietly with status 0, as
//! ripgrep does, since the reader has all it asked for. Any other failed write to standard
//! output is an error that names it.

use std::fmt;
use std::io::ErrorKind;

/// Standard output was closed by its reader (a broken pipe): not a failure of the command.
#[derive(Debug)]
pub struct StdoutClosed;

impl fmt::Display for StdoutClosed {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("standard output was closed by its reader")
    }
}

impl std::error::Error for StdoutClosed {}

/// The outcome of a write to standard output: a broken pipe is [`StdoutClosed`].
pub fn checked(written: std::io::Result<()>) -> anyhow::Result<()> {
    written.map_err(|e| match e.kind() {
        ErrorKind::BrokenPipe => anyhow::Error::new(StdoutClosed),
        _ => anyhow::Error::new(e).context("writing to standard output"),
    })
}

/// Whether `err` is, or was caused by, a closed standard output.
pub fn is_closed(err: &anyhow::Error) -> bool {
    err.chain().any(|cause| cause.is::<StdoutClosed>())
}

/// `println!` that returns a failed write (`anyhow::Result<()>`) instead of panicking.
macro_rules! outln {
    ($($arg:tt)*) => {
        $crate::out::checked({
            use std::io::Write as _;
            writeln!(std::io::stdout().lock(), $($arg)*)
        })
    };
}

/// `print!` that returns a failed write (`anyhow::Result<()>`) instead of panicking.
macro_rules! out {
    ($($arg:tt)*) => {
        $crate::out::checked({
            use std::io::Write as _;
            write!(std::io::stdout().lock(), $($arg)*)
        })
    };
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_broken_pipe_is_a_closed_stdout_and_other_errors_name_it() {
        let closed = checked(Err(std::io::Error::from(ErrorKind::BrokenPipe))).unwrap_err();
        assert!(is_closed(&closed));
        assert!(is_closed(&closed.context("listing the stages")));
        let full = checked(Err(std::io::Error::other("disk full"))).unwrap_err();
        assert!(!is_closed(&full));
        assert_eq!(format!("{full:#}"), "writing to standard output: disk full");
    }
}
