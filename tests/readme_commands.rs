//! README's commands, run in order as printed (issue 18), so that CI (`cargo test --workspace
//! --release`) fails when one stops working.
//!
//! Every ```` ```sh ```` or ```` ```bash ```` block of README.md runs, in order, as one bash
//! script under `set -euo pipefail` in one fresh directory that holds a copy of `examples/`
//! (what a fresh clone's root has that the commands read), with the built `occsim` first on
//! PATH: that is what README's `cargo install --path . --locked` gives, so that line is the
//! one `cargo` command a run block may hold and it does nothing here. A block right after
//! `<!-- readme-test: skip: REASON -->` is not run (the reason is required); other fences
//! (`text`, `rust`, ...) are not commands. Afterwards every file the commands wrote must be
//! one `.gitignore` keeps out of a commit.

mod support;

use std::path::{Path, PathBuf};
use std::time::Instant;

/// One fenced block of a Markdown file.
#[derive(Debug, PartialEq)]
struct Block {
    /// 1-based line of the opening fence.
    line: usize,
    /// The fence's info string (`sh`, `bash`, `text`, ...).
    lang: String,
    text: String,
    /// The reason given by a skip marker right before the fence.
    skip: Option<String>,
}

impl Block {
    fn is_commands(&self) -> bool {
        matches!(self.lang.as_str(), "sh" | "bash")
    }
}

const SKIP_MARKER: &str = "<!-- readme-test: skip:";

/// Every fenced block of `markdown`, or what is wrong with the file's fences or markers.
fn blocks(markdown: &str) -> Result<Vec<Block>, String> {
    let mut blocks = Vec::new();
    let mut open: Option<Block> = None;
    let mut marker: Option<(usize, String)> = None;
    for (index, line) in markdown.lines().enumerate() {
        let number = index + 1;
        if let Some(block) = open.as_mut() {
            if line.trim_start().starts_with("```") {
                blocks.push(open.take().expect("an open block"));
            } else {
                block.text.push_str(line);
                block.text.push('\n');
            }
            continue;
        }
        if let Some(fence) = line.trim_start().strip_prefix("```") {
            open = Some(Block {
                line: number,
                lang: fence.trim().to_string(),
                text: String::new(),
                skip: marker.take().map(|(_, reason)| reason),
            });
            continue;
        }
        if let Some(rest) = line.trim().strip_prefix(SKIP_MARKER) {
            let reason = rest
                .strip_suffix("-->")
                .map(str::trim)
                .filter(|r| !r.is_empty())
                .ok_or(format!(
                    "line {number}: a skip marker is `{SKIP_MARKER} REASON -->` with a reason"
                ))?;
            marker = Some((number, reason.to_string()));
            continue;
        }
        if !line.trim().is_empty() {
            if let Some((at, _)) = marker {
                return Err(format!(
                    "line {at}: a skip marker must come right before a fenced block"
                ));
            }
        }
    }
    if let Some(block) = open {
        return Err(format!("line {}: the block is never closed", block.line));
    }
    if let Some((at, _)) = marker {
        return Err(format!("line {at}: a skip marker with no block after it"));
    }
    Ok(blocks)
}

/// Run before every block: README's install step is what PATH already gives, and any other
/// `cargo` command would rebuild or retest the workspace from inside its own test.
const PREAMBLE: &str = r#"set -euo pipefail
cargo() {
    if [ "$*" = "install --path . --locked" ]; then return 0; fi
    echo "README runs 'cargo $*': only 'cargo install --path . --locked' may run here (the test puts the built occsim first on PATH); give the block a skip marker with its reason" >&2
    return 127
}
"#;

