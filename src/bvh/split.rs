//! The split of one node of the binned SAH build ([`super::build`]): each triangle's centroid
//! binned per axis (a float's bits give the bin), the cheapest boundary found by sweeping the
//! bins — or, for nodes of at most `SMALL` triangles, by sorting, which finds the split the
//! bins would — and the node's range partitioned in place.

use super::bx::*;
use glam::Vec3A;

/// 2^23: adding it to a float in [0, 2^22) leaves that float rounded to the nearest integer in
/// the low mantissa bits — a bin index without a (saturating, and slow) float-to-int conversion.
pub(super) const MAGIC: f32 = 8_388_608.0;

/// The bin of a position already mapped to [0, BINS − 1] and offset by `MAGIC`; binning and
/// partition both go through this, so both sides of a split match the bins' counts.
#[inline(always)]
pub(super) fn bin_of(t: f32) -> usize {
    (t.to_bits() & (BINS as u32 - 1)) as usize
}

/// Per axis, per bin: box and count (structure of arrays: one min and one max per update).
pub(super) struct Bins {
    lo: [[Vec3A; BINS]; 3],
    hi: [[Vec3A; BINS]; 3],
    count: [[u32; BINS]; 3],
}

impl Bins {
    fn new() -> Bins {
        Bins { lo: [[Vec3A::INFINITY; BINS]; 3], hi: [[Vec3A::NEG_INFINITY; BINS]; 3], count: [[0; BINS]; 3] }
    }
}

/// Twice the centroid, mapped so `bin_of` of each lane gives that axis's bin.
#[inline(always)]
pub(super) fn bin_pos(r: &Ref, origin2: Vec3A, scale2: Vec3A) -> [f32; 3] {
    ((r.min + r.max - origin2) * scale2 + Vec3A::splat(MAGIC)).to_array()
}

pub(super) fn bin_chunk<'a>(refs: impl IntoIterator<Item = &'a Ref>, origin2: Vec3A, scale2: Vec3A) -> Bins {
    let mut bins = Bins::new();
    for r in refs {
        for (a, &t) in bin_pos(r, origin2, scale2).iter().enumerate() {
            let i = bin_of(t);
            bins.lo[a][i] = bins.lo[a][i].min(r.min);
            bins.hi[a][i] = bins.hi[a][i].max(r.max);
            bins.count[a][i] += 1;
        }
    }
    bins
}

/// A chosen split: position in the range and both children's bounds and centroid bounds.
pub(super) struct Split {
    pub(super) mid: usize,
    pub(super) lb: Bx,
    pub(super) lcb: Bx,
    pub(super) rb: Bx,
    pub(super) rcb: Bx,
}

/// The cheapest split so far: (cost, axis, last bin of the left side, left box, right box).
pub(super) type Best = (f32, usize, usize, Bx, Bx);

/// The binned SAH over the bins of nodes above `SMALL` triangles: only occupied bins can end
/// a side (an empty bin repeats its neighbour's partition and cost).
pub(super) fn sweep_bins(bins: &Bins, ext: Vec3A, best: &mut Best) {
    for a in 0..3 {
        if ext[a] <= 0.0 {
            continue;
        }
        let mut occ = [0usize; BINS];
        let mut m = 0;
        for (i, &c) in bins.count[a].iter().enumerate() {
            if c > 0 {
                occ[m] = i;
                m += 1;
            }
        }
        if m < 2 {
            continue;
        }
        let mut right_box = [Bx::EMPTY; BINS];
        let mut right_count = [0u32; BINS];
        let (mut rb, mut rc) = (Bx::EMPTY, 0u32);
        for j in (1..m).rev() {
            let i = occ[j];
            rb = rb.union(&Bx { min: bins.lo[a][i], max: bins.hi[a][i] });
            rc += bins.count[a][i];
            right_box[j] = rb;
            right_count[j] = rc;
        }
        let (mut lb, mut lc) = (Bx::EMPTY, 0u32);
        for j in 0..m - 1 {
            let i = occ[j];
            lb = lb.union(&Bx { min: bins.lo[a][i], max: bins.hi[a][i] });
            lc += bins.count[a][i];
            let cost = lb.area() * lc as f32 + right_box[j + 1].area() * right_count[j + 1] as f32;
            if cost < best.0 {
                *best = (cost, a, i, lb, right_box[j + 1]);
            }
        }
    }
}

