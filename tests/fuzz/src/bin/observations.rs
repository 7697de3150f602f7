//! `cargo afl fuzz` entry point of the `observations` target (see the crate's documentation).
fn main() {
    afl::fuzz!(|data: &[u8]| dualgeo_fuzz::targets::observations(data));
}
