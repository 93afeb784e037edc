//! Placeholder until the frame benches land.
fn main() {}
