//! The source tree keeps the shape of the design: modules in folders, data flowing one way
//! (no two top-level modules import each other, directly or through others, in the library and
//! in the Python binding crate, `python/src`), and a library that speaks its own vocabulary (no
//! string literal outside the command line names a flag).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

fn src() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("src")
}

/// The sources of the Python binding crate (a crate of its own, see `python/Cargo.toml`).
fn python_src() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("python/src")
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// `text` without comments, and cut where its unit tests start.
fn code_of(text: &str) -> String {
    let text = text.split("#[cfg(test)]").next().unwrap_or("");
    text.lines()
        .map(|l| match l.find("//") {
            // Good enough for this tree: no string literal holds `//` before a flag.
            Some(i) if !l[..i].contains('"') => &l[..i],
            _ => l,
        })
        .collect::<Vec<_>>()
        .join("\n")
}

/// The string literals of `text` (plain, byte and raw), with their line numbers.
fn string_literals(text: &str) -> Vec<(usize, String)> {
    let b = text.as_bytes();
    let (mut i, mut line, mut out) = (0, 1, Vec::new());
    while i < b.len() {
        match b[i] {
            b'\n' => line += 1,
            b'/' if b.get(i + 1) == Some(&b'/') => {
                while i < b.len() && b[i] != b'\n' {
                    i += 1;
                }
                continue;
            }
            // A char literal: '"' or '\"' (a lifetime has no closing quote after one char).
            b'\'' if b.get(i + 2) == Some(&b'\'') => i += 2,
            b'\'' if b.get(i + 1) == Some(&b'\\') && b.get(i + 3) == Some(&b'\'') => i += 3,
            b'r' if (b.get(i + 1) == Some(&b'"') || b.get(i + 1) == Some(&b'#'))
                && (i == 0 || !(b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_')) =>
            {
                let mut j = i + 1;
                let mut hashes = 0;
                while b.get(j) == Some(&b'#') {
                    hashes += 1;
                    j += 1;
                }
                if b.get(j) == Some(&b'"') {
                    let close: Vec<u8> = std::iter::once(b'"')
                        .chain(std::iter::repeat_n(b'#', hashes))
                        .collect();
                    let start = j + 1;
                    let end = start
                        + text[start..]
                            .find(std::str::from_utf8(&close).unwrap())
                            .expect("raw string closed");
                    out.push((line, text[start..end].to_string()));
                    line += text[start..end].matches('\n').count();
                    i = end + close.len();
                    continue;
                }
            }
            b'"' => {
                let start = i + 1;
                let mut j = start;
                while b[j] != b'"' {
                    j += if b[j] == b'\\' { 2 } else { 1 };
                }
                out.push((line, text[start..j].to_string()));
                line += text[start..j].matches('\n').count();
                i = j + 1;
                continue;
            }
            _ => {}
        }
        i += 1;
    }
    out
}

/// Whether `s` holds something shaped like a long flag: `--` then a lower-case letter.
fn names_a_flag(s: &str) -> bool {
    s.as_bytes().windows(3).enumerate().any(|(k, w)| {
        w[0] == b'-'
            && w[1] == b'-'
            && w[2].is_ascii_lowercase()
            && (k == 0 || s.as_bytes()[k - 1] != b'-')
    })
}

#[test]
fn the_library_names_no_flag() {
    let mut files = Vec::new();
    rust_files(&src(), &mut files);
    let mut found = Vec::new();
    for f in files {
        let rel = f.strip_prefix(src()).unwrap().to_path_buf();
        if rel.starts_with("cli") || rel == Path::new("main.rs") {
            continue;
        }
        let text = std::fs::read_to_string(&f).unwrap();
        for (line, lit) in string_literals(&text) {
            if names_a_flag(&lit) {
                found.push(format!("src/{}:{line}: {lit:?}", rel.display()));
            }
        }
    }
    assert!(
        found.is_empty(),
        "flags outside src/cli:\n{}",
        found.join("\n")
    );
}

#[test]
fn the_scanner_finds_flags_in_every_kind_of_literal() {
    let text =
        "let a = \"x --threads\"; let c = '\"'; let b = r#\"say \"--lambda\"\"#; // \"--no\"\n";
    let lits = string_literals(text);
    let flagged: Vec<_> = lits.iter().filter(|(_, l)| names_a_flag(l)).collect();
    assert_eq!(flagged.len(), 2, "{lits:?}");
    assert!(!names_a_flag("a---b"));
}

/// Top-level module of a file under `src/` (`None` for the crate roots).
fn top_module(rel: &Path) -> Option<String> {
    let first = rel.components().next()?.as_os_str().to_str()?;
    let name = first.trim_end_matches(".rs");
    (!matches!(name, "lib" | "main")).then(|| name.to_string())
}

/// The top-level modules that `code` names through `crate::`.
fn uses(code: &str, modules: &BTreeSet<String>) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    for (k, _) in code.match_indices("crate::") {
        let rest = &code[k + "crate::".len()..];
        let names: Vec<&str> = if let Some(group) = rest.strip_prefix('{') {
            let group = &group[..group.find('}').unwrap_or(group.len())];
            group
                .split(',')
                .map(|p| p.trim().split("::").next().unwrap_or("").trim())
                .collect()
        } else {
            vec![
                rest.split(|c: char| !(c.is_alphanumeric() || c == '_'))
                    .next()
                    .unwrap_or(""),
            ]
        };
        out.extend(
            names
                .into_iter()
                .filter(|n| modules.contains(*n))
                .map(String::from),
        );
    }
    out
}

/// Which top-level modules of the crate whose sources are `root` each one names through
/// `crate::` (its unit tests left out).
fn top_module_graph(root: &Path) -> BTreeMap<String, BTreeSet<String>> {
    let mut files = Vec::new();
    rust_files(root, &mut files);
    let modules: BTreeSet<String> = files
        .iter()
        .filter_map(|f| top_module(f.strip_prefix(root).unwrap()))
        .collect();
    let mut graph: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for f in &files {
        let rel = f.strip_prefix(root).unwrap();
        let Some(top) = top_module(rel) else { continue };
        if rel.file_name().is_some_and(|n| n == "tests.rs") {
            continue;
        }
        let code = code_of(&std::fs::read_to_string(f).unwrap());
        let mut used = uses(&code, &modules);
        used.remove(&top);
        graph.entry(top).or_default().extend(used);
    }
    graph
}

#[test]
fn modules_import_each_other_in_one_direction() {
    let cycles = cycles(&top_module_graph(&src()));
    assert!(
        cycles.is_empty(),
        "import circles among the modules of src/:\n{}",
        cycles.join("\n")
    );
}

#[test]
fn binding_modules_import_each_other_in_one_direction() {
    let graph = top_module_graph(&python_src());
    // The binding's modules are found at all (a moved crate would pass for want of files).
    assert!(graph.contains_key("options"), "python/src: {graph:?}");
    let cycles = cycles(&graph);
    assert!(
        cycles.is_empty(),
        "import circles among the modules of python/src/:\n{}",
        cycles.join("\n")
    );
}

/// The path of the module a file under `src/<top>/` defines, below `top`: `a.rs` → `[a]`,
/// `sub/mod.rs` → `[sub]`, `sub/b.rs` → `[sub, b]`, `mod.rs` → `[]`.
fn module_path(rel: &Path) -> Vec<String> {
    let mut parts: Vec<String> = rel
        .iter()
        .skip(1)
        .map(|c| c.to_str().unwrap().trim_end_matches(".rs").to_string())
        .collect();
    if parts.last().is_some_and(|p| p == "mod") {
        parts.pop();
    }
    parts
}

/// Sibling modules (children of `top`) that `code`, the file of module `path` inside `top`,
/// names through `super::…` or `crate::top::…`.
fn sibling_uses(code: &str, top: &str, path: &[String]) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    let mut add = |rest: &str, up: usize| {
        // `up` levels above `path`: the names that follow are children of that module.
        if up > path.len() {
            return;
        }
        let base = &path[..path.len() - up];
        let names: Vec<String> = if let Some(group) = rest.strip_prefix('{') {
            let group = &group[..group.find('}').unwrap_or(group.len())];
            group
                .split(',')
                .map(|p| p.trim().split("::").next().unwrap_or("").trim().to_string())
                .collect()
        } else {
            vec![
                rest.split(|c: char| !(c.is_alphanumeric() || c == '_'))
                    .next()
                    .unwrap_or("")
                    .to_string(),
            ]
        };
        for n in names.into_iter().filter(|n| !n.is_empty() && n != "self") {
            // The first component below `top` of the module named.
            let first = base.first().cloned().unwrap_or(n);
            out.insert(first);
        }
    };
    let prefix = format!("crate::{top}::");
    for (k, _) in code.match_indices(&prefix) {
        add(&code[k + prefix.len()..], path.len());
    }
    for (k, _) in code.match_indices("super::") {
        if k >= 7 && &code[k - 7..k] == "super::" {
            continue; // counted from the first `super::` of the chain
        }
        let mut rest = &code[k..];
        let mut up = 0;
        while let Some(r) = rest.strip_prefix("super::") {
            rest = r;
            up += 1;
        }
        add(rest, up);
    }
    out
}