/// Whether `.gitignore`'s `rules` keep a file at the checkout's root named `name` out of a
/// commit: `*` globs, `/` anchoring at the root, `!` re-including; the last match wins.
fn ignored(rules: &str, name: &str) -> bool {
    let mut ignored = false;
    for rule in rules.lines().map(str::trim) {
        if rule.is_empty() || rule.starts_with('#') {
            continue;
        }
        let (negated, rule) = match rule.strip_prefix('!') {
            Some(rest) => (true, rest),
            None => (false, rule),
        };
        let pattern = rule.strip_prefix('/').unwrap_or(rule);
        if glob(pattern, name) {
            ignored = !negated;
        }
    }
    ignored
}

/// `pattern` with `*` matching any run of characters equals `text`.
fn glob(pattern: &str, text: &str) -> bool {
    match pattern.split_once('*') {
        None => pattern == text,
        Some((head, tail)) => {
            let Some(rest) = text.strip_prefix(head) else {
                return false;
            };
            (0..=rest.len()).any(|i| rest.is_char_boundary(i) && glob(tail, &rest[i..]))
        }
    }
}

/// Runs `block` in `dir` with `path` as PATH: its wall time in seconds, or why it failed
/// (its line, exit status, text and the end of its stderr).
fn run_block(block: &Block, dir: &Path, path: &std::ffi::OsStr) -> Result<f64, String> {
    let start = Instant::now();
    let output = std::process::Command::new("bash")
        .arg("-c")
        .arg(format!("{PREAMBLE}{}", block.text))
        .current_dir(dir)
        .env("PATH", path)
        .output()
        .map_err(|e| format!("cannot run bash: {e}"))?;
    if output.status.success() {
        return Ok(start.elapsed().as_secs_f64());
    }
    let stderr = String::from_utf8_lossy(&output.stderr);
    let lines: Vec<&str> = stderr.lines().collect();
    let tail = lines[lines.len().saturating_sub(20)..].join("\n");
    Err(format!(
        "README.md:{}: the block failed ({}):\n{}its stderr ends:\n{tail}",
        block.line, output.status, block.text
    ))
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        let target = to.join(entry.file_name());
        if entry.file_type().unwrap().is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), target).unwrap();
        }
    }
}

fn checkout() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn readme() -> String {
    std::fs::read_to_string(checkout().join("README.md")).expect("README.md")
}

#[test]
fn every_readme_command_block_runs_as_printed() {
    let blocks = blocks(&readme()).unwrap_or_else(|e| panic!("README.md:{e}"));
    let dir = support::cli::scratch_dir("readme");
    copy_dir(&checkout().join("examples"), &dir.join("examples"));
    let bin = Path::new(env!("CARGO_BIN_EXE_occsim"))
        .parent()
        .expect("the binary's directory")
        .to_path_buf();
    let path = std::env::join_paths(
        std::iter::once(bin).chain(std::env::split_paths(&std::env::var_os("PATH").unwrap())),
    )
    .unwrap();
    let started = Instant::now();
    let mut ran = 0;
    for block in blocks.iter().filter(|b| b.is_commands()) {
        let first = block.text.lines().next().unwrap_or("");
        if let Some(reason) = &block.skip {
            eprintln!("README.md:{:<4} skipped ({reason}): {first}", block.line);
            continue;
        }
        let took = run_block(block, &dir, &path).unwrap_or_else(|e| panic!("{e}"));
        ran += 1;
        eprintln!("README.md:{:<4} {took:>6.1} s  {first}", block.line);
    }
    eprintln!(
        "{ran} README blocks ran in {:.1} s",
        started.elapsed().as_secs_f64()
    );
    assert!(
        ran >= 10,
        "only {ran} blocks ran: is README's fence syntax still ```sh?"
    );

    let rules = std::fs::read_to_string(checkout().join(".gitignore")).expect(".gitignore");
    let mut unignored = Vec::new();
    for entry in std::fs::read_dir(&*dir).unwrap() {
        let name = entry.unwrap().file_name().to_string_lossy().into_owned();
        if name != "examples" && !ignored(&rules, &name) {
            unignored.push(name);
        }
    }
    assert!(
        unignored.is_empty(),
        "README's commands write files .gitignore does not ignore: {unignored:?}"
    );
}

