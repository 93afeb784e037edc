//! Build script of the `amrepro` binary: computes the program's code fingerprint
//! (`src/code_fingerprint.rs`) into `AMREPRO_CODE_FINGERPRINT`, and asks Cargo to run
//! again when any file it covers, or any folder it walked, changes.

#[path = "src/code_fingerprint.rs"]
mod code_fingerprint;

use std::path::PathBuf;

fn main() {
    let root = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").expect("Cargo sets CARGO_MANIFEST_DIR"));
    let sources = code_fingerprint::sources(&root)
        .unwrap_or_else(|e| panic!("the code fingerprint cannot list the workspace's sources: {e}"));
    let fingerprint = code_fingerprint::fingerprint(&root, &sources.files)
        .unwrap_or_else(|e| panic!("the code fingerprint cannot read the workspace's sources: {e}"));
    println!("cargo:rustc-env=AMREPRO_CODE_FINGERPRINT={fingerprint}");
    for path in sources.files.iter().chain(&sources.folders) {
        println!("cargo:rerun-if-changed={}", path.display());
    }
}
