//! `halftrace sweep`: a list of jobs — scene × ray set × variant, baseline or user kernel
//! ([`jobs`], from a [`Config`]) — that one executor per device runs through the runner
//! ([`executor`]): each target validated against its reference, then timed and counted; one
//! result row per job, written as it finishes; the report at the end.

pub mod config;
pub mod executor;
pub mod jobs;

pub use config::{check_scenes, Config, KernelSpec, DEFAULT_SCENE};
pub use executor::{prepare_out, run, Summary, OUTPUTS};
pub use jobs::{Job, Shard};
