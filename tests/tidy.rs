//! Tidy tests: the invariants ARCHITECTURE.md states about the code itself, checked by reading
//! the sources (as rust-analyzer's tidy tests do).
//! - `sim`'s modules import one another without a circle;
//! - `sim` does no file IO;
//! - `rtl-model` has no floating point;
//! - library error messages name no command-line flag (the binary's words are the binary's);
//! - every source module is named in ARCHITECTURE.md's code map.

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
    let bytes = text.as_bytes();
    let (mut code, mut strings) = (String::with_capacity(text.len()), Vec::new());
    let mut i = 0;
    while i < bytes.len() {
        let rest = &text[i..];
        if rest.starts_with("//") {
            let end = rest.find('\n').unwrap_or(rest.len());
            i += end;
        } else if rest.starts_with("/*") {
            let end = rest.find("*/").map_or(rest.len(), |e| e + 2);
            i += end;
        } else if rest.starts_with("r#\"") || rest.starts_with("r\"") {
            let hashes = rest[1..].bytes().take_while(|&b| b == b'#').count();
            let open = 2 + hashes;
            let close = format!("\"{}", "#".repeat(hashes));
            let end = rest[open..].find(&close).map_or(rest.len(), |e| open + e);
            strings.push(rest[open..end].to_owned());
            code.push_str("\"\"");
            i += (end + close.len()).min(rest.len());
        } else if bytes[i] == b'"' {
            let mut j = i + 1;
            while j < bytes.len() && bytes[j] != b'"' {
                j += if bytes[j] == b'\\' { 2 } else { 1 };
            }
            strings.push(text[i + 1..j.min(bytes.len())].to_owned());
            code.push_str("\"\"");
            i = j + 1;
        } else if bytes[i] == b'\''
            && rest.len() > 2
            && (rest.as_bytes()[2] == b'\'' || rest.as_bytes()[1] == b'\\')
        {
            // A char literal ('x' or '\n'); a lifetime has no closing quote.
            let end = rest[1..].find('\'').map_or(1, |e| e + 2);
            code.push_str("' '");
            i += end;
        } else {
            let c = rest.chars().next().expect("not at the end");
            code.push(c);
            i += c.len_utf8();
        }
    }
    Code { code, strings }
}

/// The part of a library file that is not its unit tests.
fn without_tests(text: &str) -> &str {
    text.find("#[cfg(test)]").map_or(text, |at| &text[..at])
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
        let code = split_code(without_tests(&text)).code;
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
            for string in split_code(without_tests(&text)).strings {
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

#[test]
fn every_module_is_in_the_code_map() {
    let map = std::fs::read_to_string(root().join("ARCHITECTURE.md")).expect("ARCHITECTURE.md");
    let words: BTreeSet<&str> = map
        .split(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
        .collect();
    let mut missing = Vec::new();
    for krate in ["src", "sim/src", "traces/src", "rtl-model/src", "sweep/src"] {
        let src = root().join(krate);
        for file in sources(&src) {
            let module = module_of(&src, &file);
            if let Some(name) = module.last() {
                if !words.contains(name.as_str()) {
                    missing.push(format!("{krate}/{}", module.join("/")));
                }
            }
        }
    }
    assert!(
        missing.is_empty(),
        "modules ARCHITECTURE.md does not name: {missing:?}"
    );
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
