//! Repository hygiene checks, run as `#[test]`s by `cargo test -p xtask` (and so by
//! `cargo xtask ci`) and on demand by `cargo xtask tidy`. After rust-analyzer's
//! `xtask/src/tidy.rs`: each check is a function of the repository root that returns the list
//! of problems it found, so the unit tests below can plant a bad reference, a module cycle or a
//! long file in a temporary tree and see the check fail.
//!
//! * [`check_references`]: every `theory.md §N` / `docs/<page>.md §N` citation in `*.rs` and
//!   `*.md` lands on a heading `N.` of that page; every `*.md` page a text names exists; every
//!   relative path that docs and comments cite under `docs/`, `scenes/`, `crates/` exists.
//! * [`check_crate_graph`]: the workspace crates' `[dependencies]` on each other are exactly
//!   the edges listed in `ARCHITECTURE.md` (section "Crate edges").
//! * [`check_module_cycles`]: no import cycle between the top-level modules of a crate
//!   (`use crate::x…` / `crate::x::…` in code, test modules excluded), beyond the allow-list.
//! * [`check_file_lengths`]: no source file under `crates/*/src` over [`MAX_LINES`] lines,
//!   beyond the allow-list.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// Longest source file allowed under `crates/*/src`.
pub const MAX_LINES: usize = 1000;

/// Import cycles tolerated while they are being removed (each entry: crate directory, the
/// modules of the cycle); none today. A cycle passes only if all its modules lie in one entry,
/// so a new cycle, or a new module joining a listed one, fails.
pub const ALLOWED_CYCLES: &[(&str, &[&str])] = &[];

/// Source files over [`MAX_LINES`] tolerated while they are being split; none today.
pub const ALLOWED_LONG_FILES: &[&str] = &[];

/// Every check on the repository at `root`; an empty list means clean.
pub fn check_all(root: &Path) -> Vec<String> {
    let mut problems = check_references(root);
    problems.extend(check_crate_graph(root));
    problems.extend(check_module_cycles(root, ALLOWED_CYCLES));
    problems.extend(check_file_lengths(root, MAX_LINES, ALLOWED_LONG_FILES));
    problems
}

// ---------------------------------------------------------------------------------------------
// files

/// Directories never searched (build output, VCS, generated reports).
const SKIP_DIRS: &[&str] = &["target", ".git", "out", "node_modules"];

/// Files under `dir` (recursively) whose name ends with one of `exts`, sorted.
fn files(dir: &Path, exts: &[&str]) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&d) else { continue };
        for e in entries.flatten() {
            let p = e.path();
            let name = e.file_name().to_string_lossy().into_owned();
            if p.is_dir() {
                if !SKIP_DIRS.contains(&name.as_str()) && !name.starts_with('.') {
                    stack.push(p);
                }
            } else if exts.iter().any(|x| name.ends_with(x)) {
                out.push(p);
            }
        }
    }
    out.sort();
    out
}

fn rel(root: &Path, p: &Path) -> String {
    p.strip_prefix(root).unwrap_or(p).to_string_lossy().replace('\\', "/")
}

/// A file's text (lossy for non-UTF-8 bytes; empty if it cannot be read).
fn read(p: &Path) -> String {
    std::fs::read(p).map(|b| String::from_utf8_lossy(&b).into_owned()).unwrap_or_default()
}

// ---------------------------------------------------------------------------------------------
// (a) references

/// Section numbers `N` of the headings `#… N. title` of a markdown page.
fn heading_numbers(text: &str) -> BTreeSet<u32> {
    text.lines()
        .filter_map(|l| {
            let t = l.trim_start();
            let rest = t.trim_start_matches('#');
            if rest.len() == t.len() {
                return None;
            }
            let rest = rest.trim_start();
            let digits: String = rest.chars().take_while(char::is_ascii_digit).collect();
            if digits.is_empty() || !rest[digits.len()..].starts_with('.') {
                return None;
            }
            digits.parse().ok()
        })
        .collect()
}

fn is_name_char(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_' || c == '-'
}

fn is_path_char(c: char) -> bool {
    is_name_char(c) || c == '.' || c == '/'
}

/// Byte ranges `start..end` of the path-like names ending in `.md` in one line (`end` just
/// after `.md`; the name runs back over path characters).
fn md_names(line: &str) -> impl Iterator<Item = (usize, usize)> + '_ {
    line.match_indices(".md").map(move |(k, _)| {
        let end = k + 3;
        let start = line[..k]
            .char_indices()
            .rev()
            .find(|&(_, c)| !is_path_char(c))
            .map_or(0, |(i, c)| i + c.len_utf8());
        (start, end)
    })
}

