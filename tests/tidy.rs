//! Tidy tests: the invariants ARCHITECTURE.md states about the code itself, checked by reading
//! the sources (as rust-analyzer's tidy tests do).
//! - `sim`'s modules import one another without a circle;
//! - `sim` does no file IO;
//! - `rtl-model` has no floating point;
//! - library error messages name no command-line flag (the binary's words are the binary's);
//! - every source module is named in ARCHITECTURE.md's code map, by its file;
//! - data flows one way between the crates (each one's own dependencies);
//! - glam stays in the scenes, cameras and drivers, out of the rasterizer and the models.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The workspace root (this package's directory).
fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Every `.rs` file under `dir`, sorted.
fn sources(dir: &Path) -> Vec<PathBuf> {
    let mut files = Vec::new();
    let mut pending = vec![dir.to_path_buf()];
    while let Some(dir) = pending.pop() {
        for entry in std::fs::read_dir(&dir).expect("a source directory") {
            let path = entry.expect("a directory entry").path();
            if path.is_dir() {
                pending.push(path);
            } else if path.extension().is_some_and(|e| e == "rs") {
                files.push(path);
            }
        }
    }
    files.sort();
    files
}

/// What of a source file is code: comments removed, string and char literals kept apart.
struct Code {
    /// The code with comments and literals blanked out.
    code: String,
    /// The string literals, in order.
    strings: Vec<String>,
}

fn split_code(text: &str) -> Code {
    split(text, Tests::Kept)
}

/// Whether [`split`] keeps the items under `#[cfg(test)]`.
#[derive(Clone, Copy, PartialEq)]
enum Tests {
    Kept,
    Dropped,
}

/// The part of a library file that is not its tests: [`split_code`] without every item
/// under `#[cfg(test)]` (a unit-test module, a test-only method inside an `impl`, field or
/// match arm, wherever it is in the file). A file that a `#[cfg(test)] mod x;` names is
/// still read whole, as any file is.
fn without_tests(text: &str) -> Code {
    split(text, Tests::Dropped)
}

/// A test-only item being skipped: its bracket depth, and whether its body's brace opened.
#[derive(Clone, Copy)]
struct Skipping {
    depth: u32,
    opened: bool,
}

/// Where a character leaves the test-only item being skipped.
#[derive(PartialEq)]
enum Skipped {
    /// Inside it.
    Within,
    /// Its last character (the `;` of an item without a body, the brace that closes its
    /// body, the `,` after a field, a variant or a match arm).
    Last,
    /// Past it: the closer of what holds it (a field's struct, an arm's match), code again.
    Past,
}

impl Skipping {
    /// Take one character of code.
    fn take(&mut self, c: char) -> Skipped {
        match c {
            '(' | '[' => self.depth += 1,
            '{' => (self.depth, self.opened) = (self.depth + 1, true),
            ')' | ']' | '}' if self.depth == 0 => return Skipped::Past,
            ')' | ']' | '}' => {
                self.depth -= 1;
                if c == '}' && self.depth == 0 && self.opened {
                    return Skipped::Last;
                }
            }
            ';' | ',' if self.depth == 0 => return Skipped::Last,
            _ => {}
        }
        Skipped::Within
    }
}

