//! `cargo afl fuzz` entry point of the `config` target (see the crate's documentation).
fn main() {
    afl::fuzz!(|data: &[u8]| dualgeo_fuzz::targets::config(data));
}
