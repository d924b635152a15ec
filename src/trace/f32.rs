//! Reference traversal of the `f32` layout: robust fp32 slab tests (Ize 2013), closest-first
//! order by entry distance, leaves tested as soon as their box is hit.

use super::{slab32, sort_hits, Closest, Counters, Hit, RayPre};
use crate::encode::f32::{F32Bvh, F32Nodes, NodeF32};
use crate::encode::{decode_child, CHILD_EMPTY};
use crate::bvh::ChildRef;
use crate::rays::Ray;

pub fn trace(bvh: &F32Bvh, ray: &Ray) -> (Hit, Counters) {
    match &bvh.nodes {
        F32Nodes::B2(n) => trace_n(bvh, n, ray),
        F32Nodes::B4(n) => trace_n(bvh, n, ray),
        F32Nodes::B8(n) => trace_n(bvh, n, ray),
        F32Nodes::B16(n) => trace_n(bvh, n, ray),
    }
}

fn trace_n<N: NodeF32>(bvh: &F32Bvh, nodes: &[N], ray: &Ray) -> (Hit, Counters) {
    let r = RayPre::new(ray);
    let mut c = Counters { box_tests: 1, ..Default::default() };
    let mut best = Closest::new(ray.tmax);
    let (near, far) = slab32(&r, bvh.root_lo, bvh.root_hi, r.tmin, r.tmax);
    if !(near <= far) {
        return (Hit::MISS, c);
    }
    let mut stack: Vec<(u32, f32)> = Vec::with_capacity(64);
    stack.push((0, near));
    let mut hits = [(0f32, 0usize); 16];
    while let Some((ni, tn)) = stack.pop() {
        if tn > best.t {
            continue;
        }
        c.nodes += 1;
        let n = &nodes[ni as usize];
        let mut nh = 0;
        for s in 0..N::B {
            if n.child(s) == CHILD_EMPTY {
                break;
            }
            c.box_tests += 1;
            let lo = [n.lo(0, s), n.lo(1, s), n.lo(2, s)];
            let hi = [n.hi(0, s), n.hi(1, s), n.hi(2, s)];
            let (near, far) = slab32(&r, lo, hi, r.tmin, best.t);
            if near <= far {
                hits[nh] = (near, s);
                nh += 1;
            }
        }
        sort_hits(&mut hits[..nh], |t| *t);
        let mut inner = [0u32; 16];
        let mut ni_count = 0;
        let mut inner_t = [0f32; 16];
        for &(t, s) in &hits[..nh] {
            match decode_child(n.child(s)) {
                ChildRef::Leaf { first, count } => {
                    for i in first..first + count {
                        c.tri_tests += 1;
                        best.test(&r, &bvh.tris.verts[i as usize], bvh.tris.ids[i as usize] as i32);
                    }
                }
                ChildRef::Inner(j) => {
                    inner[ni_count] = j;
                    inner_t[ni_count] = t;
                    ni_count += 1;
                }
            }
        }
        for k in (0..ni_count).rev() {
            stack.push((inner[k], inner_t[k]));
        }
    }
    c.packet_nodes = c.nodes;
    c.active_lanes = c.nodes;
    (best.hit(), c)
}

/// Packet traversal of up to 64 rays (see [`super::packet`] for the rule); returns each
/// ray's hit and counters, the packet's counters in the first ray's.
pub fn trace_packet(bvh: &F32Bvh, rays: &[Ray]) -> Vec<(Hit, Counters)> {
    match &bvh.nodes {
        F32Nodes::B2(n) => packet_n(bvh, n, rays),
        F32Nodes::B4(n) => packet_n(bvh, n, rays),
        F32Nodes::B8(n) => packet_n(bvh, n, rays),
        F32Nodes::B16(n) => packet_n(bvh, n, rays),
    }
}

fn packet_n<N: NodeF32>(bvh: &F32Bvh, nodes: &[N], rays: &[Ray]) -> Vec<(Hit, Counters)> {
    let p = rays.len();
    let pre: Vec<RayPre> = rays.iter().map(RayPre::new).collect();
    let mut best: Vec<Closest> = rays.iter().map(|r| Closest::new(r.tmax)).collect();
    let mut c = vec![Counters { box_tests: 1, ..Default::default() }; p];
    let (mut pnodes, mut active_sum) = (0u32, 0u32);
    // Per lane: the entry distance of the node, or None (inactive).
    let roots: Vec<Option<f32>> = pre
        .iter()
        .map(|r| {
            let (near, far) = slab32(r, bvh.root_lo, bvh.root_hi, r.tmin, r.tmax);
            (near <= far).then_some(near)
        })
        .collect();
    let mut stack: Vec<(u32, Vec<Option<f32>>)> = Vec::new();
    if roots.iter().any(|r| r.is_some()) {
        stack.push((0, roots));
    }
    while let Some((ni, tns)) = stack.pop() {
        let active: Vec<bool> = (0..p).map(|l| tns[l].is_some_and(|t| t <= best[l].t)).collect();
        if !active.iter().any(|&a| a) {
            continue;
        }
        pnodes += 1;
        active_sum += active.iter().filter(|&&a| a).count() as u32;
        let n = &nodes[ni as usize];
        let mut slots: Vec<(f32, usize, Vec<Option<f32>>)> = Vec::new();
        for s in 0..N::B {
            if n.child(s) == CHILD_EMPTY {
                break;
            }
            let lo = [n.lo(0, s), n.lo(1, s), n.lo(2, s)];
            let hi = [n.hi(0, s), n.hi(1, s), n.hi(2, s)];
            let mut key = f32::INFINITY;
            let res: Vec<Option<f32>> = (0..p)
                .map(|l| {
                    if !active[l] {
                        return None;
                    }
                    c[l].box_tests += 1;
                    let (near, far) = slab32(&pre[l], lo, hi, pre[l].tmin, best[l].t);
                    (near <= far).then(|| {
                        key = key.min(near);
                        near
                    })
                })
                .collect();
            if res.iter().any(|r| r.is_some()) {
                slots.push((key, s, res));
            }
        }
        super::packet::order(&mut slots);
        let mut pending = Vec::new();
        for (_, s, res) in slots {
            match decode_child(n.child(s)) {
                ChildRef::Leaf { first, count } => {
                    for l in (0..p).filter(|&l| res[l].is_some()) {
                        for i in first..first + count {
                            c[l].tri_tests += 1;
                            best[l].test(&pre[l], &bvh.tris.verts[i as usize], bvh.tris.ids[i as usize] as i32);
                        }
                    }
                }
                ChildRef::Inner(j) => pending.push((j, res)),
            }
        }
        for l in 0..p {
            if active[l] {
                c[l].nodes += 1;
            }
        }
        stack.extend(pending.into_iter().rev());
    }
    c[0].packet_nodes = pnodes;
    c[0].active_lanes = active_sum;
    best.iter().zip(c).map(|(b, c)| (b.hit(), c)).collect()
}