/// The `(page, section numbers)` cited in one line: `page.md §N`, `page.md §N–M`,
/// `page.md §N, §M`, the page name optionally in backquotes and with a `docs/` prefix.
fn section_citations(line: &str) -> Vec<(String, Vec<u32>)> {
    let mut out = Vec::new();
    for (start, end) in md_names(line) {
        // the page name with `.md`, with an optional `docs/` prefix
        let page = &line[start..end];
        if page.len() <= 3 {
            continue;
        }
        // `§N` after optional backquote and spaces
        let mut rest = line[end..].trim_start_matches('`').trim_start();
        if !rest.starts_with('§') {
            continue;
        }
        let mut numbers = Vec::new();
        loop {
            rest = rest['§'.len_utf8()..].trim_start();
            let digits: String = rest.chars().take_while(char::is_ascii_digit).collect();
            let Ok(first) = digits.parse::<u32>() else { break };
            rest = &rest[digits.len()..];
            // a range `N–M` or `N–§M`
            let after = rest.trim_start_matches(['–', '-']);
            if after.len() != rest.len() {
                let after = after.trim_start_matches('§');
                let d2: String = after.chars().take_while(char::is_ascii_digit).collect();
                if let Ok(last) = d2.parse::<u32>() {
                    numbers.extend(first..=last.max(first));
                    rest = &after[d2.len()..];
                } else {
                    numbers.push(first);
                }
            } else {
                numbers.push(first);
            }
            // a list `N, §M`
            let t = rest.trim_start_matches(',').trim_start();
            if t.len() != rest.len() && t.starts_with('§') {
                rest = t;
            } else {
                break;
            }
        }
        if !numbers.is_empty() {
            out.push((page.to_string(), numbers));
        }
    }
    out
}

/// Where a cited page lives: `docs/x.md` at the root, a bare `x.md` in `docs/` or at the root.
fn resolve_page(root: &Path, page: &str) -> Option<PathBuf> {
    if page.contains('/') {
        let p = root.join(page);
        return p.is_file().then_some(p);
    }
    [root.join("docs").join(page), root.join(page)].into_iter().find(|p| p.is_file())
}

/// Relative paths cited in a line of docs that must exist: tokens starting with one of the
/// `prefixes` (up to the first character that cannot be in a path; a trailing `.` or a `:line`
/// suffix is dropped). Tokens preceded by a path character (e.g. `../x/docs/…`) are skipped.
fn cited_paths(line: &str, prefixes: &[&str]) -> Vec<String> {
    let mut out = Vec::new();
    for (i, _) in line.char_indices() {
        let prev = line[..i].chars().next_back();
        if prev.is_some_and(|c| is_path_char(c) || c == '$' || c == '<') {
            continue;
        }
        // `git show a432463:crates/…`: a path at a past commit, not in the tree
        if prev == Some(':') {
            let word =
                line[..i - 1].rsplit(|c: char| !c.is_ascii_alphanumeric()).next().unwrap_or("");
            if word.len() >= 7 && word.chars().all(|c| c.is_ascii_hexdigit()) {
                continue;
            }
        }
        let rest = &line[i..];
        if !prefixes.iter().any(|p| rest.starts_with(p)) {
            continue;
        }
        let len = rest.find(|c: char| !is_path_char(c)).unwrap_or(rest.len());
        // a brace alternative `scenes/paper-{2d,3d}-mpc.toml` stands for each of its paths
        if let Some(group) = rest[len..].strip_prefix('{') {
            if let Some(close) = group.find('}') {
                let tail = &group[close + 1..];
                let tail_len = tail.find(|c: char| !is_path_char(c)).unwrap_or(tail.len());
                let tail = tail[..tail_len].trim_end_matches('.');
                for alt in group[..close].split(',') {
                    out.push(format!("{}{}{tail}", &rest[..len], alt.trim()));
                }
                continue;
            }
        }
        out.push(rest[..len].trim_end_matches('.').to_string());
    }
    out
}

/// The text of a file that counts as documentation: all of a `*.md`, the comments of a `*.rs`.
fn doc_lines(path: &Path, text: &str) -> Vec<(usize, String)> {
    let md = path.extension().is_some_and(|x| x == "md");
    let mut in_output = false;
    text.lines()
        .enumerate()
        .filter_map(|(i, l)| {
            if md {
                // a ```text block shows program output (e.g. an error message for a user's own
                // scene), not a citation
                let t = l.trim_start();
                if t.starts_with("```") {
                    in_output = !in_output && t.trim_start_matches('`').trim() == "text";
                    return None;
                }
                (!in_output).then(|| (i + 1, l.to_string()))
            } else {
                l.find("//").map(|k| (i + 1, l[k..].to_string()))
            }
        })
        .collect()
}

