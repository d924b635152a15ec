//! The variant matrix as data: layout × branching × packet size. Artifact names spell the
//! values (`trav_f16h_b8_p1`).

use crate::bvh::BRANCHINGS;
use crate::encode::Layout;

/// One traversal kernel configuration.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Variant {
    pub layout: Layout,
    pub branching: usize,
    /// Rays per packet (1 = single-ray traversal).
    pub packet: usize,
}

/// Packet sizes of the default matrix (single-ray kernels for now).
pub const PACKETS: [usize; 1] = [1];

/// GPU stack entries per ray for a branching factor: room for (B−1)·depth + 1 entries with
/// depth ≤ 64, 32, 24, 16 for B = 2, 4, 8, 16.
pub fn stack_entries(b: usize) -> usize {
    match b {
        2 => 65,
        4 => 97,
        8 => 169,
        _ => 241,
    }
}

impl Variant {
    pub fn new(layout: Layout, branching: usize, packet: usize) -> Variant {
        Variant { layout, branching, packet }
    }

    /// The kernel's name; with `stats`, the counting variant's.
    pub fn name(&self, stats: bool) -> String {
        format!("trav_{}_b{}_p{}{}", self.layout.name(), self.branching, self.packet, if stats { "_stats" } else { "" })
    }

    /// The default matrix: every layout and B, every packet size.
    pub fn matrix() -> Vec<Variant> {
        let mut v = Vec::new();
        for layout in Layout::ALL {
            for b in BRANCHINGS {
                for p in PACKETS {
                    v.push(Variant::new(layout, b, p));
                }
            }
        }
        v
    }

    /// The GLSL entry file of this variant.
    pub fn source_file(&self) -> &'static str {
        match self.layout {
            Layout::F32 => "trav_f32.comp",
            Layout::F16h => "trav_f16h.comp",
        }
    }

    /// Preprocessor definitions of this variant.
    pub fn defines(&self, stats: bool, f64_fallback: bool) -> Vec<(String, String)> {
        let mut d = vec![
            ("B".to_string(), self.branching.to_string()),
            ("P".to_string(), self.packet.to_string()),
            ("STACK_SIZE".to_string(), stack_entries(self.branching).to_string()),
        ];
        if stats {
            d.push(("STATS".into(), "1".into()));
        }
        if f64_fallback {
            d.push(("HAS_F64".into(), "1".into()));
        }
        d
    }
}

impl std::fmt::Display for Variant {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.name(false))
    }
}