fn split(text: &str, tests: Tests) -> Code {
    let bytes = text.as_bytes();
    let (mut code, mut strings) = (String::with_capacity(text.len()), Vec::new());
    let mut skipping: Option<Skipping> = None;
    let mut i = 0;
    while i < bytes.len() {
        let rest = &text[i..];
        let literal = if rest.starts_with("//") {
            let end = rest.find('\n').unwrap_or(rest.len());
            i += end;
            None
        } else if rest.starts_with("/*") {
            let end = rest.find("*/").map_or(rest.len(), |e| e + 2);
            i += end;
            None
        } else if rest.starts_with("r#\"") || rest.starts_with("r\"") {
            let hashes = rest[1..].bytes().take_while(|&b| b == b'#').count();
            let open = 2 + hashes;
            let close = format!("\"{}", "#".repeat(hashes));
            let end = rest[open..].find(&close).map_or(rest.len(), |e| open + e);
            i += (end + close.len()).min(rest.len());
            Some((Some(rest[open..end].to_owned()), "\"\""))
        } else if bytes[i] == b'"' {
            let mut j = i + 1;
            while j < bytes.len() && bytes[j] != b'"' {
                j += if bytes[j] == b'\\' { 2 } else { 1 };
            }
            let string = text[i + 1..j.min(bytes.len())].to_owned();
            i = j + 1;
            Some((Some(string), "\"\""))
        } else if bytes[i] == b'\''
            && rest.len() > 2
            && (rest.as_bytes()[2] == b'\'' || rest.as_bytes()[1] == b'\\')
        {
            // A char literal ('x' or '\n'); a lifetime has no closing quote.
            let end = rest[1..].find('\'').map_or(1, |e| e + 2);
            i += end;
            Some((None, "' '"))
        } else if tests == Tests::Dropped && skipping.is_none() && rest.starts_with("#[cfg(test)]")
        {
            skipping = Some(Skipping {
                depth: 0,
                opened: false,
            });
            i += "#[cfg(test)]".len();
            continue;
        } else {
            let c = rest.chars().next().expect("not at the end");
            i += c.len_utf8();
            match &mut skipping {
                Some(item) => match item.take(c) {
                    Skipped::Within => {}
                    Skipped::Last => skipping = None,
                    Skipped::Past => {
                        skipping = None;
                        code.push(c);
                    }
                },
                None => code.push(c),
            }
            continue;
        };
        if let (Some((string, blank)), None) = (literal, skipping) {
            strings.extend(string);
            code.push_str(blank);
        }
    }
    Code { code, strings }
}

/// The module path of `file` in a crate whose root directory is `src`.
fn module_of(src: &Path, file: &Path) -> Vec<String> {
    let relative = file.strip_prefix(src).expect("inside the crate");
    let mut parts: Vec<String> = relative
        .iter()
        .map(|p| p.to_string_lossy().trim_end_matches(".rs").to_owned())
        .collect();
    if matches!(
        parts.last().map(String::as_str),
        Some("mod" | "lib" | "main")
    ) {
        parts.pop();
    }
    parts
}

/// Every path a piece of code names from `crate::` or `super::`, made absolute, with
/// `use` groups (`a::{b, c::d}`) expanded.
fn crate_paths(code: &str, module: &[String]) -> Vec<Vec<String>> {
    let mut paths = Vec::new();
    let bytes = code.as_bytes();
    let mut i = 0;
    while i < code.len() {
        let rest = &code[i..];
        let at_word = i == 0 || !(bytes[i - 1].is_ascii_alphanumeric() || bytes[i - 1] == b'_');
        let start: Option<(Vec<String>, usize)> = if at_word && rest.starts_with("crate::") {
            Some((Vec::new(), 7))
        } else if at_word && rest.starts_with("super::") {
            // A module's `super` is its parent, whether it is a file or a directory's mod.rs.
            let mut base = module.to_vec();
            let mut skip = 0;
            while code[i + skip..].starts_with("super::") {
                skip += 7;
                base.pop();
            }
            Some((base, skip))
        } else {
            None
        };
        let Some((base, skip)) = start else {
            i += rest.chars().next().map_or(1, char::len_utf8);
            continue;
        };
        let (found, used) = parse_tree(&code[i + skip..]);
        for tail in found {
            let mut path = base.clone();
            path.extend(tail);
            paths.push(path);
        }
        i += skip + used.max(1);
    }
    paths
}

/// A path tree at the start of `text`: `a::b`, `a::{b, c::{d}}`, `a::b::*`. Returns the
/// expanded paths and the bytes read.
fn parse_tree(text: &str) -> (Vec<Vec<String>>, usize) {
    let mut i = 0;
    let mut prefix = Vec::new();
    loop {
        let rest = &text[i..];
        let trimmed = rest.trim_start();
        i += rest.len() - trimmed.len();
        if trimmed.starts_with('{') {
            let mut paths = Vec::new();
            let mut j = i + 1;
            loop {
                let inside = &text[j..];
                let skipped = inside.len() - inside.trim_start().len();
                j += skipped;
                if text[j..].starts_with('}') {
                    j += 1;
                    break;
                }
                let (sub, used) = parse_tree(&text[j..]);
                for s in sub {
                    let mut p = prefix.clone();
                    p.extend(s);
                    paths.push(p);
                }
                j += used;
                let after = &text[j..];
                let skipped = after.len() - after.trim_start().len();
                j += skipped;
                if text[j..].starts_with(',') {
                    j += 1;
                } else if text[j..].starts_with('}') || j >= text.len() {
                    j += 1;
                    break;
                } else {
                    j += 1;
                }
            }
            return (paths, j);
        }
        let ident: String = trimmed
            .chars()
            .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
            .collect();
        if ident.is_empty() {
            return (vec![prefix], i);
        }
        i += ident.len();
        if ident != "self" {
            prefix.push(ident);
        }
        if text[i..].starts_with("::") {
            i += 2;
        } else {
            return (vec![prefix], i);
        }
    }
}

