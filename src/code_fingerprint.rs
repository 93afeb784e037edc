//! The code fingerprints: hashes of the source files built into `amrepro`, computed by
//! `build.rs` at build time (which includes this file as a module), so that the stage
//! cache reruns a stage when the code it runs changes, and only then (ARCHITECTURE.md,
//! the cache invariant). A kind's version says *that* its outputs changed; the
//! fingerprint catches the change nobody versioned.
//!
//! **A stage kind's fingerprint is the code of its crate** ([`code_by_crate`]): the
//! crate that defines the kind (`stages`, `reports`, `pipeline` for `test.fault`) and
//! every workspace member it depends on to build, transitively (its `[dependencies]`
//! and `[build-dependencies]` on members, read from the members' `Cargo.toml`; not its
//! `[dev-dependencies]`), each member hashed on its own; plus `Cargo.lock` (every
//! external crate's version), the root manifest's workspace-wide tables (shared
//! dependency versions and features, profiles: what every member's build reads; not the
//! root package's own tables, such as its `[[test]]` list) and the toolchain. So a
//! change in `reports` reruns the `figure.*` and `report.*` kinds and no `stages` kind,
//! and a change in `models` reruns every kind of `stages` and of `reports` (both depend
//! on it). The root crate's own `src/` (the CLI) is in no kind's code: it parses
//! arguments and assembles the registry, and what it hands a stage — parameters, seed,
//! inputs — is in the stage's cache key itself.
//!
//! A member's files are its folder's except what is not built into the program (its
//! `tests/`, `benches/`, `examples/`, `target/` and hidden entries); for the root, its
//! `src/`. Contents and relative paths count, not modification times. The build counts
//! too ([`toolchain`]): the compiler's `rustc -vV` (its release, commit and LLVM), the
//! target triple and the `RUSTFLAGS` given, so a new compiler or other code-generation
//! flags rerun every stage instead of serving tables another build computed. The same
//! checkout built by the same toolchain gives the same fingerprints on any machine,
//! which a run spread over machines needs (docs/SCALE.md). Not covered: environment
//! variables read at build time (none today).
//!
//! The whole program's fingerprint ([`sources`], [`fingerprint`]: every member's files,
//! the root's `Cargo.toml` and `Cargo.lock`) is what `amrepro --version` names first.
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

/// The name of the part holding the lock file (every kind's code has it).
pub const LOCK_PART: &str = "Cargo.lock";
/// The name of the part holding the root manifest's workspace-wide tables.
pub const WORKSPACE_PART: &str = "workspace";
/// The name of the part holding the toolchain line.
pub const TOOLCHAIN_PART: &str = "toolchain";

/// Tables of the root `Cargo.toml` that concern only the root package (the binary and
/// its tests), not the code of any other member.
const ROOT_PACKAGE_TABLES: [&str; 10] = [
    "package",
    "bin",
    "test",
    "bench",
    "example",
    "dependencies",
    "dev-dependencies",
    "build-dependencies",
    "lints",
    "badges",
];

/// The code of one crate as a stage kind's cache key sees it: the fingerprint of its
/// parts, and the parts by name (the crate and every workspace member it depends on,
/// transitively, each with the hash of its built files; [`LOCK_PART`],
/// [`WORKSPACE_PART`] and [`TOOLCHAIN_PART`]).
#[derive(Debug, Clone, PartialEq)]
pub struct CrateCode {
    /// [`DIGITS`] hex digits over the parts.
    pub fingerprint: String,
    /// Part name → its hash.
    pub parts: std::collections::BTreeMap<String, String>,
}

