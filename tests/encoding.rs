//! Encoding invariants on every node of every shared scene and every B: each stored fp16
//! child box contains the true child box (checked exactly, in f64, in the parent frame), every
//! stored coordinate is finite and within [-16384, 16384], and the frames the traversal
//! derives are the encoder's.

mod common;
use common::*;
use halftrace::bvh::{collapse, ChildRef, BRANCHINGS};
use halftrace::encode::f16h::{self, derive_child, F16hNodes, NodeF16h};
use halftrace::encode::{decode_child, encode_child, CHILD_EMPTY};

fn check<N: NodeF16h>(name: &str, b: usize, w: &halftrace::bvh::WideBvh, enc: &f16h::F16hBvh, nodes: &[N]) -> usize {
    let mut checked = 0;
    assert_eq!(nodes.len(), w.nodes.len());
    for (i, (wn, n)) in w.nodes.iter().zip(nodes).enumerate() {
        let f = &enc.frames[i];
        for s in 0..N::B {
            if s >= wn.children.len() {
                assert_eq!(n.child(s), CHILD_EMPTY, "{name} B={b} node {i} slot {s} should be empty");
                continue;
            }
            let (bx, c) = &wn.children[s];
            assert_eq!(n.child(s), encode_child(c));
            assert_eq!(decode_child(n.child(s)), *c);
            for a in 0..3 {
                let (lo, hi) = (n.lo(a, s), n.hi(a, s));
                assert!(lo.is_finite() && hi.is_finite(), "{name} B={b} node {i} slot {s}: non-finite");
                assert!(lo.to_f32().abs() <= 16384.0 && hi.to_f32().abs() <= 16384.0, "{name} B={b} node {i} slot {s}: out of range {lo} {hi}");
                // Exact containment in the parent frame (fp32 inputs, power-of-two scale).
                let tl = (bx.min[a] as f64 - f.w[a] as f64) * f.k as f64;
                let th = (bx.max[a] as f64 - f.w[a] as f64) * f.k as f64;
                assert!(lo.to_f64() <= tl && hi.to_f64() >= th, "{name} B={b} node {i} slot {s} axis {a}: [{lo}, {hi}] does not contain [{tl}, {th}]");
            }
            if let ChildRef::Inner(j) = c {
                let lo = [n.lo(0, s), n.lo(1, s), n.lo(2, s)];
                let hi = [n.hi(0, s), n.hi(1, s), n.hi(2, s)];
                assert_eq!(derive_child(f, lo, hi).frame, enc.frames[*j as usize], "{name} B={b}: derived frame of node {j}");
            }
            checked += 1;
        }
    }
    checked
}

#[test]
fn every_node_of_every_scene_satisfies_the_f16h_invariants() {
    let mut total = 0;
    for path in all_scenes() {
        let p = prepare(&path);
        for b in BRANCHINGS {
            let w = collapse(&p.bin, b);
            let enc = f16h::encode(&p.scene, &w).unwrap();
            let name = &p.scene.name;
            total += match &enc.nodes {
                F16hNodes::B2(n) => check(name, b, &w, &enc, n),
                F16hNodes::B4(n) => check(name, b, &w, &enc, n),
                F16hNodes::B8(n) => check(name, b, &w, &enc, n),
                F16hNodes::B16(n) => check(name, b, &w, &enc, n),
            };
        }
    }
    assert!(total > 1_000_000, "only {total} child boxes checked");
    eprintln!("{total} child boxes checked");
}
