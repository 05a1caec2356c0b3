//! Benchmark of one servo cycle.
fn main() {}
