//! `halftrace sweep`: a configuration ([`Config`]) checked into typed values once ([`Sweep`]),
//! then a list of jobs — scene × ray set × variant, baseline or user kernel, each carrying
//! what its row needs ([`jobs`]) — that one executor per device runs through the runner
//! ([`executor`]): each target validated against its reference, then timed and counted; one
//! result row per job, written as it finishes; the report at the end.

pub mod config;
pub mod executor;
pub mod jobs;

pub use config::{check_scenes, Config, KernelTable, Sweep, UserKernel, DEFAULT_SCENE};
pub use executor::{prepare_out, run, Summary, OUTPUTS};
pub use jobs::{Job, SceneFile, Shard};