/// The same binned SAH for nodes of at most `SMALL` triangles, without bins: per axis the
/// triangles sorted by (bin, position), and a side ends wherever the bin changes — the same
/// candidates in the same order, with the same boxes (unions are exact) and counts, so the
/// same costs and the same choice. One instance per node size: every loop has a fixed length
/// (unrolled, no mispredicted loop exits) and the choice is kept without branches.
pub(super) fn sweep_small<const N: usize>(refs: &[Ref], origin2: Vec3A, scale2: Vec3A, ext: Vec3A, best: &mut Best) {
    let refs: &[Ref; N] = refs.try_into().expect("node of N triangles");
    let pos: [[f32; 3]; N] = std::array::from_fn(|j| bin_pos(&refs[j], origin2, scale2));
    // The cheapest candidate as one integer to minimise without branches: costs are finite and
    // non-negative, so their bits order as they do; then axis, then position (the first of
    // equal costs wins, as in the bins' sweep).
    let mut key = u64::MAX;
    let mut sorted = [[0u8; N]; 3];
    for a in 0..3 {
        if ext[a] <= 0.0 {
            continue;
        }
        // Counting sort by bin (stable): `order` lists the triangles' indices by bin.
        let bin: [u8; N] = std::array::from_fn(|j| bin_of(pos[j][a]) as u8);
        let mut start = [0u8; BINS];
        for &b in &bin {
            start[b as usize] += 1;
        }
        let mut acc = 0u8;
        for s in start.iter_mut() {
            let c = *s;
            *s = acc;
            acc += c;
        }
        let order = &mut sorted[a];
        for (j, &b) in bin.iter().enumerate() {
            order[index::<N>(start[b as usize])] = j as u8;
            start[b as usize] += 1;
        }
        let at = |k: usize| index::<N>(order[k]);
        let mut right_area = [0f32; N];
        let mut rb = Bx::EMPTY;
        for k in (1..N).rev() {
            rb = rb.union(&refs[at(k)]);
            right_area[k] = rb.area();
        }
        let mut lb = Bx::EMPTY;
        for k in 0..N - 1 {
            lb = lb.union(&refs[at(k)]);
            let c = lb.area() * (k + 1) as f32 + right_area[k + 1] * (N - k - 1) as f32;
            let here = (c.to_bits() as u64) << 32 | (a as u64) << 8 | k as u64;
            key = key.min(if bin[at(k)] != bin[at(k + 1)] { here } else { u64::MAX });
        }
    }
    let cost = f32::from_bits((key >> 32) as u32);
    if cost < best.0 {
        let (axis, last) = ((key >> 8 & 3) as usize, (key & 0xff) as usize);
        let order = &sorted[axis];
        let (mut lb, mut rb) = (Bx::EMPTY, Bx::EMPTY);
        for (k, &j) in order.iter().enumerate() {
            if k <= last {
                lb = lb.union(&refs[index::<N>(j)]);
            } else {
                rb = rb.union(&refs[index::<N>(j)]);
            }
        }
        *best = (cost, axis, bin_of(pos[index::<N>(order[last])][axis]), lb, rb);
    }
}

/// A position in a node of N triangles, kept below N so indexing needs no bounds check.
#[inline(always)]
pub(super) fn index<const N: usize>(j: u8) -> usize {
    (j as usize).min(N - 1)
}

/// `sweep_small` for a node of 3 to `SMALL` triangles.
pub(super) fn sweep_small_any(refs: &[Ref], origin2: Vec3A, scale2: Vec3A, ext: Vec3A, best: &mut Best) {
    macro_rules! by_size {
        ($($n:literal)*) => {
            match refs.len() {
                $($n => sweep_small::<$n>(refs, origin2, scale2, ext, best),)*
                n => unreachable!("sweep_small_any called for a node of {n} triangles"),
            }
        };
    }
    by_size!(3 4 5 6 7 8 9 10 11 12 13 14 15 16)
}

