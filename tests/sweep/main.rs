//! End to end: a small sweep on the default device (lavapipe in CI) writes every output,
//! with one consistent row per variant; an interrupted sweep keeps its finished rows; a
//! folder with results is refused, resumed or replaced; `report` merges folders and shards.
//! One test binary, a module per concern.

mod device_report;
mod folders;
mod outputs;
mod report;

pub use halftrace::report::tables::ratios;
pub use halftrace::report::{read_rows, Row, Status};
pub use std::path::{Path, PathBuf};
pub use std::process::Command;

pub fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("halftrace-sweep-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

pub fn teapot() -> String {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scenes/teapot.obj").display().to_string()
}

pub fn sweep(out: &Path, extra: &[&str]) -> std::process::Output {
    sweep_cmd(out, extra).output().unwrap()
}

/// The small sweep's command, to run with extra environment.
pub fn sweep_cmd(out: &Path, extra: &[&str]) -> Command {
    let scene = teapot();
    let mut args = vec![
        "sweep",
        "--quiet",
        "--scene",
        &scene,
        "--width",
        "24",
        "--height",
        "24",
        "--repeat",
        "3",
        "--warmup",
        "1",
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    let mut c = Command::new(env!("CARGO_BIN_EXE_halftrace"));
    c.args(&args);
    c
}
