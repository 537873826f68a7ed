//! An internal error (a bug) as the user sees it: the hidden command `internal-error-check`
//! fails on purpose inside flexmpc. The message says it is a bug and how to report it, exits
//! with 101, and shows no stack trace unless `RUST_BACKTRACE` asks for one.

use std::path::PathBuf;
use std::process::Command;

fn flexmpc() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_flexmpc"));
    c.current_dir(PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../.."));
    c.env_remove("RUST_BACKTRACE").env_remove("RUST_LIB_BACKTRACE");
    c
}

#[test]
fn internal_error_says_it_is_a_bug_and_how_to_report_it() {
    let o = flexmpc().arg("internal-error-check").output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(101), "{err}");
    assert!(o.stdout.is_empty());
    let lines: Vec<&str> = err.lines().collect();
    assert_eq!(lines.len(), 2, "the message and how to report it, nothing else: {err}");
    assert!(
        lines[0].starts_with(&format!("internal error in flexmpc {}: ", env!("CARGO_PKG_VERSION"))),
        "{err}"
    );
    assert!(lines[0].contains("deliberate internal error") && lines[0].contains(".rs:"), "{err}");
    assert_eq!(lines[1], flexmpc::bug_report::HOW_TO_REPORT);
    assert!(lines[1].contains("This is a bug") && lines[1].contains("Reporting bugs"));
    // the README section the message points to exists
    let readme =
        std::fs::read_to_string(PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../README.md"))
            .unwrap();
    assert!(readme.contains("\n## Reporting bugs\n"));
    for bad in ["panicked", "backtrace", "stack", "RUST_BACKTRACE", "http", "example.invalid"] {
        assert!(!err.contains(bad), "`{bad}` in {err}");
    }
    // hidden from the help
    let help = flexmpc().arg("--help").output().unwrap();
    assert!(!String::from_utf8_lossy(&help.stdout).contains("internal-error-check"));
}

/// With `RUST_BACKTRACE=1` the same message comes first, then the stack trace to attach to the
/// report (user errors never show one: `cli_breaks::user_errors_have_no_backtrace`).
#[test]
fn internal_error_with_rust_backtrace_adds_the_trace() {
    let o = flexmpc().env("RUST_BACKTRACE", "1").arg("internal-error-check").output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(101), "{err}");
    let lines: Vec<&str> = err.lines().collect();
    assert!(lines[0].starts_with("internal error in flexmpc"), "{err}");
    assert_eq!(lines[1], flexmpc::bug_report::HOW_TO_REPORT);
    assert!(lines[2].starts_with("stack backtrace"), "{err}");
}
