//! Encoding invariants on every node of every test scene and every B: each stored fp16
//! child box contains the true child box (checked exactly, in f64, in the parent frame), every
//! stored coordinate is finite and within [-16384, 16384], and the frames the traversal
//! derives are the encoder's.

mod common;
use common::*;
use halftrace::bvh::{collapse, ChildRef, WideBvh, BRANCHINGS};
use halftrace::interface::CHILD_EMPTY;
use halftrace::layout::frames::{derive_child, encode_chained, Frame};
use halftrace::layout::{decode_child, encode_child};

fn check<const B: usize>(name: &str, w: &WideBvh) -> usize {
    let (nodes, _, frames) = encode_chained::<B>("f16h", w).unwrap();
    let mut checked = 0;
    assert_eq!(nodes.len(), w.nodes.len());
    for (i, (wn, n)) in w.nodes.iter().zip(&nodes).enumerate() {
        let f: &Frame = &frames[i];
        for s in 0..B {
            if s >= wn.children.len() {
                assert_eq!(n.child[s], CHILD_EMPTY, "{name} B={B} node {i} slot {s} should be empty");
                continue;
            }
            let (bx, c) = &wn.children[s];
            assert_eq!(n.child[s], encode_child(c));
            assert_eq!(decode_child(n.child[s]), *c);
            let (lo, hi) = n.slot_box(s);
            for a in 0..3 {
                let (lo, hi) = (lo[a], hi[a]);
                assert!(lo.is_finite() && hi.is_finite(), "{name} B={B} node {i} slot {s}: non-finite");
                assert!(
                    lo.to_f32().abs() <= 16384.0 && hi.to_f32().abs() <= 16384.0,
                    "{name} B={B} node {i} slot {s}: out of range {lo} {hi}"
                );
                // Exact containment in the parent frame (fp32 inputs, power-of-two scale).
                let tl = (bx.min[a] as f64 - f.w[a] as f64) * f.k as f64;
                let th = (bx.max[a] as f64 - f.w[a] as f64) * f.k as f64;
                assert!(
                    lo.to_f64() <= tl && hi.to_f64() >= th,
                    "{name} B={B} node {i} slot {s} axis {a}: [{lo}, {hi}] does not contain [{tl}, {th}]"
                );
            }
            if let ChildRef::Inner(j) = c {
                assert_eq!(
                    derive_child(f, lo, hi).frame,
                    frames[*j as usize],
                    "{name} B={B}: derived frame of node {j}"
                );
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
            let name = &p.scene.name;
            total += match b {
                2 => check::<2>(name, &w),
                4 => check::<4>(name, &w),
                8 => check::<8>(name, &w),
                _ => check::<16>(name, &w),
            };
        }
    }
    assert!(total > 1_000_000, "only {total} child boxes checked");
    eprintln!("{total} child boxes checked");
}

/// q8 keeps 8 bytes per child plus 24 per node: at B = 8 its node array is at most 0.4 of
/// f32's on every test scene (CWBVH: 80 bytes per 8-wide node), and every layout encodes
/// every test scene at every B.
#[test]
fn q8_nodes_take_at_most_four_tenths_of_f32_at_b8() {
    use halftrace::layout::LayoutId;
    for path in all_scenes() {
        let p = prepare(&path);
        for b in halftrace::bvh::BRANCHINGS {
            let f = encode(&p, LayoutId::f32(), b);
            for l in LayoutId::all() {
                let e = encode(&p, l, b);
                assert_eq!(e.node_count(), f.node_count(), "{} {l} B={b}: the same tree", p.scene.name);
                if l.name() == "q8" && b == 8 {
                    let r = e.node_bytes() as f64 / f.node_bytes() as f64;
                    assert!(r <= 0.4, "{}: q8 ÷ f32 node bytes {r:.3}", p.scene.name);
                }
            }
        }
    }
}
