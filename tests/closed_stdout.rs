//! A reader that closes standard output early (`amrepro stages | head`) ends a printing
//! command quietly: status 0, nothing on standard error. Before, the next write's broken
//! pipe made `println!` panic, reported as "internal error, a bug in amrepro".

use std::path::Path;
use std::process::{Command, Stdio};

/// Runs `amrepro args...` in `cwd` with standard output a pipe whose reading end is
/// closed before the program starts, so that its first write fails with a broken pipe.
fn run_with_stdout_closed(cwd: &Path, args: &[&str]) -> (std::process::ExitStatus, String) {
    let (reader, writer) = std::io::pipe().expect("a pipe");
    drop(reader);
    let out = Command::new(env!("CARGO_BIN_EXE_amrepro"))
        .args(args)
        .current_dir(cwd)
        .env_remove("AMREPRO_DATA")
        .stdin(Stdio::null())
        .stdout(writer)
        .stderr(Stdio::piped())
        .output()
        .expect("amrepro runs");
    (out.status, String::from_utf8_lossy(&out.stderr).into_owned())
}

#[test]
fn printing_commands_end_quietly_when_their_reader_has_gone() {
    let tmp = tempfile::tempdir().unwrap();
    let spec = Path::new(env!("CARGO_MANIFEST_DIR")).join("specs/ren2021_virtual.toml");
    let spec = spec.to_str().unwrap();
    let photos = tmp.path().join("photos");
    let generate = [
        "datasets",
        "generate",
        "fdm",
        "--printer",
        "taz6",
        "--seed",
        "1",
        "--conditions",
        "ren2021",
        "--px-per-mm",
        "10",
        "--out",
        photos.to_str().unwrap(),
    ];
    let commands: [&[&str]; 7] = [
        &["stages"],
        &["stages", "--markdown"],
        &["outputs", spec],
        &["outputs", "--markdown", spec],
        &["graph", spec],
        &["plan", spec],
        &generate,
    ];
    for args in commands {
        let (status, stderr) = run_with_stdout_closed(tmp.path(), args);
        assert!(status.success(), "amrepro {args:?} with stdout closed: {status}\n{stderr}");
        assert!(stderr.is_empty(), "amrepro {args:?} with stdout closed said:\n{stderr}");
    }
    // The command's work is done all the same: the dataset was written before the
    // message about it failed to print.
    assert!(photos.join("lines.csv").is_file());
}