#[test]
fn sim_modules_import_one_another_without_a_circle() {
    let src = root().join("sim/src");
    let files = sources(&src);
    let modules: BTreeSet<Vec<String>> = files.iter().map(|f| module_of(&src, f)).collect();
    let mut edges: BTreeMap<Vec<String>, BTreeSet<Vec<String>>> = BTreeMap::new();
    for file in &files {
        let text = std::fs::read_to_string(file).expect("readable source");
        let from = module_of(&src, file);
        let code = without_tests(&text).code;
        for path in crate_paths(&code, &from) {
            // The longest prefix that is a module: the module the path's item lives in.
            let target = (0..=path.len())
                .rev()
                .map(|n| path[..n].to_vec())
                .find(|p| modules.contains(p))
                .unwrap_or_default();
            if target != from {
                edges.entry(from.clone()).or_default().insert(target);
            }
        }
    }
    // Depth-first search for a back edge.
    fn visit(
        node: &Vec<String>,
        edges: &BTreeMap<Vec<String>, BTreeSet<Vec<String>>>,
        state: &mut BTreeMap<Vec<String>, u8>,
        stack: &mut Vec<Vec<String>>,
    ) -> Option<Vec<Vec<String>>> {
        match state.get(node) {
            Some(2) => return None,
            Some(1) => {
                let from = stack.iter().position(|n| n == node).unwrap_or(0);
                let mut circle = stack[from..].to_vec();
                circle.push(node.clone());
                return Some(circle);
            }
            _ => {}
        }
        state.insert(node.clone(), 1);
        stack.push(node.clone());
        for next in edges.get(node).into_iter().flatten() {
            if let Some(circle) = visit(next, edges, state, stack) {
                return Some(circle);
            }
        }
        stack.pop();
        state.insert(node.clone(), 2);
        None
    }
    let mut state = BTreeMap::new();
    for module in &modules {
        if let Some(circle) = visit(module, &edges, &mut state, &mut Vec::new()) {
            let names: Vec<String> = circle
                .iter()
                .map(|m| format!("crate::{}", m.join("::")))
                .collect();
            panic!(
                "sim modules import one another in a circle: {}",
                names.join(" -> ")
            );
        }
    }
    // The test must see the crate's real imports (a broken parser would find none).
    assert!(
        edges.values().map(BTreeSet::len).sum::<usize>() > 50,
        "{edges:?}"
    );
}

#[test]
fn sim_does_no_file_io() {
    let src = root().join("sim/src");
    for file in sources(&src) {
        let text = std::fs::read_to_string(&file).expect("readable source");
        let code = split_code(&text).code;
        for forbidden in [
            "std::fs",
            "fs::File",
            "File::open",
            "File::create",
            "OpenOptions",
        ] {
            assert!(
                !code.contains(forbidden),
                "{} uses {forbidden}",
                file.display()
            );
        }
    }
}

#[test]
fn rtl_model_has_no_floating_point() {
    let src = root().join("rtl-model/src");
    for file in sources(&src) {
        let text = std::fs::read_to_string(&file).expect("readable source");
        let code = split_code(&text).code;
        for word in code.split(|c: char| !(c.is_ascii_alphanumeric() || c == '_')) {
            assert!(
                word != "f32" && word != "f64",
                "{} uses {word}",
                file.display()
            );
        }
    }
}

#[test]
fn library_error_messages_name_no_command_line_flag() {
    for krate in ["sim/src", "traces/src", "rtl-model/src", "sweep/src"] {
        for file in sources(&root().join(krate)) {
            let text = std::fs::read_to_string(&file).expect("readable source");
            for string in without_tests(&text).strings {
                let flag = string.match_indices("--").find(|(at, _)| {
                    string[at + 2..]
                        .chars()
                        .next()
                        .is_some_and(|c| c.is_ascii_lowercase())
                });
                assert!(
                    flag.is_none(),
                    "{}: the library message `{string}` names a command-line flag; the binary adds those",
                    file.display()
                );
            }
        }
    }
}

