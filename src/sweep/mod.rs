//! `halftrace sweep`: a configuration ([`Config`]) checked into typed values once ([`Sweep`]),
//! then a list of jobs — scene × ray set × variant, baseline or user kernel, each carrying
//! what its row needs ([`jobs`]) — that one executor per device runs through the runner
//! ([`executor`]): each target validated against its reference, then timed and counted; one
//! result row per job, written as it finishes; the report at the end.

pub mod config;
pub mod executor;
pub mod jobs;

pub use config::{check_scenes, Config, KernelTable, Sweep, UserKernel, DEFAULT_SCENE};
pub use executor::{prepare_out, run, OutMode, Summary};
pub use jobs::{Job, SceneFile, Shard};

use std::path::PathBuf;

/// `reports/<UTC timestamp>` for a default output folder.
pub fn default_out() -> PathBuf {
    let secs =
        std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map(|d| d.as_secs()).unwrap_or(0) as i64;
    let (days, rem) = (secs.div_euclid(86400), secs.rem_euclid(86400));
    // civil-from-days (H. Hinnant)
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + if m <= 2 { 1 } else { 0 };
    PathBuf::from(format!("reports/{y:04}{m:02}{d:02}-{:02}{:02}{:02}", rem / 3600, rem % 3600 / 60, rem % 60))
}
