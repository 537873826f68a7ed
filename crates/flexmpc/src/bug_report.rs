//! Internal errors: a panic is a bug in flexmpc, never a mistake in the input (those are
//! `Result` errors that name the file, line and field). The message says so and how to report
//! it. flexmpc has no public issue tracker; bugs go to its maintainers as README.md,
//! "Reporting bugs", describes.

use std::io::Write;

/// How to report a bug, the last line of every internal-error message.
pub const HOW_TO_REPORT: &str = "This is a bug in flexmpc, not a mistake in your input. Please \
report it to the flexmpc maintainers with the command line, the scene file and this message \
(README.md, \"Reporting bugs\").";

/// The message of an internal error: what failed (`what`, the panic's message), where in the
/// code (`at`: `file:line`), the version, and [`HOW_TO_REPORT`].
///
/// ```
/// let m = flexmpc::bug_report::message("index out of bounds", Some("src/x.rs:3"));
/// assert!(m.starts_with("internal error in flexmpc"));
/// assert!(m.contains("index out of bounds at src/x.rs:3"));
/// assert!(m.ends_with(flexmpc::bug_report::HOW_TO_REPORT));
/// ```
pub fn message(what: &str, at: Option<&str>) -> String {
    let at = at.map(|l| format!(" at {l}")).unwrap_or_default();
    format!("internal error in flexmpc {}: {what}{at}\n{HOW_TO_REPORT}", env!("CARGO_PKG_VERSION"))
}

/// Installs the panic hook of the `flexmpc` binary: a panic prints [`message`] on stderr, and a
/// stack trace only when `RUST_BACKTRACE` asks for one (then it is worth attaching to the
/// report); the process then exits with status 101.
pub fn install_panic_hook() {
    std::panic::set_hook(Box::new(|info| {
        let what = info
            .payload()
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| info.payload().downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "(no message)".into());
        let at = info.location().map(|l| format!("{}:{}", l.file(), l.line()));
        let mut e = std::io::stderr().lock();
        let _ = writeln!(e, "{}", message(&what, at.as_deref()));
        let bt = std::backtrace::Backtrace::capture();
        if bt.status() == std::backtrace::BacktraceStatus::Captured {
            let _ = writeln!(e, "stack backtrace (RUST_BACKTRACE is set):\n{bt}");
        }
    }));
}

/// Fails with an internal error on purpose, so that tests can check what a user sees on a
/// bug (the hidden command `flexmpc internal-error-check` calls it).
#[doc(hidden)]
pub fn fail_on_purpose() -> ! {
    panic!("deliberate internal error (internal-error-check)")
}
