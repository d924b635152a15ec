//! Packet traversal: P rays share one node sequence.
//!
//! Rule (identical in the CPU reference and the shaders):
//! - A ray is *active* for a popped node when it hit that node's box and its closest hit so
//!   far is not nearer than its entry bound. The node is visited when any ray is active;
//!   otherwise it is skipped. Each active ray counts the visit and its box tests.
//! - A child is visited when any active ray hits it. Children are ordered once per packet by
//!   the smallest entry distance among the rays that hit them (the f16h entry is in each
//!   ray's own node frame, the same scale for every ray of a packet up to its direction's
//!   largest component), ties by slot. Leaves are tested, in that order, by the rays that hit
//!   them; inner children are pushed farthest first.
//! - Each ray keeps its own closest hit and, for f16h, its own moved origin and error bound
//!   per stack level (inactive rays carry none).
//!
//! Packets are P consecutive rays; the last may be partial. P = 1 is single-ray traversal.

use super::{Counters, Hit};
use crate::encode::f16h::F16hBvh;
use crate::encode::f32::F32Bvh;
use crate::rays::Ray;
use rayon::prelude::*;

/// Sorts (key, slot, per-lane results) ascending by key, then slot. Keys are never NaN;
/// −0 and +0 compare equal, as in the shaders.
pub(crate) fn order<T>(slots: &mut [(f32, usize, T)]) {
    slots.sort_by(|a, b| a.0.partial_cmp(&b.0).unwrap_or(std::cmp::Ordering::Equal).then(a.1.cmp(&b.1)));
}

/// Packet sizes the harness supports.
pub const PACKETS: [usize; 6] = [1, 4, 8, 16, 32, 64];

/// Traces rays in packets of `p` consecutive rays with `f`.
pub fn trace_packets<F>(rays: &[Ray], p: usize, f: F) -> (Vec<Hit>, Vec<Counters>)
where
    F: Fn(&[Ray]) -> Vec<(Hit, Counters)> + Sync + Send,
{
    let per: Vec<Vec<(Hit, Counters)>> = rays.par_chunks(p.max(1)).map(&f).collect();
    per.into_iter().flatten().unzip()
}

pub fn trace_f32(bvh: &F32Bvh, rays: &[Ray], p: usize) -> (Vec<Hit>, Vec<Counters>) {
    trace_packets(rays, p, |r| super::f32::trace_packet(bvh, r))
}

pub fn trace_f16h(bvh: &F16hBvh, rays: &[Ray], p: usize, math: super::f16h::Math) -> (Vec<Hit>, Vec<Counters>) {
    trace_packets(rays, p, |r| super::f16h::trace_packet(bvh, r, math))
}

/// Share of active rays per visited packet node: Σ active / (Σ packet visits · P).
pub fn simd_utilisation(c: &[Counters], p: usize) -> f64 {
    let visits: u64 = c.iter().map(|x| x.packet_nodes as u64).sum();
    let active: u64 = c.iter().map(|x| x.active_lanes as u64).sum();
    if visits == 0 {
        1.0
    } else {
        active as f64 / (visits as f64 * p as f64)
    }
}