/// A member's crate name: its folder, the root's `[package] name` for `.` (folder
/// name = crate name, CONVENTIONS.md).
fn crate_name(root: &Path, member: &str) -> io::Result<String> {
    if member != "." {
        return Ok(member.replace('-', "_"));
    }
    let manifest = root.join("Cargo.toml");
    let text = fs::read_to_string(&manifest)?;
    let package = tables(&text).into_iter().find(|(name, _)| name == "package").map(|(_, body)| body);
    let name = package.as_deref().and_then(|body| {
        body.lines().find_map(|l| {
            let (key, value) = l.split_once('=')?;
            (key.trim() == "name").then(|| value.trim().trim_matches('"').replace('-', "_"))
        })
    });
    name.ok_or_else(|| io::Error::new(io::ErrorKind::InvalidData, format!("{}: no package name", manifest.display())))
}

/// A manifest's tables in order: the header's name (`dependencies`, `bin` for
/// `[[bin]]`, `dependencies.x` for `[dependencies.x]`) and its text (the header's line
/// included; comments dropped). Text before the first header is the table "".
fn tables(text: &str) -> Vec<(String, String)> {
    let mut out = vec![(String::new(), String::new())];
    for line in text.lines() {
        let code = line.split('#').next().unwrap_or("");
        let trimmed = code.trim();
        if trimmed.starts_with('[') {
            let name = trimmed.trim_matches(|c| c == '[' || c == ']').trim().to_string();
            out.push((name, String::new()));
        }
        let body = &mut out.last_mut().expect("one table at least").1;
        body.push_str(code);
        body.push('\n');
    }
    out
}

/// The workspace members `member`'s manifest depends on to build (its
/// `[dependencies]`, `[build-dependencies]` and target-specific ones; not its
/// `[dev-dependencies]`, which only its tests see, nor the root's
/// `[workspace.dependencies]`), among `crates`.
fn member_dependencies(root: &Path, member: &str, crates: &[String]) -> io::Result<Vec<String>> {
    let text = fs::read_to_string(root.join(member).join("Cargo.toml"))?;
    let mut deps = Vec::new();
    for (table, body) in tables(&text) {
        let kind = table.rsplit('.').find(|s| s.ends_with("dependencies")).unwrap_or("");
        let inline = table.split('.').position(|s| s.ends_with("dependencies"));
        if kind.is_empty() || kind == "dev-dependencies" || table.starts_with("workspace") {
            continue;
        }
        // `[dependencies.name]` names the dependency in its header.
        let parts: Vec<&str> = table.split('.').collect();
        if let Some(i) = inline.filter(|&i| i + 1 < parts.len()) {
            deps.push(parts[i + 1].trim_matches('"').to_string());
            continue;
        }
        for line in body.lines().skip(1) {
            let Some((key, value)) = line.split_once('=') else { continue };
            let key = key.trim().split('.').next().unwrap_or("").trim_matches('"').to_string();
            // A renamed dependency names its package.
            let package = value.split("package").nth(1).and_then(|v| v.split('"').nth(1)).map(str::to_string);
            deps.push(package.unwrap_or(key));
        }
    }
    let mut deps: Vec<String> = deps.into_iter().map(|d| d.replace('-', "_")).filter(|d| crates.contains(d)).collect();
    deps.sort();
    deps.dedup();
    Ok(deps)
}

/// The text of the root manifest that every member's build reads: its tables other
/// than the root package's own ([`ROOT_PACKAGE_TABLES`]): `[workspace]`,
/// `[workspace.dependencies]` (versions and features), `[profile.*]`, `[patch.*]`.
fn workspace_manifest(root: &Path) -> io::Result<String> {
    let text = fs::read_to_string(root.join("Cargo.toml"))?;
    let shared = tables(&text).into_iter().filter(|(name, _)| {
        let head = name.split('.').next().unwrap_or("");
        !ROOT_PACKAGE_TABLES.contains(&head) && !name.is_empty()
    });
    Ok(shared.map(|(_, body)| body).collect())
}

fn sha_hex(chunks: &[&[u8]]) -> String {
    let mut hasher = Sha256::new();
    for chunk in chunks {
        hasher.update((chunk.len() as u64).to_le_bytes());
        hasher.update(chunk);
    }
    hasher.finalize().iter().map(|b| format!("{b:02x}")).collect::<String>()[..DIGITS].to_string()
}