/// Citations that do not resolve: `page.md §N` without a heading `N.` in that page, a `*.md`
/// page that does not exist, or a cited `docs/…`, `scenes/…`, `crates/…` path that does not
/// exist. Searches `*.rs` and `*.md` under `root` (not `target/` or hidden directories).
pub fn check_references(root: &Path) -> Vec<String> {
    let mut problems = Vec::new();
    let mut headings: BTreeMap<PathBuf, BTreeSet<u32>> = BTreeMap::new();
    for path in files(root, &[".rs", ".md"]) {
        let name = rel(root, &path);
        if name == "xtask/src/tidy.rs" {
            continue; // this file: its docs and tests show bad references on purpose
        }
        let text = read(&path);
        for (n, line) in doc_lines(&path, &text) {
            let citations = section_citations(&line);
            for (page, numbers) in citations.iter().cloned() {
                let Some(target) = resolve_page(root, &page) else {
                    problems.push(format!(
                        "{name}:{n}: cites `{page} §…`, and `{page}` does not exist"
                    ));
                    continue;
                };
                let have = headings
                    .entry(target.clone())
                    .or_insert_with(|| heading_numbers(&read(&target)));
                for k in numbers {
                    if !have.contains(&k) {
                        problems.push(format!(
                            "{name}:{n}: cites `{page} §{k}`, and {} has no heading `{k}.`",
                            rel(root, &target)
                        ));
                    }
                }
            }
            let pages: Vec<&String> = citations.iter().map(|(p, _)| p).collect();
            for token in cited_paths(&line, &["docs/", "scenes/", "crates/"]) {
                if !root.join(&token).exists() && !pages.iter().any(|p| **p == token) {
                    problems.push(format!("{name}:{n}: cites `{token}`, which does not exist"));
                }
            }
            for page in upper_case_pages(&line) {
                if resolve_page(root, page).is_none() {
                    problems.push(format!("{name}:{n}: cites `{page}`, which does not exist"));
                }
            }
        }
    }
    problems
}

/// Bare upper-case page names (`ARCHITECTURE.md`, `LAYOUT.md`) in a line.
fn upper_case_pages(line: &str) -> Vec<&str> {
    let mut out = Vec::new();
    for (start, end) in md_names(line) {
        let name = &line[start..end - 3];
        let followed = line[end..].chars().next().is_some_and(is_name_char);
        if !followed
            && !name.is_empty()
            && !name.contains('/')
            && name.chars().all(|c| c.is_ascii_uppercase() || c == '_')
        {
            out.push(&line[start..end]);
        }
    }
    out
}

// ---------------------------------------------------------------------------------------------
// (b) crate graph

/// The workspace members (directories relative to the root) from the root `Cargo.toml`.
fn members(root: &Path) -> Vec<String> {
    let text = read(&root.join("Cargo.toml"));
    let Some(k) = text.find("members") else { return Vec::new() };
    let Some(open) = text[k..].find('[') else { return Vec::new() };
    let Some(close) = text[k + open..].find(']') else { return Vec::new() };
    text[k + open + 1..k + open + close]
        .split(',')
        .map(|s| s.trim().trim_matches('"').to_string())
        .filter(|s| !s.is_empty() && !s.starts_with('#'))
        .collect()
}

/// `name = "…"` of a manifest's `[package]` table.
fn package_name(manifest: &str) -> Option<String> {
    let mut in_package = false;
    for line in manifest.lines() {
        let t = line.trim();
        if t.starts_with('[') {
            in_package = t == "[package]";
        } else if in_package {
            if let Some(v) = t.strip_prefix("name") {
                let v = v.trim_start();
                if let Some(v) = v.strip_prefix('=') {
                    return Some(v.trim().trim_matches('"').to_string());
                }
            }
        }
    }
    None
}

/// The keys of a manifest's `[dependencies]` table (also `[dependencies.name]` tables).
fn dependency_names(manifest: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    let mut in_deps = false;
    for line in manifest.lines() {
        let t = line.trim();
        if t.starts_with('[') {
            in_deps = t == "[dependencies]";
            if let Some(name) = t.strip_prefix("[dependencies.").and_then(|s| s.strip_suffix(']')) {
                out.insert(name.trim().to_string());
            }
            continue;
        }
        if in_deps && !t.is_empty() && !t.starts_with('#') {
            let key: String = t.chars().take_while(|&c| is_name_char(c)).collect();
            if !key.is_empty() {
                out.insert(key);
            }
        }
    }
    out
}

