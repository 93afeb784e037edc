//! Build script of the `amrepro` binary: computes the program's code fingerprint
//! (`src/code_fingerprint.rs`: the sources and the toolchain building them) into
//! `AMREPRO_CODE_FINGERPRINT`, the toolchain's line into `AMREPRO_TOOLCHAIN`, each
//! crate's code (its own and its workspace dependencies' sources, the lock file, the
//! workspace manifest and the toolchain), which the stage kinds of that crate are cached
//! on, into `$OUT_DIR/code_by_crate.rs`, and
//! asks Cargo to run again when any file it covers, or any folder it walked, changes,
//! or `RUSTFLAGS` in the environment. A new compiler rebuilds this script and so runs
//! it again; flags given only in a Cargo config file for a `--target` build are not
//! watched (they do not rebuild a build script).

#[path = "src/code_fingerprint.rs"]
mod code_fingerprint;

use std::path::PathBuf;
use std::process::Command;

/// The toolchain line of [`code_fingerprint::toolchain`] for this build, from what Cargo
/// tells a build script: the compiler (`RUSTC`), `TARGET` and `CARGO_ENCODED_RUSTFLAGS`.
fn this_toolchain() -> String {
    let var = |name: &str| std::env::var(name).unwrap_or_default();
    let rustc = std::env::var_os("RUSTC").unwrap_or_else(|| "rustc".into());
    let output = Command::new(&rustc)
        .arg("-vV")
        .output()
        .unwrap_or_else(|e| panic!("the code fingerprint cannot run `{} -vV`: {e}", rustc.to_string_lossy()));
    if !output.status.success() {
        panic!("the code fingerprint: `{} -vV` failed: {}", rustc.to_string_lossy(), output.status);
    }
    let version = String::from_utf8_lossy(&output.stdout);
    code_fingerprint::toolchain(&version, &var("TARGET"), &var("CARGO_ENCODED_RUSTFLAGS"))
}

fn main() {
    let root = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").expect("Cargo sets CARGO_MANIFEST_DIR"));
    let sources = code_fingerprint::sources(&root)
        .unwrap_or_else(|e| panic!("the code fingerprint cannot list the workspace's sources: {e}"));
    let toolchain = this_toolchain();
    let fingerprint = code_fingerprint::fingerprint(&root, &sources.files, &toolchain)
        .unwrap_or_else(|e| panic!("the code fingerprint cannot read the workspace's sources: {e}"));
    let by_crate = code_fingerprint::code_by_crate(&root, &toolchain)
        .unwrap_or_else(|e| panic!("the code fingerprint cannot hash the workspace's crates: {e}"));
    let out = PathBuf::from(std::env::var_os("OUT_DIR").expect("Cargo sets OUT_DIR")).join("code_by_crate.rs");
    std::fs::write(&out, code_fingerprint::code_by_crate_source(&by_crate))
        .unwrap_or_else(|e| panic!("the code fingerprint cannot write {}: {e}", out.display()));
    let listed: Vec<String> = by_crate.iter().map(|(name, code)| format!("{name} {}", code.fingerprint)).collect();
    println!("cargo:rustc-env=AMREPRO_CODE_FINGERPRINT={fingerprint}");
    println!("cargo:rustc-env=AMREPRO_CODE_BY_CRATE={}", listed.join(", "));
    println!("cargo:rustc-env=AMREPRO_TOOLCHAIN={toolchain}");
    println!("cargo:rerun-if-env-changed=RUSTFLAGS");
    for path in sources.files.iter().chain(&sources.folders) {
        println!("cargo:rerun-if-changed={}", path.display());
    }
}
