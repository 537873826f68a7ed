//! The command blocks of `docs/guide.md` and `README.md` run: every `cargo run --release [--
//! ARGS]` line of a ```sh block is run as `flexmpc ARGS`, in a scratch folder holding copies of
//! `scenes/` on 4 elements per beam (`check` also runs on the shipped scenes themselves), with
//! `--duration 0.4` added to `mpc` and `sweep` and `0.05` to `simulate` when the line gives
//! none, and `/tmp/` read as a folder of the scratch. Each must succeed; an `out/…` path its
//! comment names must exist afterwards; a `diff -r A B` line compares the two folders byte
//! for byte. Lines with placeholders (`[--plant fe|rom]`) are skipped; the other `cargo`
//! commands (`test`, `install`, `xtask`) are not flexmpc's.

use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// `(line number, line)` of every line inside a ```sh block of `text`.
fn sh_lines(text: &str) -> Vec<(usize, String)> {
    let mut out = Vec::new();
    let mut inside = false;
    for (i, l) in text.lines().enumerate() {
        let t = l.trim();
        if t.starts_with("```") {
            inside = t == "```sh";
            continue;
        }
        if inside && !t.is_empty() && !t.starts_with('#') {
            out.push((i + 1, t.to_string()));
        }
    }
    out
}

/// Splits `cmd  # comment` (a `#` after whitespace starts the comment).
fn split_comment(line: &str) -> (&str, &str) {
    match line.find(" #") {
        Some(i) => (line[..i].trim(), line[i + 2..].trim()),
        None => (line.trim(), ""),
    }
}

/// Every file under `dir`, relative, with its bytes.
fn tree(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push((p.strip_prefix(dir).unwrap().to_path_buf(), std::fs::read(&p).unwrap()));
            }
        }
    }
    out.sort();
    out
}

#[test]
fn guide_and_readme_command_blocks_run() {
    let scratch = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("guide-commands");
    let _ = std::fs::remove_dir_all(&scratch);
    std::fs::create_dir_all(scratch.join("scenes")).unwrap();
    std::fs::create_dir_all(scratch.join("tmp")).unwrap();
    for e in std::fs::read_dir(root().join("scenes")).unwrap() {
        let p = e.unwrap().path();
        let text = std::fs::read_to_string(&p).unwrap();
        let small: String = text
            .lines()
            .map(|l| if l.starts_with("elements = ") { "elements = 4" } else { l })
            .collect::<Vec<_>>()
            .join("\n");
        std::fs::write(scratch.join("scenes").join(p.file_name().unwrap()), small).unwrap();
    }
    let mut ran = 0;
    let mut scenes_named = std::collections::BTreeSet::new();
    for doc in ["docs/guide.md", "README.md"] {
        let text = std::fs::read_to_string(root().join(doc)).unwrap();
        for (n, line) in sh_lines(&text) {
            let (cmd, comment) = split_comment(&line);
            let at = format!("{doc}:{n}: `{cmd}`");
            let words: Vec<&str> = cmd.split_whitespace().collect();
            if words.first() == Some(&"diff") {
                assert_eq!(words[1], "-r", "{at}");
                let dir = |w: &str| scratch.join(w.trim_start_matches('/'));
                assert_eq!(tree(&dir(words[2])), tree(&dir(words[3])), "{at}: folders differ");
                continue;
            }
            if words.first() != Some(&"cargo") || words.get(1) != Some(&"run") {
                continue;
            }
            if cmd.contains('[') || cmd.contains('|') {
                continue; // a synopsis with placeholders
            }
            assert_eq!(words.get(2), Some(&"--release"), "{at}");
            let mut args: Vec<String> = match words.get(3) {
                None => vec![],
                Some(&"--") => words[4..].iter().map(|w| w.to_string()).collect(),
                Some(w) => panic!("{at}: `{w}` after --release"),
            };
            for a in &mut args {
                if let Some(rest) = a.strip_prefix("/tmp/") {
                    *a = format!("tmp/{rest}");
                }
                if a.starts_with("scenes/") {
                    scenes_named.insert(a.clone());
                }
            }
            let sub = args.iter().find(|a| !a.starts_with("--")).cloned().unwrap_or_default();
            let default_duration = match sub.as_str() {
                "mpc" | "sweep" => Some("0.4"),
                "simulate" => Some("0.05"),
                _ => None,
            };
            if let Some(d) = default_duration {
                if !args.iter().any(|a| a == "--duration") {
                    args.extend(["--duration".to_string(), d.to_string()]);
                }
            }
            let o = Command::new(env!("CARGO_BIN_EXE_flexmpc"))
                .current_dir(&scratch)
                .env_remove("RUST_BACKTRACE")
                .args(&args)
                .output()
                .unwrap();
            assert!(
                o.status.success(),
                "{at} as `flexmpc {}`: {}",
                args.join(" "),
                String::from_utf8_lossy(&o.stderr)
            );
            for w in comment.split_whitespace() {
                let w = w.trim_end_matches([',', ';', ':', ')']);
                if w.starts_with("out/") && !w.contains('<') && !w.contains('…') {
                    assert!(scratch.join(w).exists(), "{at}: the comment names {w}, not written");
                }
            }
            ran += 1;
        }
    }
    assert!(ran >= 15, "only {ran} commands found");
    // the shipped scenes the blocks name pass `check` at their full size
    for s in &scenes_named {
        let o = Command::new(env!("CARGO_BIN_EXE_flexmpc"))
            .current_dir(root())
            .args(["--quiet", "check", s])
            .output()
            .unwrap();
        assert!(o.status.success(), "check {s}: {}", String::from_utf8_lossy(&o.stderr));
    }
    assert!(scenes_named.len() >= 6, "{scenes_named:?}");
}