/// The allowed edges listed in `ARCHITECTURE.md`: the table under the heading that starts with
/// `## Crate edges`, rows `| `crate` | `dep`, `dep` |` (or `—` for none).
fn listed_edges(architecture: &str) -> BTreeMap<String, BTreeSet<String>> {
    let mut out = BTreeMap::new();
    let mut in_section = false;
    for line in architecture.lines() {
        if line.starts_with("## ") {
            in_section = line.starts_with("## Crate edges");
            continue;
        }
        if !in_section || !line.starts_with('|') {
            continue;
        }
        let cells: Vec<&str> = line.trim().trim_matches('|').split('|').map(str::trim).collect();
        if cells.len() < 2 || !cells[0].starts_with('`') {
            continue;
        }
        let krate = cells[0].trim_matches('`').to_string();
        let deps = cells[1]
            .split(',')
            .map(|s| s.trim().trim_matches('`').to_string())
            .filter(|s| !s.is_empty() && s != "—" && s != "-")
            .collect();
        out.insert(krate, deps);
    }
    out
}

/// Differences between the workspace crates' `[dependencies]` on each other and the edges
/// that `ARCHITECTURE.md` lists (both ways: an undocumented edge, and a listed edge that is
/// gone), and workspace crates with no row.
pub fn check_crate_graph(root: &Path) -> Vec<String> {
    let mut problems = Vec::new();
    let mut crates: BTreeMap<String, String> = BTreeMap::new(); // name → member dir
    for m in members(root) {
        match package_name(&read(&root.join(&m).join("Cargo.toml"))) {
            Some(name) => {
                crates.insert(name, m);
            }
            None => problems.push(format!("{m}/Cargo.toml: no [package] name")),
        }
    }
    let listed = listed_edges(&read(&root.join("ARCHITECTURE.md")));
    if listed.is_empty() {
        problems.push("ARCHITECTURE.md: no `## Crate edges` table".to_string());
        return problems;
    }
    for (name, dir) in &crates {
        let actual: BTreeSet<String> = dependency_names(&read(&root.join(dir).join("Cargo.toml")))
            .into_iter()
            .filter(|d| crates.contains_key(d))
            .collect();
        let Some(allowed) = listed.get(name) else {
            problems.push(format!(
                "ARCHITECTURE.md: crate `{name}` ({dir}) has no row in `## Crate edges`"
            ));
            continue;
        };
        for d in actual.difference(allowed) {
            problems.push(format!(
                "{dir}/Cargo.toml: `{name}` depends on `{d}`, an edge ARCHITECTURE.md does not list"
            ));
        }
        for d in allowed.difference(&actual) {
            problems.push(format!(
                "ARCHITECTURE.md: lists `{name}` → `{d}`, which {dir}/Cargo.toml does not have"
            ));
        }
    }
    for name in listed.keys().filter(|n| !crates.contains_key(*n)) {
        problems.push(format!("ARCHITECTURE.md: `{name}` is not a workspace crate"));
    }
    problems
}

// ---------------------------------------------------------------------------------------------
// (c) module cycles

/// Rust source with comments removed and `#[cfg(test)]` items (test modules) cut out.
fn code_only(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut lines = text.lines().peekable();
    while let Some(line) = lines.next() {
        if line.trim() == "#[cfg(test)]" {
            // skip the next item: up to the matching `}` (or `;` for `mod x;`)
            let mut depth = 0i64;
            let mut opened = false;
            for l in lines.by_ref() {
                let l = strip_comment(l);
                depth += l.matches('{').count() as i64 - l.matches('}').count() as i64;
                opened |= l.contains('{');
                if (opened && depth <= 0) || (!opened && l.trim_end().ends_with(';')) {
                    break;
                }
            }
            continue;
        }
        out.push_str(strip_comment(line));
        out.push('\n');
    }
    out
}

/// A line without its `//` comment (outside string literals, roughly: a `//` inside a string
/// on the same line is rare in this code and only hides an edge).
fn strip_comment(line: &str) -> &str {
    let mut in_str = false;
    let b = line.as_bytes();
    let mut i = 0;
    while i < b.len() {
        match b[i] {
            b'\\' if in_str => i += 1,
            b'"' => in_str = !in_str,
            b'/' if !in_str && b.get(i + 1) == Some(&b'/') => return &line[..i],
            _ => {}
        }
        i += 1;
    }
    line
}