/// Every crate's code (module docs): per workspace member, the parts its build reads
/// and their fingerprint. A change in one member changes the code of that member and of
/// the members depending on it, and of no other.
pub fn code_by_crate(root: &Path, toolchain: &str) -> io::Result<std::collections::BTreeMap<String, CrateCode>> {
    use std::collections::{BTreeMap, BTreeSet};
    let members = members(root)?;
    let names: Vec<String> = members.iter().map(|m| crate_name(root, m)).collect::<io::Result<_>>()?;
    let mut part_hash = BTreeMap::new();
    let mut direct = BTreeMap::new();
    for (member, name) in members.iter().zip(&names) {
        let mut files = Sources { files: Vec::new(), folders: Vec::new() };
        if member == "." {
            walk(root, Path::new("src"), &mut files)?;
        } else {
            walk(root, Path::new(member), &mut files)?;
        }
        files.files.sort();
        part_hash.insert(name.clone(), fingerprint(root, &files.files, "")?);
        direct.insert(name.clone(), member_dependencies(root, member, &names)?);
    }
    part_hash.insert(LOCK_PART.into(), fingerprint(root, &[PathBuf::from("Cargo.lock")], "")?);
    part_hash.insert(WORKSPACE_PART.into(), sha_hex(&[workspace_manifest(root)?.as_bytes()]));
    part_hash.insert(TOOLCHAIN_PART.into(), sha_hex(&[toolchain.as_bytes()]));
    let mut out = BTreeMap::new();
    for name in &names {
        let mut closure = BTreeSet::from([name.clone()]);
        let mut todo = vec![name.clone()];
        while let Some(next) = todo.pop() {
            for dep in &direct[&next] {
                if closure.insert(dep.clone()) {
                    todo.push(dep.clone());
                }
            }
        }
        closure.extend([LOCK_PART.to_string(), WORKSPACE_PART.into(), TOOLCHAIN_PART.into()]);
        let parts: BTreeMap<String, String> = closure.into_iter().map(|p| (p.clone(), part_hash[&p].clone())).collect();
        out.insert(name.clone(), CrateCode { fingerprint: parts_fingerprint(&parts), parts });
    }
    Ok(out)
}

/// The fingerprint over parts (name and hash each), in name order.
pub fn parts_fingerprint(parts: &std::collections::BTreeMap<String, String>) -> String {
    let chunks: Vec<&[u8]> = parts.iter().flat_map(|(n, h)| [n.as_bytes(), h.as_bytes()]).collect();
    sha_hex(&chunks)
}