/// Cycles in `graph`, each as `a -> b -> a`.
fn cycles(graph: &BTreeMap<String, BTreeSet<String>>) -> Vec<String> {
    let mut found = Vec::new();
    for start in graph.keys() {
        let mut stack: Vec<(String, Vec<String>)> = vec![(start.clone(), vec![start.clone()])];
        let mut seen = BTreeSet::new();
        while let Some((m, path)) = stack.pop() {
            for next in graph.get(&m).into_iter().flatten() {
                if next == start {
                    found.push(format!("{} -> {start}", path.join(" -> ")));
                } else if seen.insert(next.clone()) {
                    let mut p = path.clone();
                    p.push(next.clone());
                    stack.push((next.clone(), p));
                }
            }
        }
    }
    found
}

#[test]
fn files_of_a_module_import_each_other_in_one_direction() {
    let mut files = Vec::new();
    rust_files(&src(), &mut files);
    let mut graphs: BTreeMap<String, BTreeMap<String, BTreeSet<String>>> = BTreeMap::new();
    for f in &files {
        let rel = f.strip_prefix(src()).unwrap();
        let Some(top) = top_module(rel) else { continue };
        let path = module_path(rel);
        let Some(own) = path.first().cloned() else {
            continue; // the module's root, which declares and dispatches to its children
        };
        if path.last().is_some_and(|n| n == "tests") {
            continue;
        }
        let code = code_of(&std::fs::read_to_string(f).unwrap());
        let mut used = sibling_uses(&code, &top, &path);
        used.remove(&own);
        graphs
            .entry(top)
            .or_default()
            .entry(own)
            .or_default()
            .extend(used);
    }
    let found: Vec<String> = graphs
        .iter()
        .flat_map(|(top, g)| cycles(g).into_iter().map(move |c| format!("{top}: {c}")))
        .collect();
    assert!(
        found.is_empty(),
        "import circles inside modules:\n{}",
        found.join("\n")
    );
}