/// The first path segments after every `crate::` in code (a `crate::{a, b::c}` group gives
/// each entry's first segment). `$crate::` (macros) is skipped.
fn crate_paths(code: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    let mut from = 0;
    while let Some(k) = code[from..].find("crate::") {
        let at = from + k;
        from = at + 7;
        let prev = code[..at].chars().next_back();
        if prev.is_some_and(|c| is_name_char(c) || c == '$') {
            continue;
        }
        let rest = &code[from..];
        if let Some(group) = rest.strip_prefix('{') {
            let mut depth = 1;
            let mut entry = String::new();
            let mut first = true;
            for c in group.chars() {
                match c {
                    '{' => depth += 1,
                    '}' => {
                        depth -= 1;
                        if depth == 0 {
                            break;
                        }
                    }
                    ',' if depth == 1 => {
                        if !entry.is_empty() {
                            out.insert(std::mem::take(&mut entry));
                        }
                        first = true;
                        continue;
                    }
                    _ => {}
                }
                if depth == 1 && first {
                    if is_name_char(c) {
                        entry.push(c);
                    } else if !entry.is_empty() {
                        out.insert(std::mem::take(&mut entry));
                        first = false;
                    }
                }
            }
            if !entry.is_empty() {
                out.insert(entry);
            }
        } else {
            let name: String = rest.chars().take_while(|&c| is_name_char(c)).collect();
            if !name.is_empty() {
                out.insert(name);
            }
        }
    }
    out
}

/// Names the crate root re-exports from its modules: `pub use module::Name;` and
/// `pub use module::{A, B as C};` give `Name → module`, `A → module`, `C → module`.
fn reexports(root_code: &str) -> BTreeMap<String, String> {
    let mut out = BTreeMap::new();
    for stmt in root_code.split(';') {
        let s = stmt.trim();
        let Some(s) = s.strip_prefix("pub use ") else { continue };
        let s = s.trim_start_matches("crate::").trim_start_matches("self::");
        let module: String = s.chars().take_while(|&c| is_name_char(c)).collect();
        let tail = &s[module.len()..];
        let Some(tail) = tail.strip_prefix("::") else { continue };
        let names: Vec<&str> = if let Some(g) = tail.strip_prefix('{') {
            g.trim_end_matches('}').split(',').collect()
        } else {
            vec![tail]
        };
        for n in names {
            let n = n.trim();
            let local = n.rsplit(" as ").next().unwrap_or(n).trim();
            let local = local.rsplit("::").next().unwrap_or(local);
            if !local.is_empty() && local != "*" {
                out.insert(local.to_string(), module.clone());
            }
        }
    }
    out
}

/// The crate's top-level module of a source file under `src/` (`None` for the crate root).
fn top_module(src: &Path, file: &Path) -> Option<String> {
    let r = file.strip_prefix(src).ok()?;
    let first = r.components().next()?.as_os_str().to_string_lossy().into_owned();
    let m = first.strip_suffix(".rs").unwrap_or(&first).to_string();
    (!["lib", "main"].contains(&m.as_str()) || r.components().count() > 1).then_some(m)
}

/// Names of the modules a file declares test-only: `#[cfg(test)]` followed by `mod name;`.
fn test_module_names(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut after_cfg_test = false;
    for line in text.lines() {
        let t = line.trim();
        if t.is_empty() {
            continue;
        }
        if after_cfg_test {
            let decl = t.trim_start_matches("pub(crate) ").trim_start_matches("pub ");
            if let Some(name) = decl.strip_prefix("mod ").and_then(|r| r.strip_suffix(';')) {
                out.push(name.trim().to_string());
            }
        }
        after_cfg_test = t == "#[cfg(test)]";
    }
    out
}

/// The files of the test-only modules that `file` declares (`x.rs` or `x/mod.rs` in the
/// directory of `file`'s children).
fn test_module_files(file: &Path, text: &str) -> Vec<PathBuf> {
    let stem = file.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let parent = file.parent().unwrap_or(Path::new(""));
    let dir = if ["lib", "main", "mod"].contains(&stem.as_str()) {
        parent.to_path_buf()
    } else {
        parent.join(&stem)
    };
    test_module_names(text)
        .into_iter()
        .flat_map(|n| [dir.join(format!("{n}.rs")), dir.join(&n).join("mod.rs")])
        .collect()
}

