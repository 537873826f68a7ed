//! `flexmpc`: the command-line front end (scene files, runs, reports).

fn main() {
    println!("flexmpc {}", env!("CARGO_PKG_VERSION"));
}