#[test]
fn no_loose_module_files() {
    let loose: Vec<String> = std::fs::read_dir(src())
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_file())
        .filter_map(|p| p.file_name()?.to_str().map(String::from))
        .filter(|n| !matches!(n.as_str(), "lib.rs" | "main.rs" | "error.rs"))
        .collect();
    assert!(loose.is_empty(), "loose files in src/: {loose:?}");
}

/// The variants of `smooth::Method`, read from its declaration.
fn method_variants() -> Vec<String> {
    let text = std::fs::read_to_string(src().join("smooth/mod.rs")).unwrap();
    let body = text
        .split("pub enum Method {")
        .nth(1)
        .and_then(|rest| rest.split('}').next())
        .expect("smooth/mod.rs declares `pub enum Method`");
    body.lines()
        .map(str::trim)
        .filter(|l| !l.starts_with("//") && !l.starts_with("#["))
        .filter_map(|l| l.strip_suffix(','))
        .map(str::to_string)
        .collect()
}

/// A variant's command-line name, as the registry spells it (`VcsLowpass` → `vcs-lowpass`).
fn kebab(variant: &str) -> String {
    let mut out = String::new();
    for (i, c) in variant.chars().enumerate() {
        if c.is_ascii_uppercase() && i > 0 {
            out.push('-');
        }
        out.push(c.to_ascii_lowercase());
    }
    out
}

/// Whether `lit` holds `name` as a word of its own (`vcs` in "vcs-lowpass" is not `vcs`).
fn names_word(lit: &str, name: &str) -> bool {
    let word = |c: char| c.is_ascii_alphanumeric() || c == '-' || c == '_';
    lit.split(|c: char| !word(c)).any(|w| w == name)
}

/// Outside `smooth/` the library asks the registry: no method's variant, no method's name, and no
/// `match` on a method (unit tests aside). A new method is one unit there and nowhere else.
#[test]
fn no_method_is_named_outside_smooth() {
    let variants = method_variants();
    assert!(variants.len() >= 8, "{variants:?}");
    let mut files = Vec::new();
    rust_files(&src(), &mut files);
    rust_files(&python_src(), &mut files);
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut found = Vec::new();
    for f in files {
        let rel = f.strip_prefix(root).unwrap().to_path_buf();
        // `tests.rs` files are unit-test modules (`#[cfg(test)] mod tests;`).
        if rel.starts_with("src/smooth") || rel.file_name().is_some_and(|n| n == "tests.rs") {
            continue;
        }
        let code = code_of(&std::fs::read_to_string(&f).unwrap());
        for v in &variants {
            let path = format!("Method::{v}");
            for (i, _) in code.match_indices(&path) {
                let next = code[i + path.len()..].chars().next();
                if !next.is_some_and(|c| c.is_ascii_alphanumeric() || c == '_') {
                    found.push(format!("{}: {path}", rel.display()));
                }
            }
            for (line, lit) in string_literals(&code) {
                if names_word(&lit, &kebab(v)) {
                    found.push(format!("{}:{line}: {lit:?}", rel.display()));
                }
            }
        }
        for (i, _) in code.match_indices("match ") {
            let scrutinee = code[i + 6..].split('{').next().unwrap_or("").trim();
            if scrutinee == "method" || scrutinee.ends_with(".method") {
                found.push(format!("{}: match {scrutinee}", rel.display()));
            }
        }
    }
    assert!(
        found.is_empty(),
        "methods named outside src/smooth:\n{}",
        found.join("\n")
    );
}

#[test]
fn the_method_scan_sees_variants_names_and_matches() {
    assert_eq!(kebab("VcsLowpass"), "vcs-lowpass");
    assert!(names_word("use vcs-lowpass here", "vcs-lowpass"));
    assert!(!names_word("vcs-lowpass", "vcs"));
    assert!(!names_word("vcsmooth", "vcs"));
    let code =
        code_of("fn f() { if m == Method::Vcs { g(\"taubin\") } }\n#[cfg(test)]\nMethod::Hc");
    assert!(code.contains("Method::Vcs") && !code.contains("Method::Hc"));
    assert_eq!(string_literals(&code)[0].1, "taubin");
}