/// The import graph between a crate's top-level modules: `module → modules it names`.
/// Test-only module files (`#[cfg(test)] mod tests;`) and their children do not count.
fn module_graph(src: &Path) -> BTreeMap<String, BTreeSet<String>> {
    let all = files(src, &[".rs"]);
    let test_only: BTreeSet<PathBuf> =
        all.iter().flat_map(|f| test_module_files(f, &read(f))).collect();
    let module_dir = |t: &Path| -> PathBuf {
        if t.file_name().is_some_and(|n| n == "mod.rs") {
            t.parent().unwrap_or(t).to_path_buf()
        } else {
            t.with_extension("")
        }
    };
    let sources: Vec<PathBuf> = all
        .into_iter()
        .filter(|f| !test_only.iter().any(|t| f == t || f.starts_with(module_dir(t))))
        .collect();
    let mut by_module: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    let mut root_code = String::new();
    for f in &sources {
        let code = code_only(&read(f));
        match top_module(src, f) {
            Some(m) => by_module.entry(m).or_default().extend(crate_paths(&code)),
            None => root_code.push_str(&code),
        }
    }
    let exported = reexports(&root_code);
    let modules: BTreeSet<String> = by_module.keys().cloned().collect();
    by_module
        .into_iter()
        .map(|(m, names)| {
            let deps = names
                .into_iter()
                .filter_map(
                    |n| if modules.contains(&n) { Some(n) } else { exported.get(&n).cloned() },
                )
                .filter(|d| *d != m)
                .collect();
            (m, deps)
        })
        .collect()
}

/// Strongly connected components with more than one module (Tarjan), each sorted.
fn cycles(graph: &BTreeMap<String, BTreeSet<String>>) -> Vec<Vec<String>> {
    struct State<'a> {
        graph: &'a BTreeMap<String, BTreeSet<String>>,
        index: BTreeMap<&'a str, usize>,
        low: BTreeMap<&'a str, usize>,
        stack: Vec<&'a str>,
        on_stack: BTreeSet<&'a str>,
        out: Vec<Vec<String>>,
    }
    fn visit<'a>(s: &mut State<'a>, v: &'a str) {
        let i = s.index.len();
        s.index.insert(v, i);
        s.low.insert(v, i);
        s.stack.push(v);
        s.on_stack.insert(v);
        if let Some(next) = s.graph.get(v) {
            for w in next {
                let w = w.as_str();
                if !s.graph.contains_key(w) {
                    continue;
                }
                if !s.index.contains_key(w) {
                    visit(s, w);
                    let lw = s.low[w];
                    let lv = s.low.get_mut(v).expect("visited");
                    *lv = (*lv).min(lw);
                } else if s.on_stack.contains(w) {
                    let iw = s.index[w];
                    let lv = s.low.get_mut(v).expect("visited");
                    *lv = (*lv).min(iw);
                }
            }
        }
        if s.low[v] == s.index[v] {
            let mut comp = Vec::new();
            while let Some(w) = s.stack.pop() {
                s.on_stack.remove(w);
                comp.push(w.to_string());
                if w == v {
                    break;
                }
            }
            if comp.len() > 1 {
                comp.sort();
                s.out.push(comp);
            }
        }
    }
    let mut s = State {
        graph,
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        on_stack: BTreeSet::new(),
        out: Vec::new(),
    };
    for v in graph.keys() {
        if !s.index.contains_key(v.as_str()) {
            visit(&mut s, v);
        }
    }
    s.out.sort();
    s.out
}

/// Import cycles between the top-level modules of each workspace member's `src/`, except
/// those inside one `allowed` entry `(member dir, modules)`.
pub fn check_module_cycles(root: &Path, allowed: &[(&str, &[&str])]) -> Vec<String> {
    let mut problems = Vec::new();
    for m in members(root) {
        let graph = module_graph(&root.join(&m).join("src"));
        for cycle in cycles(&graph) {
            let ok = allowed
                .iter()
                .any(|(dir, mods)| *dir == m && cycle.iter().all(|c| mods.contains(&c.as_str())));
            if !ok {
                let edges: Vec<String> = cycle
                    .iter()
                    .flat_map(|a| {
                        graph[a]
                            .iter()
                            .filter(|b| cycle.contains(b))
                            .map(move |b| format!("{a} → {b}"))
                    })
                    .collect();
                problems.push(format!(
                    "{m}/src: module import cycle {{{}}} ({})",
                    cycle.join(", "),
                    edges.join(", ")
                ));
            }
        }
    }
    problems
}

// ---------------------------------------------------------------------------------------------
// (d) file length

/// Source files under `crates/*/src` longer than `limit` lines, except the `allowed` paths.
pub fn check_file_lengths(root: &Path, limit: usize, allowed: &[&str]) -> Vec<String> {
    let mut problems = Vec::new();
    let Ok(crates) = std::fs::read_dir(root.join("crates")) else { return problems };
    let mut dirs: Vec<PathBuf> = crates.flatten().map(|e| e.path().join("src")).collect();
    dirs.sort();
    for dir in dirs {
        for f in files(&dir, &[".rs"]) {
            let name = rel(root, &f);
            let n = read(&f).lines().count();
            if n > limit && !allowed.contains(&name.as_str()) {
                problems.push(format!("{name}: {n} lines, over the limit of {limit}"));
            }
        }
    }
    problems
}

