//! How far two traversal results agree ([`agreement`]), how busy a packet's lanes were and the
//! mean counters per ray, and what one run returns ([`RunOutput`]).

use super::hit::{Counters, Hit};

/// How many rays of one result agree with a reference: same hit/miss, and the same `prim` or,
/// where triangles tie or share edges, `t` within 1e-5 relative. This is the one definition of
/// "differs from f32" in reports ([`Agreement::differs`]); the exact layouts are held to more —
/// bitwise equality with their CPU reference — by validation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Agreement {
    pub agree: usize,
    pub total: usize,
    pub false_misses: usize,
    pub max_abs_dt: f64,
}

impl Agreement {
    /// Rays that disagree.
    pub fn differs(&self) -> usize {
        self.total - self.agree
    }

    pub fn rate(&self) -> f64 {
        if self.total == 0 {
            1.0
        } else {
            self.agree as f64 / self.total as f64
        }
    }
}

pub fn agreement(got: &[Hit], reference: &[Hit]) -> Agreement {
    let mut a = Agreement { agree: 0, total: got.len(), false_misses: 0, max_abs_dt: 0.0 };
    for (g, r) in got.iter().zip(reference) {
        let ok = match (g.is_hit(), r.is_hit()) {
            (false, false) => true,
            (true, true) => {
                let dt = (g.t as f64 - r.t as f64).abs();
                a.max_abs_dt = a.max_abs_dt.max(dt);
                g.prim == r.prim || dt <= 1e-5 * (r.t as f64).abs().max(f64::MIN_POSITIVE)
            }
            (false, true) => {
                a.false_misses += 1;
                false
            }
            (true, false) => false,
        };
        a.agree += ok as usize;
    }
    a
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

/// Mean counters over a ray set: nodes, box tests, triangle tests, re-anchors per ray.
pub fn mean_counters(c: &[Counters]) -> [f64; 4] {
    let n = c.len().max(1) as f64;
    let mut s = [0f64; 4];
    for x in c {
        s[0] += x.nodes as f64;
        s[1] += x.box_tests as f64;
        s[2] += x.tri_tests as f64;
        s[3] += x.reanchors as f64;
    }
    s.map(|v| v / n)
}

/// Hits (and counters, for a counting kernel) and the time of each timed run, ms.
pub struct RunOutput {
    pub hits: Vec<Hit>,
    pub counters: Option<Vec<Counters>>,
    pub times_ms: Vec<f64>,
    /// Rays the traversal flagged and the exact re-trace decided (0 where nothing re-traced:
    /// a kernel's own output keeps its flags, `Hit::is_flagged`).
    pub flagged: usize,
}
