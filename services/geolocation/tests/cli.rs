//! The `dualgeo-geolocation` binary refuses to start without what the supervisor passes.

#[test]
fn missing_arguments_are_a_usage_error() {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_dualgeo-geolocation"))
        .output()
        .expect("spawn dualgeo-geolocation");
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("--run-id") && stderr.contains("--stats-dir"),
        "{stderr}"
    );
}
