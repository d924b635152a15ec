//! Each step's child command, typed. `commands` turns one into the binary's arguments from
//! the command's own clap arguments ([`super::Options::argv`]), and a test there parses each
//! back, so a renamed flag fails in the tests, not in a report.

use crate::rays::RayKind;
use std::path::PathBuf;

/// A step's child command: what the report asks of it.
#[derive(Clone, Debug, PartialEq)]
pub enum Child {
    /// `devices`: what the device runs.
    Devices { mask_features: Vec<String> },
    /// `conformance --quick` on one scene into the report's own folder (replaced).
    Conformance { scene: PathBuf, device: String, mask_features: Vec<String>, out: PathBuf },
    /// A short `bench` into one Markdown file.
    Bench {
        scene: PathBuf,
        device: String,
        rays: Vec<RayKind>,
        rounds: usize,
        repeat: usize,
        width: u32,
        height: u32,
        out: PathBuf,
    },
    /// A quiet `sweep` in a budget, resumed or replacing its own files where its folder has
    /// some.
    Sweep {
        scenes: Vec<PathBuf>,
        device: String,
        mask_features: Vec<String>,
        width: u32,
        height: u32,
        kernel_timeout_s: f64,
        budget_s: f64,
        out: PathBuf,
        resume: bool,
        force: bool,
    },
    /// A quiet `isa` of the device into the sweep's folder (its own files replaced).
    Isa { device: String, out: PathBuf },
}
