//! `cargo afl fuzz` entry point of the `flight` target (see the crate's documentation).
fn main() {
    afl::fuzz!(|data: &[u8]| dualgeo_fuzz::targets::flight(data));
}
