//! The work of each subcommand, one file each: arguments ([`crate::cli`]) in, lines on stdout
//! and files out. `main.rs` only parses and dispatches.

mod bench;
mod bvh_stats;
mod conformance;
mod device_report;
mod devices;
mod estimate;
mod instance;
mod isa;
mod memory;
mod report;
mod shaders;
mod sweep;
mod trace;

pub use bench::bench;
pub use bvh_stats::bvh_stats;
pub use conformance::conformance;
pub use device_report::device_report;
pub use devices::devices;
pub use estimate::estimate;
pub use instance::instance;
pub use isa::{isa, isa_model, probe_family};
pub use memory::memory;
pub use report::report;
pub use shaders::shaders;
pub use sweep::sweep;
pub use trace::trace;

/// Writes a line to stdout, returning I/O errors (a closed pipe ends the command quietly).
macro_rules! outln {
    ($($t:tt)*) => { { use std::io::Write as _; writeln!(std::io::stdout(), $($t)*)? } };
}
pub(crate) use outln;