/// Rust source of `code` as a constant expression of type
/// `&[(&str, &str, &[(&str, &str)])]`: per crate its name, fingerprint and parts, for
/// the binary to `include!`.
pub fn code_by_crate_source(code: &std::collections::BTreeMap<String, CrateCode>) -> String {
    let mut s = String::from("&[\n");
    for (name, c) in code {
        let parts: Vec<String> = c.parts.iter().map(|(p, h)| format!("({p:?}, {h:?})")).collect();
        s += &format!("    ({name:?}, {:?}, &[{}]),\n", c.fingerprint, parts.join(", "));
    }
    s + "]\n"
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
        let manifest = "# members = [\"old\"]\n[workspace]\nmembers = [\".\", \"core\", # the library\n  \"io\"]\nexclude = [\"fuzz\"]\n\
                        [workspace.dependencies]\ncore = { path = \"core\" }\nrand = \"0.9\"\n\
                        [package]\nname = \"app\"\n[dependencies]\nio = { path = \"io\" }\n[[test]]\nname = \"cli\"\n\
                        [profile.release]\ndebug = false\n";
        put("Cargo.toml", manifest);
        put("Cargo.lock", "lock");
        put("src/main.rs", "fn main() {}");
        put("tests/cli.rs", "#[test] fn t() {}");
        put("core/Cargo.toml", "[package]\nname = \"core\"\n[dev-dependencies]\nio.workspace = true\n");
        put("core/src/lib.rs", "pub fn f() {}");
        put("core/assets/font.ttf", "glyphs");
        put("core/tests/t.rs", "#[test] fn t() {}");
        put("core/benches/b.rs", "fn b() {}");
        put("core/.editor.swp", "x");
        put(
            "io/Cargo.toml",
            "[package]\nname = \"io\"\n[dependencies]\ncore.workspace = true\nrand.workspace = true\n",
        );
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

    /// Each crate's code fingerprint in the workspace at `root`.
    fn codes(root: &Path) -> std::collections::BTreeMap<String, String> {
        code_by_crate(root, TOOLCHAIN).unwrap().into_iter().map(|(name, c)| (name, c.fingerprint)).collect()
    }

    /// The crates whose code differs between `before` and the workspace at `root`.
    fn changed(before: &std::collections::BTreeMap<String, String>, root: &Path) -> Vec<String> {
        let after = codes(root);
        assert_eq!(after.keys().collect::<Vec<_>>(), before.keys().collect::<Vec<_>>());
        after.into_iter().filter(|(name, code)| before[name] != *code).map(|(name, _)| name).collect()
    }

    #[test]
    fn a_crates_code_is_its_own_sources_and_those_it_depends_on() {
        let ws = workspace();
        let code = code_by_crate(ws.path(), TOOLCHAIN).unwrap();
        let parts = |name: &str| code[name].parts.keys().cloned().collect::<Vec<_>>();
        // `io` builds on `core`; `core` only tests with `io` (a dev-dependency).
        assert_eq!(parts("core"), ["Cargo.lock", "core", "toolchain", "workspace"]);
        assert_eq!(parts("io"), ["Cargo.lock", "core", "io", "toolchain", "workspace"]);
        assert_eq!(parts("app"), ["Cargo.lock", "app", "core", "io", "toolchain", "workspace"]);
        assert_eq!(code["io"].fingerprint, parts_fingerprint(&code["io"].parts));
        // What build.rs writes for the binary to include.
        let source = code_by_crate_source(&code);
        let io_line = format!(
            "(\"io\", \"{}\", &[(\"Cargo.lock\", \"{}\"), ",
            code["io"].fingerprint, code["io"].parts["Cargo.lock"]
        );
        assert!(source.starts_with("&[\n") && source.contains(&io_line), "{source}");
        let before = codes(ws.path());
        let edit = |rel: &str, text: &str| {
            let ws = workspace();
            let path = ws.path().join(rel);
            let old = fs::read_to_string(&path).unwrap_or_default();
            fs::write(&path, old + text).unwrap();
            changed(&before, ws.path())
        };
        assert_eq!(edit("core/src/lib.rs", "// a comment"), ["app", "core", "io"]);
        assert_eq!(edit("io/src/lib.rs", "// a comment"), ["app", "io"]);
        assert_eq!(edit("src/main.rs", "// a comment"), ["app"]);
        assert_eq!(edit("core/assets/font.ttf", "x"), ["app", "core", "io"]);
        // Every crate's: the lock file, the shared manifest tables, the toolchain.
        assert_eq!(edit("Cargo.lock", "x"), ["app", "core", "io"]);
        assert_eq!(edit("Cargo.toml", "[workspace.lints.rust]\nunsafe_code = \"forbid\"\n"), ["app", "core", "io"]);
        assert_eq!(edit("Cargo.toml", "[profile.bench]\ninherits = \"release\"\n"), ["app", "core", "io"]);
        let other = toolchain("rustc 1.91.0", "x86_64-unknown-linux-gnu", "");
        let ws = workspace();
        let moved = code_by_crate(ws.path(), &other).unwrap();
        assert!(moved.iter().all(|(name, c)| c.fingerprint != before[name]));
        // No crate's: the root package's own tables, tests, benches, docs.
        assert!(edit("Cargo.toml", "[[test]]\nname = \"other\"\n").is_empty());
        assert!(edit("Cargo.toml", "[dev-dependencies]\ntempfile = \"3\"\n").is_empty());
        for rel in ["tests/cli.rs", "core/tests/t.rs", "core/benches/b.rs", "docs/README.md"] {
            assert!(edit(rel, "// changed").is_empty(), "{rel}");
        }
    }

    /// A copy of this workspace's built files (what the fingerprints read) in a
    /// temporary folder, so that a test can change one crate's source without
    /// touching the real one.
    fn copy_of_this_workspace() -> tempfile::TempDir {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let copy = tempfile::tempdir().unwrap();
        for rel in sources(root).unwrap().files {
            let to = copy.path().join(&rel);
            fs::create_dir_all(to.parent().unwrap()).unwrap();
            fs::copy(root.join(&rel), to).unwrap();
        }
        copy
    }

    /// The kinds of this program (with `test.fault` of `pipeline`) whose code differs
    /// between `before` and `after` (each crate's code), and those whose code does not.
    fn kinds_changed(
        before: &std::collections::BTreeMap<String, CrateCode>,
        after: &std::collections::BTreeMap<String, CrateCode>,
    ) -> (Vec<&'static str>, Vec<&'static str>) {
        let mut registry = crate::commands::registry();
        registry.register(Box::new(pipeline::testing::FaultKind));
        let code = |all: &std::collections::BTreeMap<String, CrateCode>, kind: &dyn pipeline::StageKind| {
            all.get(kind.crate_name()).map(|c| c.fingerprint.clone()).unwrap_or_else(|| panic!("{}", kind.crate_name()))
        };
        let (changed, same): (Vec<_>, Vec<_>) = registry.kinds().partition(|k| code(before, *k) != code(after, *k));
        let names = |kinds: Vec<&dyn pipeline::StageKind>| kinds.iter().map(|k| k.info().name).collect();
        (names(changed), names(same))
    }

    #[test]
    fn a_change_in_one_crate_reruns_the_kinds_that_run_its_code_and_no_other() {
        let built_by = env!("AMREPRO_TOOLCHAIN");
        let ws = copy_of_this_workspace();
        let before = code_by_crate(ws.path(), built_by).unwrap();
        // The copy is this checkout: its code is the build's (as long as nobody edited
        // the sources since the build).
        for (name, fingerprint, _) in crate::commands::CODE_BY_CRATE {
            assert_eq!(before[*name].fingerprint, *fingerprint, "{name}");
        }
        let append = |rel: &str| {
            let path = ws.path().join(rel);
            let text = fs::read_to_string(&path).unwrap();
            fs::write(&path, text.clone() + "\n// one more line\n").unwrap();
            let after = code_by_crate(ws.path(), built_by).unwrap();
            fs::write(&path, text).unwrap();
            after
        };
        // One line in `reports`: only its figure and report kinds.
        let (changed, same) = kinds_changed(&before, &append("reports/src/lib.rs"));
        assert!(!changed.is_empty() && changed.iter().all(|k| k.starts_with("figure.") || k.starts_with("report.")));
        assert!(same.iter().all(|k| !k.starts_with("figure.") && !k.starts_with("report.")), "{same:?}");
        assert!(same.iter().any(|k| k.starts_with("fdm.")) && same.contains(&"test.fault"));
        // One line in `models`: every kind that runs it, those of `stages` and of
        // `reports` (its shared median); not the engine's own `test.fault`.
        let (changed, same) = kinds_changed(&before, &append("models/src/lib.rs"));
        assert_eq!(same, ["test.fault"]);
        for prefix in ["fdm.", "inkjet.", "thermal.", "table.", "figure.", "report."] {
            assert!(changed.iter().any(|k| k.starts_with(prefix)), "{prefix}");
        }
        // One line in `pipeline`: every kind.
        let (_, same) = kinds_changed(&before, &append("pipeline/src/lib.rs"));
        assert!(same.is_empty(), "{same:?}");
        // Back as it was: nothing.
        let (changed, _) = kinds_changed(&before, &code_by_crate(ws.path(), built_by).unwrap());
        assert!(changed.is_empty(), "{changed:?}");
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
