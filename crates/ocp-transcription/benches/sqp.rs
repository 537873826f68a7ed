//! Criterion benches of the SQP (filled in later).
fn main() {}
