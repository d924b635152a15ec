//! BVH construction: one binary SAH build in fp32 ([`build`]), collapsed to B-wide nodes
//! ([`wide`]), with statistics ([`stats`]). Encoders turn a [`WideBvh`] into GPU layouts.

pub mod build;
mod bx;
pub mod exact;
mod split;
pub mod stats;
pub mod wide;

pub use build::{build_binary, BinaryBvh, BinaryNode};
pub use wide::{breadth_first, collapse, ChildRef, WideBvh, WideNode};

use thiserror::Error;

/// Branching factors the harness supports.
pub const BRANCHINGS: [usize; 4] = [2, 4, 8, 16];

#[derive(Debug, Error, PartialEq)]
pub enum BvhError {
    #[error("branching factor {0} is not supported (use one of 2, 4, 8, 16)")]
    Branching(usize),
}

/// Checks a branching factor given on the command line or in a config.
pub fn check_branching(b: usize) -> Result<usize, BvhError> {
    if BRANCHINGS.contains(&b) {
        Ok(b)
    } else {
        Err(BvhError::Branching(b))
    }
}
