//! The program's code fingerprint: a hash of the source files built into `amrepro`,
//! computed by `build.rs` at build time (which includes this file as a module) and
//! given to the stage registry, so that the stage cache reruns every stage when the
//! code changes (ARCHITECTURE.md, the cache invariant). A kind's version says *that*
//! its outputs changed; the fingerprint catches the change nobody versioned.
//!
//! The files are those of the workspace's members (the root `Cargo.toml`'s
//! `members`): the root's `Cargo.toml`, `Cargo.lock` and `src/`, and every other
//! member's folder except what is not built into the program (its `tests/`,
//! `benches/`, `examples/`, `target/` and hidden entries). Contents and relative paths
//! count, not modification times. The build counts too ([`toolchain`]): the
//! compiler's `rustc -vV` (its release, commit and LLVM), the target triple and the
//! `RUSTFLAGS` given, so a new compiler or other code-generation flags rerun every
//! stage instead of serving tables another build computed. The same checkout built by
//! the same toolchain gives the same fingerprint on any machine, which a run spread
//! over machines needs (docs/SCALE.md). Not covered: environment variables read at
//! build time (none today).
//!
//! Hand-written: Cargo gives a build script no hash of a package's sources.

use std::fs;
use std::io;
use std::path::{Path, PathBuf};

use sha2::{Digest, Sha256};

/// Sub-folders of a member that are not built into the program.
const NOT_BUILT: [&str; 4] = ["tests", "benches", "examples", "target"];

/// Hex digits of the fingerprint (64 bits of SHA-256).
const DIGITS: usize = 16;

/// What the fingerprint covers, for `build.rs` to watch: the files it hashed (relative
/// to the workspace root, sorted) and the folders whose new files would change it.
#[derive(Debug)]
pub struct Sources {
    /// Every hashed file, relative to the root.
    pub files: Vec<PathBuf>,
    /// The folders walked (relative), for Cargo's `rerun-if-changed`.
    pub folders: Vec<PathBuf>,
}

/// The workspace members named in `root/Cargo.toml`: the `members = [".", "pipeline",
/// …]` list of its `[workspace]` table (comments ignored).
pub fn members(root: &Path) -> io::Result<Vec<String>> {
    let manifest = root.join("Cargo.toml");
    let text = fs::read_to_string(&manifest)?;
    let invalid = |why: &str| io::Error::new(io::ErrorKind::InvalidData, format!("{}: {why}", manifest.display()));
    let code: String = text.lines().map(|l| l.split('#').next().unwrap_or("")).collect::<Vec<_>>().join("\n");
    let workspace = &code[code.find("[workspace]").ok_or_else(|| invalid("no `[workspace]` table"))?..];
    let start = workspace.find("members").ok_or_else(|| invalid("no workspace `members`"))?;
    let list = &workspace[start..];
    let (open, close) = (list.find('[').ok_or_else(|| invalid("`members` is not a list"))?, list.find(']'));
    let close = close.filter(|&c| c > open).ok_or_else(|| invalid("`members` list is not closed"))?;
    let names: Vec<String> = list[open + 1..close]
        .split(',')
        .map(|s| s.trim().trim_matches('"').to_string())
        .filter(|s| !s.is_empty())
        .collect();
    if names.is_empty() {
        return Err(invalid("`members` is empty"));
    }
    Ok(names)
}

/// The files and folders the fingerprint covers (module docs).
pub fn sources(root: &Path) -> io::Result<Sources> {
    let mut out = Sources { files: Vec::new(), folders: Vec::new() };
    for member in members(root)? {
        if member == "." {
            out.files.extend([PathBuf::from("Cargo.toml"), PathBuf::from("Cargo.lock")]);
            walk(root, Path::new("src"), &mut out)?;
        } else {
            walk(root, Path::new(&member), &mut out)?;
        }
    }
    out.files.sort();
    out.files.dedup();
    Ok(out)
}

fn walk(root: &Path, rel: &Path, out: &mut Sources) -> io::Result<()> {
    out.folders.push(rel.to_path_buf());
    for entry in fs::read_dir(root.join(rel))? {
        let entry = entry?;
        let name = entry.file_name();
        let name = name.to_string_lossy();
        if name.starts_with('.') {
            continue;
        }
        let path = rel.join(&*name);
        if entry.file_type()?.is_dir() {
            if !NOT_BUILT.contains(&&*name) {
                walk(root, &path, out)?;
            }
        } else {
            out.files.push(path);
        }
    }
    Ok(())
}