/// README's cluster recipe (the job script and the merge, the blocks that write
/// `cluster-*` files) is the one `occsim sweep --help` prints, line for line.
#[test]
fn sweep_help_prints_readmes_cluster_recipe() {
    let blocks = blocks(&readme()).unwrap();
    let cluster: Vec<&Block> = blocks
        .iter()
        .filter(|b| b.is_commands() && b.text.contains("cluster-"))
        .collect();
    assert_eq!(cluster.len(), 2, "the job script and the merge");
    assert!(cluster[0].text.contains("SLURM_ARRAY_TASK_ID"));
    let help = support::cli::stdout_of(&["sweep", "--help"]);
    let help_lines: Vec<&str> = help.lines().map(str::trim).collect();
    for line in cluster.iter().flat_map(|b| b.text.lines()).map(str::trim) {
        assert!(
            help_lines.contains(&line),
            "README's cluster line `{line}` is not in `occsim sweep --help`:\n{help}"
        );
    }
}

#[test]
fn blocks_are_found_with_their_skip_reasons() {
    let markdown = "intro\n```sh\na 1\nb 2\n```\n\n<!-- readme-test: skip: too slow -->\n\
                    ```bash\nc\n```\n```text\nnot run\n```\n";
    let found = blocks(markdown).unwrap();
    assert_eq!(
        found,
        [
            Block {
                line: 2,
                lang: "sh".into(),
                text: "a 1\nb 2\n".into(),
                skip: None
            },
            Block {
                line: 8,
                lang: "bash".into(),
                text: "c\n".into(),
                skip: Some("too slow".into())
            },
            Block {
                line: 11,
                lang: "text".into(),
                text: "not run\n".into(),
                skip: None
            },
        ]
    );
    assert!(!found[2].is_commands());
}

#[test]
fn bad_markers_and_fences_are_refused() {
    let no_reason = blocks("<!-- readme-test: skip: -->\n```sh\na\n```\n").unwrap_err();
    assert!(
        no_reason.starts_with("line 1: a skip marker is"),
        "{no_reason}"
    );
    let astray = blocks("<!-- readme-test: skip: slow -->\ntext\n```sh\na\n```\n").unwrap_err();
    assert_eq!(
        astray,
        "line 1: a skip marker must come right before a fenced block"
    );
    let open = blocks("```sh\na\n").unwrap_err();
    assert_eq!(open, "line 1: the block is never closed");
}

#[test]
fn a_failing_command_fails_its_block() {
    let dir = support::cli::scratch_dir("readme-runner");
    let path = std::env::var_os("PATH").unwrap();
    let block = |text: &str| Block {
        line: 7,
        lang: "sh".into(),
        text: text.into(),
        skip: None,
    };
    assert!(run_block(
        &block("true\ncargo install --path . --locked\n"),
        &dir,
        &path
    )
    .is_ok());
    let err = run_block(&block("true\nfalse\ntouch never\n"), &dir, &path).unwrap_err();
    assert!(err.starts_with("README.md:7: the block failed"), "{err}");
    assert!(
        !dir.join("never").exists(),
        "the block stops at its first failure"
    );
    let err = run_block(&block("cargo build\n"), &dir, &path).unwrap_err();
    assert!(err.contains("README runs 'cargo build'"), "{err}");
    let err = run_block(&block("false | cat\n"), &dir, &path).unwrap_err();
    assert!(err.contains("the block failed"), "pipefail: {err}");
}

#[test]
fn gitignore_rules_match_as_git_does_at_the_root() {
    let rules = "/target\n*.occt\n/*.toml\n!/Cargo.toml\n# a comment\n";
    assert!(ignored(rules, "demo.occt"));
    assert!(ignored(rules, "my.toml"));
    assert!(!ignored(rules, "Cargo.toml"), "re-included");
    assert!(ignored(rules, "target"));
    assert!(!ignored(rules, "demo.svg"));
    assert!(!ignored(rules, "occt"), "the star needs its dot");
}