#[cfg(test)]
mod tests {
    use super::*;

    fn repo_root() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .parent()
            .expect("xtask sits in the workspace")
            .to_path_buf()
    }

    fn assert_clean(problems: Vec<String>) {
        assert!(problems.is_empty(), "{} problem(s):\n{}", problems.len(), problems.join("\n"));
    }

    #[test]
    fn references_resolve() {
        assert_clean(check_references(&repo_root()));
    }

    #[test]
    fn crate_graph_matches_architecture() {
        assert_clean(check_crate_graph(&repo_root()));
    }

    #[test]
    fn no_new_module_cycles() {
        assert_clean(check_module_cycles(&repo_root(), ALLOWED_CYCLES));
    }

    #[test]
    fn no_new_long_files() {
        assert_clean(check_file_lengths(&repo_root(), MAX_LINES, ALLOWED_LONG_FILES));
    }

    /// A fresh directory under the system temp dir, removed on drop.
    struct Scratch(PathBuf);
    impl Scratch {
        fn new(tag: &str) -> Self {
            let p = std::env::temp_dir().join(format!("xtask-tidy-{tag}-{}", std::process::id()));
            let _ = std::fs::remove_dir_all(&p);
            std::fs::create_dir_all(&p).expect("temp dir");
            Scratch(p)
        }
        fn write(&self, rel: &str, text: &str) {
            let p = self.0.join(rel);
            std::fs::create_dir_all(p.parent().expect("parent")).expect("mkdir");
            std::fs::write(p, text).expect("write");
        }
    }
    impl Drop for Scratch {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }

    /// A two-crate workspace: `b` depends on `a`; `a` has modules `x`, `y`.
    fn workspace(tag: &str) -> Scratch {
        let s = Scratch::new(tag);
        s.write(
            "Cargo.toml",
            "[workspace]\nmembers = [\n    \"crates/a\",\n    \"crates/b\",\n]\n",
        );
        s.write(
            "crates/a/Cargo.toml",
            "[package]\nname = \"a\"\n\n[dependencies]\nserde = \"1\"\n",
        );
        s.write(
            "crates/b/Cargo.toml",
            "[package]\nname = \"b\"\n\n[dependencies]\na = { path = \"../a\" }\n",
        );
        s.write(
            "ARCHITECTURE.md",
            "# A\n\n## Crate edges\n\n| crate | depends on |\n|---|---|\n| `a` | — |\n| `b` | `a` |\n\n## Other\n",
        );
        s.write("docs/theory.md", "# Theory\n\n## 1. One\n\ntext\n\n## 2. Two\n\n### 3. Three\n");
        s.write("scenes/s.toml", "");
        s.write("crates/a/src/lib.rs", "//! See theory.md §1–§2 and docs/theory.md §3, scenes/s.toml.\nmod x;\nmod y;\npub use x::X;\n");
        s.write("crates/a/src/x.rs", "use crate::y::Y;\npub struct X(Y);\n");
        s.write(
            "crates/a/src/y.rs",
            "pub struct Y;\n#[cfg(test)]\nmod tests {\n    use crate::X;\n}\n",
        );
        s.write("crates/b/src/lib.rs", "//! (theory.md §1, §2)\n");
        s
    }

    #[test]
    fn clean_tree_passes() {
        let s = workspace("clean");
        assert_clean(check_references(&s.0));
        assert_clean(check_crate_graph(&s.0));
        assert_clean(check_module_cycles(&s.0, &[]));
        assert_clean(check_file_lengths(&s.0, 10, &[]));
    }

    #[test]
    fn planted_bad_references_fail() {
        let s = workspace("refs");
        s.write("crates/b/src/lib.rs", "//! theory.md §4 and `theory.md` §1–5\n");
        s.write(
            "docs/page.md",
            "See LAYOUT.md, docs/missing.md §1, scenes/nope.toml and crates/a/src/z.rs:12.\n\
             ```text\nscenes/output-only.toml:3: an error message\n```\n",
        );
        let p = check_references(&s.0);
        let has = |needle: &str| p.iter().any(|m| m.contains(needle));
        assert!(has("crates/b/src/lib.rs:1: cites `theory.md §4`"), "{p:?}");
        assert!(has("cites `theory.md §5`"), "{p:?}");
        assert!(has("cites `theory.md §4`") && has("cites `theory.md §5`"), "{p:?}");
        assert!(!has("§1`") && !has("§2`") && !has("§3`"), "{p:?}");
        assert!(has("`LAYOUT.md`, which does not exist"), "{p:?}");
        assert!(has("`docs/missing.md` does not exist"), "{p:?}");
        assert!(has("`scenes/nope.toml`, which does not exist"), "{p:?}");
        assert!(has("`crates/a/src/z.rs`, which does not exist"), "{p:?}");
        // §4 twice (once per citation), §5, and the four missing files
        assert_eq!(p.len(), 7, "{p:?}");
    }

    #[test]
    fn planted_crate_edge_fails() {
        let s = workspace("edges");
        s.write(
            "crates/a/Cargo.toml",
            "[package]\nname = \"a\"\n\n[dependencies]\nb.workspace = true\n",
        );
        let p = check_crate_graph(&s.0);
        assert!(
            p.iter()
                .any(|m| m.contains("`a` depends on `b`, an edge ARCHITECTURE.md does not list")),
            "{p:?}"
        );
        // and a listed edge that is gone
        s.write("crates/b/Cargo.toml", "[package]\nname = \"b\"\n");
        let p = check_crate_graph(&s.0);
        assert!(p.iter().any(|m| m.contains("lists `b` → `a`")), "{p:?}");
    }

    #[test]
    fn planted_cycle_fails_and_allow_list_is_exact() {
        let s = workspace("cycle");
        // y → x through the root re-export of `X`, x → y directly
        s.write("crates/a/src/y.rs", "use crate::{X, x::helper};\npub struct Y;\n");
        let p = check_module_cycles(&s.0, &[]);
        assert_eq!(p.len(), 1, "{p:?}");
        assert!(p[0].contains("crates/a/src: module import cycle {x, y}"), "{p:?}");
        assert_clean(check_module_cycles(&s.0, &[("crates/a", &["x", "y"])]));
        // a third module joining the allowed cycle fails again
        s.write("crates/a/src/lib.rs", "mod x;\nmod y;\nmod z;\npub use x::X;\n");
        s.write("crates/a/src/z.rs", "pub fn f() { crate::x::g() }\n");
        s.write("crates/a/src/x.rs", "use crate::y::Y;\nuse crate::z::f;\npub struct X(Y);\n");
        s.write("crates/a/src/y.rs", "use crate::{X, z};\npub struct Y;\n");
        let p = check_module_cycles(&s.0, &[("crates/a", &["x", "y"])]);
        assert!(p.iter().any(|m| m.contains("{x, y, z}")), "{p:?}");
    }

    #[test]
    fn test_module_files_do_not_count() {
        let s = workspace("testmod");
        // y names x only in its test module file y/tests.rs: no cycle
        s.write("crates/a/src/y.rs", "pub struct Y;\n#[cfg(test)]\nmod tests;\n");
        s.write("crates/a/src/y/tests.rs", "use crate::x::X;\n");
        assert_clean(check_module_cycles(&s.0, &[]));
        // the same import in y.rs itself closes the cycle x → y → x
        s.write("crates/a/src/y.rs", "pub struct Y;\npub fn f() -> Option<crate::x::X> { None }\n");
        let p = check_module_cycles(&s.0, &[]);
        assert!(p.iter().any(|m| m.contains("{x, y}")), "{p:?}");
    }

    #[test]
    fn planted_long_file_fails() {
        let s = workspace("long");
        s.write("crates/a/src/long.rs", &"// line\n".repeat(11));
        let p = check_file_lengths(&s.0, 10, &[]);
        assert_eq!(p, vec!["crates/a/src/long.rs: 11 lines, over the limit of 10".to_string()]);
        assert_clean(check_file_lengths(&s.0, 10, &["crates/a/src/long.rs"]));
    }

    #[test]
    fn citation_parser() {
        let c = section_citations(
            "see `docs/mpc.md` §3, theory.md §2–3 and theory.md §1, §6; paper §5",
        );
        assert_eq!(
            c,
            vec![
                ("docs/mpc.md".to_string(), vec![3]),
                ("theory.md".to_string(), vec![2, 3]),
                ("theory.md".to_string(), vec![1, 6]),
            ]
        );
        assert_eq!(
            cited_paths("`git show a432463:crates/x/examples/y.rs`", &["crates/"]),
            Vec::<String>::new()
        );
        assert_eq!(
            cited_paths(
                "(`scenes/paper-{2d,3d}-mpc.toml`; see docs/mpc.md.",
                &["scenes/", "docs/"]
            ),
            ["scenes/paper-2d-mpc.toml", "scenes/paper-3d-mpc.toml", "docs/mpc.md"]
                .map(String::from)
        );
        assert_eq!(
            crate_paths("use crate::{a::B, c, d::{e, f}};\nlet x = crate::g::h(); $crate::i"),
            ["a", "c", "d", "g"].map(String::from).into()
        );
    }
}