/// Whether `map` names the module of `file` by its file, `name.rs` (its directory `name/`
/// for a `mod.rs`), not merely by a word that happens to be its name (the `city` scene had
/// stood for `builtin/city.rs`).
fn names_module(map: &str, file: &Path) -> bool {
    let stem = file.file_stem().expect("a file").to_string_lossy();
    let name = match stem.as_ref() {
        "mod" => file
            .parent()
            .and_then(Path::file_name)
            .expect("a directory")
            .to_string_lossy(),
        _ => stem.clone(),
    };
    let mention = match stem.as_ref() {
        "mod" => format!("{name}/"),
        _ => format!("{name}.rs"),
    };
    // Not inside a longer name: `tests.rs` is no mention of `depth_tests.rs`.
    map.match_indices(&mention).any(|(at, _)| {
        let before = map[..at].chars().next_back();
        !before.is_some_and(|c| c.is_ascii_alphanumeric() || c == '_')
    })
}

#[test]
fn every_module_is_in_the_code_map() {
    let map = std::fs::read_to_string(root().join("ARCHITECTURE.md")).expect("ARCHITECTURE.md");
    let mut missing = Vec::new();
    for krate in ["src", "sim/src", "traces/src", "rtl-model/src", "sweep/src"] {
        let src = root().join(krate);
        for file in sources(&src) {
            let module = module_of(&src, &file);
            if !module.is_empty() && !names_module(&map, &file) {
                missing.push(format!("{krate}/{}", module.join("/")));
            }
        }
    }
    assert!(
        missing.is_empty(),
        "modules ARCHITECTURE.md does not name: {missing:?}"
    );
}

#[test]
fn a_module_is_named_by_its_file_not_by_a_word() {
    let city = Path::new("traces/src/builtin/city.rs");
    assert!(!names_module("the `city` scene; a city block", city));
    assert!(names_module("`city.rs`: the demo's city block", city));
    let fifo = Path::new("sim/src/blocks/fifo.rs");
    assert!(!names_module("the blocks: `fifo`, ...", fifo));
    assert!(names_module("the blocks: `fifo.rs`, ...", fifo));
    let levels = Path::new("sim/src/levels/mod.rs");
    assert!(names_module("- `levels/`: the fidelity levels", levels));
    assert!(!names_module("the levels of detail", levels));
    let tests = Path::new("sweep/src/tests.rs");
    assert!(!names_module("`depth_tests.rs`: ...", tests));
    assert!(names_module("`tests.rs`: ...", tests));
}

#[test]
fn the_path_parser_expands_groups_and_resolves_super() {
    let module = vec!["levels".to_owned(), "analytic".to_owned()];
    let paths = crate_paths(
        "use crate::{arch::Arch, levels::{level::Fidelity, functional}};\nlet x = super::o2::f();",
        &module,
    );
    let text: Vec<String> = paths.iter().map(|p| p.join("::")).collect();
    assert_eq!(
        text,
        vec![
            "arch::Arch",
            "levels::level::Fidelity",
            "levels::functional",
            "levels::o2::f"
        ]
    );
    let code = split_code("let s = \"crate::not_code\"; // crate::comment\nuse crate::real;");
    assert_eq!(code.strings, vec!["crate::not_code"]);
    let paths: Vec<String> = crate_paths(&code.code, &[])
        .iter()
        .map(|p| p.join("::"))
        .collect();
    assert_eq!(paths, vec!["real"]);
}

#[test]
fn every_source_path_the_docs_name_exists() {
    let mut missing = Vec::new();
    for doc in ["README.md", "ARCHITECTURE.md"] {
        let text = std::fs::read_to_string(root().join(doc)).expect("the doc");
        for word in text.split(|c: char| c.is_whitespace() || "`()[],;:".contains(c)) {
            let roots = [
                "sim/",
                "traces/",
                "rtl-model/",
                "sweep/",
                "src/",
                "tests/",
                "benches/",
            ];
            let source = word.ends_with(".rs") && roots.iter().any(|r| word.starts_with(r));
            if source && !root().join(word).exists() {
                missing.push(format!("{doc}: {word}"));
            }
        }
    }
    assert!(missing.is_empty(), "paths that do not exist: {missing:?}");
}