/// Splits `refs`/`prims` in place into the triangles `left` accepts and the rest; returns the
/// split position and the left and right boxes (gathered only if `BOXES`) and centroid
/// bounds.
pub(super) fn partition<const BOXES: bool>(
    refs: &mut [Ref],
    prims: &mut [u32],
    left: impl Fn(&Ref) -> bool,
) -> (usize, Bx, Bx, Bx, Bx) {
    let (mut lb, mut lcb, mut rb, mut rcb) = (Bx::EMPTY, Bx::EMPTY, Bx::EMPTY, Bx::EMPTY);
    let (mut lo, mut hi) = (0usize, refs.len());
    while lo < hi {
        let r = refs[lo];
        if left(&r) {
            lcb.grow(r.min + r.max);
            if BOXES {
                lb = lb.union(&r);
            }
            lo += 1;
        } else {
            hi -= 1;
            rcb.grow(r.min + r.max);
            if BOXES {
                rb = rb.union(&r);
            }
            refs.swap(lo, hi);
            prims.swap(lo, hi);
        }
    }
    (lo, lb, half(lcb), rb, half(rcb))
}

/// Chooses a SAH split and partitions `refs` and `prims` (centroid bounds of both sides are
/// gathered during the partition; box bounds come from the bins, or from the partition where
/// the bins held a sample); returns `None` for a leaf.
pub(super) fn split(refs: &mut [Ref], prims: &mut [u32], bounds: &Bx, cb: &Bx) -> Option<Split> {
    let n = refs.len();
    if n <= 1 {
        return None;
    }
    let ext = cb.max - cb.min;
    let mut best: Best = (f32::INFINITY, 0usize, 0usize, Bx::EMPTY, Bx::EMPTY);
    let sampled = n >= SAMPLE_FROM;
    if ext.max_element() > 0.0 {
        // Bins over twice the centroid: (min + max − 2·cb.min) · (BINS − 1) / (2·ext), rounded
        // to the nearest bin (the end bins are half as wide as the others).
        let scale2 = Vec3A::select(ext.cmpgt(Vec3A::ZERO), Vec3A::splat((BINS - 1) as f32 * 0.5) / ext, Vec3A::ZERO);
        let origin2 = cb.min * 2.0;
        if n == 2 {
            // Two triangles (a third of all nodes): on every axis where their centroids differ
            // they fall in bin 0 and bin BINS − 1, so the sweep's only candidate is one triangle
            // a side, at the same cost on each such axis, and the first such axis wins.
            let a = (0..3).find(|&a| ext[a] > 0.0).expect("some axis has extent");
            let (l, r) = if (refs[0].min + refs[0].max)[a] < (refs[1].min + refs[1].max)[a] { (0, 1) } else { (1, 0) };
            best = (refs[l].area() + refs[r].area(), a, 0, refs[l], refs[r]);
        } else if n <= SMALL {
            sweep_small_any(refs, origin2, scale2, ext, &mut best);
        } else if sampled {
            sweep_bins(&bin_chunk(refs.iter().step_by(n / SAMPLES), origin2, scale2), ext, &mut best);
        } else {
            sweep_bins(&bin_chunk(refs.iter(), origin2, scale2), ext, &mut best);
        }
        if best.0.is_finite() {
            let split_cost = C_TRAV + if bounds.area() > 0.0 { best.0 / bounds.area() } else { n as f32 };
            if n <= MAX_LEAF && n as f32 <= split_cost {
                return None;
            }
            let (_, a, i, lb, rb) = best;
            let (o, sc) = (origin2[a], scale2[a]);
            let left = |r: &Ref| bin_of(((r.min + r.max)[a] - o) * sc + MAGIC) <= i;
            let (lo, lb, lcb, rb, rcb) = if sampled {
                partition::<true>(refs, prims, left)
            } else {
                let (lo, _, lcb, _, rcb) = partition::<false>(refs, prims, left);
                (lo, lb, lcb, rb, rcb)
            };
            if lo > 0 && lo < n {
                return Some(Split { mid: lo, lb, lcb, rb, rcb });
            }
        }
    }
    if n <= MAX_LEAF {
        return None;
    }
    // All centroids coincide (or binning failed): split in the middle of the range.
    let mid = n / 2;
    let (lb, lcb) = range_bounds(&refs[..mid]);
    let (rb, rcb) = range_bounds(&refs[mid..]);
    Some(Split { mid, lb, lcb, rb, rcb })
}