/// One line naming the build: `rustc_verbose_version` (the output of `rustc -vV`, its
/// lines joined by `; `), the target triple and the encoded `RUSTFLAGS` (Cargo's
/// `CARGO_ENCODED_RUSTFLAGS`, flags separated by `0x1f`, shown separated by spaces).
pub fn toolchain(rustc_verbose_version: &str, target: &str, encoded_rustflags: &str) -> String {
    let rustc: Vec<&str> = rustc_verbose_version.lines().map(str::trim).filter(|l| !l.is_empty()).collect();
    let flags: Vec<&str> = encoded_rustflags.split('\x1f').filter(|f| !f.is_empty()).collect();
    format!("{}; target: {target}; rustflags: [{}]", rustc.join("; "), flags.join(" "))
}

/// The fingerprint of `files` under `root` built by `toolchain` ([`toolchain`]):
/// SHA-256 over the toolchain line, then each file's relative path (with `/`
/// separators), its length and its bytes, in the given order; the first [`DIGITS`] hex
/// digits.
pub fn fingerprint(root: &Path, files: &[PathBuf], toolchain: &str) -> io::Result<String> {
    let mut hasher = Sha256::new();
    hasher.update((toolchain.len() as u64).to_le_bytes());
    hasher.update(toolchain.as_bytes());
    for rel in files {
        let bytes = fs::read(root.join(rel))?;
        let name: Vec<String> = rel.components().map(|c| c.as_os_str().to_string_lossy().into_owned()).collect();
        hasher.update(name.join("/").as_bytes());
        hasher.update([0]);
        hasher.update((bytes.len() as u64).to_le_bytes());
        hasher.update(&bytes);
    }
    let digest = hasher.finalize();
    Ok(digest.iter().map(|b| format!("{b:02x}")).collect::<String>()[..DIGITS].to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A workspace of a root crate and two members, one with tests, benches, an asset
    /// and a hidden file.
    fn workspace() -> tempfile::TempDir {
        let dir = tempfile::tempdir().unwrap();
        let put = |rel: &str, text: &str| {
            let path = dir.path().join(rel);
            fs::create_dir_all(path.parent().unwrap()).unwrap();
            fs::write(path, text).unwrap();
        };
        let manifest = "# members = [\"old\"]\n[workspace]\nmembers = [\".\", \"core\", # the library\n  \"io\"]\nexclude = [\"fuzz\"]\n";
        put("Cargo.toml", manifest);
        put("Cargo.lock", "lock");
        put("src/main.rs", "fn main() {}");
        put("tests/cli.rs", "#[test] fn t() {}");
        put("core/Cargo.toml", "[package]");
        put("core/src/lib.rs", "pub fn f() {}");
        put("core/assets/font.ttf", "glyphs");
        put("core/tests/t.rs", "#[test] fn t() {}");
        put("core/benches/b.rs", "fn b() {}");
        put("core/.editor.swp", "x");
        put("io/Cargo.toml", "[package]");
        put("io/src/lib.rs", "pub fn g() {}");
        put("fuzz/Cargo.toml", "[package]");
        put("fuzz/fuzz_targets/a.rs", "fn a() {}");
        put("docs/README.md", "docs");
        dir
    }

    const TOOLCHAIN: &str = "rustc 1.90.0 (1159e78c4 2025-09-14); host: x86_64-unknown-linux-gnu; target: x86_64-unknown-linux-gnu; rustflags: []";

    fn of(root: &Path) -> String {
        fingerprint(root, &sources(root).unwrap().files, TOOLCHAIN).unwrap()
    }

    #[test]
    fn covers_the_members_built_files_only() {
        let ws = workspace();
        let files: Vec<String> =
            sources(ws.path()).unwrap().files.iter().map(|p| p.to_string_lossy().replace('\\', "/")).collect();
        let expected = [
            "Cargo.lock",
            "Cargo.toml",
            "core/Cargo.toml",
            "core/assets/font.ttf",
            "core/src/lib.rs",
            "io/Cargo.toml",
            "io/src/lib.rs",
            "src/main.rs",
        ];
        assert_eq!(files, expected);
    }

    #[test]
    fn changes_with_a_built_file_and_with_nothing_else() {
        let ws = workspace();
        let before = of(ws.path());
        assert_eq!(before.len(), DIGITS);
        assert!(before.chars().all(|c| c.is_ascii_hexdigit()), "{before}");
        // Not built into the program: tests, benches, docs, a non-member, hidden files.
        for rel in ["tests/cli.rs", "core/tests/t.rs", "core/benches/b.rs", "docs/README.md", "fuzz/fuzz_targets/a.rs"]
        {
            fs::write(ws.path().join(rel), "changed").unwrap();
        }
        fs::write(ws.path().join("core/.editor.swp"), "changed").unwrap();
        assert_eq!(of(ws.path()), before);
        // Rewriting a file with the same bytes (a new modification time) changes nothing.
        fs::write(ws.path().join("core/src/lib.rs"), "pub fn f() {}").unwrap();
        assert_eq!(of(ws.path()), before);
        // Any built file, an asset and the lock file included, changes it.
        for (rel, text) in
            [("core/src/lib.rs", "pub fn f() { }"), ("core/assets/font.ttf", "glyph"), ("Cargo.lock", "l")]
        {
            let ws = workspace();
            fs::write(ws.path().join(rel), text).unwrap();
            assert_ne!(of(ws.path()), before, "{rel}");
        }
        // A new source file, and a file moved to another path with the same bytes.
        let ws = workspace();
        fs::write(ws.path().join("io/src/extra.rs"), "").unwrap();
        assert_ne!(of(ws.path()), before);
        let ws = workspace();
        fs::rename(ws.path().join("io/src/lib.rs"), ws.path().join("io/src/main.rs")).unwrap();
        assert_ne!(of(ws.path()), before);
    }

    #[test]
    fn a_manifest_without_workspace_members_is_an_error_naming_it() {
        let dir = tempfile::tempdir().unwrap();
        fs::write(dir.path().join("Cargo.toml"), "[package]\nname = \"x\"\n").unwrap();
        let err = sources(dir.path()).unwrap_err().to_string();
        assert!(err.contains("Cargo.toml") && err.contains("[workspace]"), "{err}");
        fs::write(dir.path().join("Cargo.toml"), "[workspace]\nresolver = \"2\"\n").unwrap();
        let err = sources(dir.path()).unwrap_err().to_string();
        assert!(err.contains("Cargo.toml") && err.contains("members"), "{err}");
    }

    #[test]
    fn this_workspace_covers_every_library_crate() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let files = sources(root).unwrap().files;
        for rel in ["Cargo.lock", "src/main.rs", "pipeline/src/cache.rs", "models/src/fdm/fit.rs", "reports/assets"] {
            assert!(files.iter().any(|f| f.starts_with(rel)), "{rel} not covered");
        }
        assert!(!files.iter().any(|f| f.starts_with("tests") || f.starts_with("fuzz") || f.starts_with("docs")));
        // The program's own fingerprint is this checkout's, built by this toolchain.
        let built_by = env!("AMREPRO_TOOLCHAIN");
        assert!(built_by.starts_with("rustc ") && built_by.contains("; target: "), "{built_by}");
        assert_eq!(env!("AMREPRO_CODE_FINGERPRINT"), fingerprint(root, &files, built_by).unwrap());
    }

    #[test]
    fn another_compiler_or_other_flags_change_it() {
        let ws = workspace();
        let files = sources(ws.path()).unwrap().files;
        let rustc = "rustc 1.90.0 (1159e78c4 2025-09-14)\nbinary: rustc\nhost: x86_64-unknown-linux-gnu\nLLVM version: 20.1.8\n";
        let line = toolchain(rustc, "x86_64-unknown-linux-gnu", "");
        assert_eq!(
            line,
            "rustc 1.90.0 (1159e78c4 2025-09-14); binary: rustc; host: x86_64-unknown-linux-gnu; \
             LLVM version: 20.1.8; target: x86_64-unknown-linux-gnu; rustflags: []"
        );
        let base = fingerprint(ws.path(), &files, &line).unwrap();
        let newer = toolchain(&rustc.replace("1.90.0", "1.91.0"), "x86_64-unknown-linux-gnu", "");
        let flags = toolchain(rustc, "x86_64-unknown-linux-gnu", "-C\x1ftarget-cpu=native");
        assert_eq!(flags, line.replace("rustflags: []", "rustflags: [-C target-cpu=native]"));
        let other_target = toolchain(rustc, "aarch64-unknown-linux-gnu", "");
        for other in [newer, flags, other_target] {
            assert_ne!(fingerprint(ws.path(), &files, &other).unwrap(), base, "{other}");
        }
        assert_eq!(fingerprint(ws.path(), &files, &line).unwrap(), base);
    }
}