#[test]
fn only_the_items_under_cfg_test_are_dropped() {
    // A test-only method inside an impl, then the file's code goes on: its string stays
    // (the old cut at the first `#[cfg(test)]` lost it), the tests' strings do not.
    let text = "impl A {\n    #[cfg(test)]\n    fn peek(&self) -> [u8; 2] { [b'{', 1] }\n    fn f() { g(\"kept\") }\n}\n#[cfg(test)]\nconst T: [u8; 2] = [0; 2];\n#[cfg(test)]\nmod tests {\n    fn t() { assert!(x, \"dropped {}\", 1) }\n}\nfn after() { h(\"also kept\") }\n";
    let code = without_tests(text);
    assert_eq!(code.strings, vec!["kept", "also kept"]);
    // A test-only field ends at its comma, the last one at its struct's brace, which stays.
    let fields = without_tests("struct S {\n    a: u8,\n    #[cfg(test)]\n    b: u8,\n    c: u8,\n}\nstruct T {\n    #[cfg(test)]\n    d: u8\n}\nfn g() { h(\"kept\") }\n");
    assert!(
        fields.code.contains("a: u8") && fields.code.contains("c: u8"),
        "{}",
        fields.code
    );
    assert!(!fields.code.contains("b: u8") && !fields.code.contains("d: u8"));
    assert!(fields.code.contains("struct T {") && fields.code.contains("fn g()"));
    assert_eq!(fields.strings, vec!["kept"]);
    assert!(!code.code.contains("peek") && !code.code.contains("mod tests"));
    assert!(!code.code.contains("const T"));
    assert!(code.code.contains("fn f()") && code.code.contains("fn after()"));
    // split_code keeps them all.
    assert_eq!(
        split_code(text).strings,
        vec!["kept", "dropped {}", "also kept"]
    );
}

/// The workspace's own crates a crate's `Cargo.toml` depends on (its `[dependencies]`).
fn own_dependencies(manifest: &str) -> BTreeSet<String> {
    let text = std::fs::read_to_string(root().join(manifest)).expect("a manifest");
    let table: toml::Table = text.parse().expect("TOML");
    table
        .get("dependencies")
        .and_then(|d| d.as_table())
        .map(|d| {
            d.keys()
                .filter(|k| k.starts_with("occsim"))
                .cloned()
                .collect()
        })
        .unwrap_or_default()
}

#[test]
fn data_flows_one_way_between_the_crates() {
    // scene -> rasterizer -> trace (occsim-traces) -> machine model (occsim-sim, over
    // occsim-rtl) -> report (the binary); the sweep engine knows no machine.
    let expected: [(&str, &[&str]); 5] = [
        ("traces/Cargo.toml", &[]),
        ("rtl-model/Cargo.toml", &[]),
        ("sim/Cargo.toml", &["occsim-rtl", "occsim-traces"]),
        ("sweep/Cargo.toml", &["occsim-traces"]),
        (
            "Cargo.toml",
            &["occsim-rtl", "occsim-sim", "occsim-sweep", "occsim-traces"],
        ),
    ];
    for (manifest, crates) in expected {
        let crates: BTreeSet<String> = crates.iter().map(|c| c.to_string()).collect();
        assert_eq!(own_dependencies(manifest), crates, "{manifest}");
    }
}

#[test]
fn glam_stays_out_of_the_rasterizer_and_the_models() {
    // Vector math for scenes, cameras and drivers only: the rasterizer's and the models'
    // arithmetic is stated exactly, in integers and f32 as llvmpipe's is.
    let allowed = [
        "traces/src/geometry.rs",
        "traces/src/builtin/",
        "traces/src/workloads/",
    ];
    let mut found = Vec::new();
    for krate in ["src", "sim/src", "traces/src", "rtl-model/src", "sweep/src"] {
        for file in sources(&root().join(krate)) {
            let text = std::fs::read_to_string(&file).expect("readable source");
            let code = split_code(&text).code;
            let uses_glam = code
                .split(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
                .any(|word| word == "glam");
            let path = file.strip_prefix(root()).expect("in the workspace");
            let path = path.to_string_lossy();
            if uses_glam && !allowed.iter().any(|a| path.starts_with(a)) {
                found.push(path.into_owned());
            }
        }
    }
    assert!(found.is_empty(), "glam used outside its places: {found:?}");
    for manifest in ["sim/Cargo.toml", "rtl-model/Cargo.toml", "sweep/Cargo.toml"] {
        let text = std::fs::read_to_string(root().join(manifest)).expect("a manifest");
        assert!(!text.contains("glam"), "{manifest} depends on glam");
    }
}
