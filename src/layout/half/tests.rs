//! The box test's bound under any faithful rounding, every sign and magnitude class: the
//! proof obligations of [`super`] checked by exhaustive and random cases.

use super::*;
use crate::base::Ray;
use crate::fp16;
use proptest::prelude::*;

/// One fp16 operation rounded faithfully: the exact result (`x`, exact in f64 for these
/// operands) rounded to nearest, or — when `flip` — to its other fp16 neighbour, as a device
/// without float controls may.
fn faithful(x: f64, flip: bool) -> f16 {
    let r = f16::from_f64(x);
    if !flip || r.to_f64() == x || r.is_infinite() {
        return r;
    }
    if r.to_f64() < x {
        fp16::next_up(r)
    } else {
        fp16::next_down(r)
    }
}

/// [`slab16`] without float controls, with every fp16 operation (and the reciprocal) rounded either way.
fn slab16_faithful(o: &[f16; 3], d: &[f16; 3], w: f16, lo: [f16; 3], hi: [f16; 3], bits: &mut u64) -> (f64, f64) {
    let mut flip = || {
        *bits = bits.rotate_left(1);
        *bits & 1 == 1
    };
    let sat = f16::from_f32(SAT);
    let (mut tn, mut tf) = (-sat, sat);
    for a in 0..3 {
        let la = faithful(faithful(lo[a].to_f64() - o[a].to_f64(), flip()).to_f64() - w.to_f64(), flip());
        let ha = faithful(faithful(hi[a].to_f64() - o[a].to_f64(), flip()).to_f64() + w.to_f64(), flip());
        let (t0, t1) = if d[a] == f16::ZERO {
            if la <= f16::ZERO && ha >= f16::ZERO {
                (-sat, sat)
            } else {
                (sat, -sat)
            }
        } else {
            let idir = faithful(1.0 / d[a].to_f64(), flip());
            let mul = |v: f16, f: bool| {
                let p = v.to_f64() * idir.to_f64();
                if p > SAT as f64 {
                    sat
                } else if p < -(SAT as f64) {
                    -sat
                } else {
                    faithful(p, f)
                }
            };
            let (x, y) = (mul(la, flip()), mul(ha, flip()));
            (x.min(y), x.max(y))
        };
        tn = tn.max(t0);
        tf = tf.min(t1);
    }
    let down = f16::from_f32(1.0 - 1.0 / 256.0);
    let up = f16::from_f32(1.0 + 1.0 / 256.0);
    let tn_lb = faithful(tn.to_f64() * if tn > f16::ZERO { down } else { up }.to_f64(), flip());
    let tf_ub = faithful(tf.to_f64() * if tf > f16::ZERO { up } else { down }.to_f64(), flip());
    (tn_lb.to_f64(), tf_ub.to_f64())
}

/// Rays and boxes of the slab property tests: a point X of the box at parameter s on the
/// exact line through P = X − s·d (|P| ≤ 20000), and an fp16 origin O within e of P.
#[allow(clippy::type_complexity)]
fn slab_case(
    x: [f64; 3],
    off: [f64; 3],
    e_scale: f64,
    d: [f64; 3],
    s_frac: f64,
    ext: [f64; 3],
) -> ([f16; 3], f32, f64, [f16; 3], [f16; 3]) {
    let mut s = s_frac * (16384.0 + 20000.0);
    for a in 0..3 {
        if d[a] != 0.0 {
            s = s.signum() * s.abs().min((20000.0 - x[a].abs()) / d[a].abs());
        }
    }
    let p = [0, 1, 2].map(|a| x[a] - s * d[a]);
    let o: [f16; 3] = [0, 1, 2].map(|a| f16::from_f64((p[a] + off[a] * e_scale).clamp(-OCAP as f64, OCAP as f64)));
    let e_true = (0..3).fold(0f64, |m, a| m.max((o[a].to_f64() - p[a]).abs()));
    let e = (e_true as f32) * (1.0 + 1e-6) + 1e-6;
    let lo = [0, 1, 2].map(|a| fp16::down_f64((x[a] - ext[a]).max(-16384.0)));
    let hi = [0, 1, 2].map(|a| fp16::up_f64((x[a] + ext[a]).min(16384.0)));
    (o, e, s, lo, hi)
}

/// Without float controls: whichever way each fp16 operation (and the reciprocal) rounds —
/// to nearest, always the other way, or mixed — the widened test (`W_MARGIN_OFF`) reports an
/// interval containing s. (Sampling finds no case that needs more than the e·2⁻¹¹ term even
/// without the absolute margin: a subtraction can only err by 16–32 where the operands are
/// large, and there the relative 2⁻⁸ or the outward rounding of w covers it; the margin keeps
/// the argued full-ulp budget rather than relying on that.)
#[test]
fn slab16_off_holds_under_any_faithful_rounding() {
    use proptest::test_runner::{Config, TestRunner};
    let mut runner = TestRunner::new(Config { cases: 20000, ..Config::default() });
    let strat = (
        prop::array::uniform3(-16384.0f64..16384.0),
        prop::array::uniform3(-1.0f64..1.0),
        prop_oneof![Just(0.0f64), 0.0f64..1.0, 0.0f64..64.0, 1000.0f64..16000.0],
        prop::array::uniform3(-1.0f64..1.0),
        0usize..4,
        prop_oneof![-1.0f64..1.0, -1e-3f64..1e-3],
        prop::array::uniform3(prop_oneof![Just(0.0f64), 0.0f64..0.01, 0.0f64..50.0]),
        any::<u64>(),
    );
    runner
        .run(&strat, |(x, off, e_scale, dv, zero_axis, s_frac, ext, seed)| {
            let mut dv = dv;
            if zero_axis < 3 {
                dv[zero_axis] = 0.0;
            }
            let Some(d) = dir(dv) else { return Ok(()) };
            let (o, e, s, lo, hi) = slab_case(x, off, e_scale, d, s_frac, ext);
            prop_assume!(e <= EBIG);
            let pre = RayPre::new(&Ray::new(
                glam::Vec3::ZERO,
                glam::Vec3::new(d[0] as f32, d[1] as f32, d[2] as f32),
                0.0,
                f32::INFINITY,
            ));
            let r16 = Ray16::new(&pre, Math::F16, crate::precision::FloatControls::Off);
            for flips in [seed, !seed, u64::MAX, 0] {
                let mut bits = flips;
                let w = up_f32(e + e * TWO_M11 + W_MARGIN_OFF);
                let (tn_lb, tf_ub) = slab16_faithful(&o, &r16.d, w, lo, hi, &mut bits);
                prop_assert!(
                    tn_lb <= s && s <= tf_ub,
                    "s={} not in [{}, {}] (o={:?} e={} d={:?} box {:?}..{:?})",
                    s,
                    tn_lb,
                    tf_ub,
                    o,
                    e,
                    d,
                    lo,
                    hi
                );
            }
            Ok(())
        })
        .unwrap();
}

/// A unit-max-norm direction from three random components.
fn dir(v: [f64; 3]) -> Option<[f64; 3]> {
    let m = v.iter().fold(0f64, |m, x| m.max(x.abs()));
    (m > 1e-9).then(|| {
        let d = v.map(|x| ((x / m) as f32) as f64);
        // make the dominant component exactly ±1
        let k = (0..3).max_by(|&a, &b| d[a].abs().total_cmp(&d[b].abs())).unwrap();
        let mut d = d;
        d[k] = d[k].signum();
        d
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(20000))]

    /// The invariant the traversal relies on: if the true line through P (within e of
    /// O) reaches a point X of a box at parameter s, the widened fp16 slab test of the
    /// stored box reports an interval containing s.
    #[test]
    fn slab16_never_misses_a_point_the_true_ray_reaches(
        x in prop::array::uniform3(-16384.0f64..16384.0),
        off in prop::array::uniform3(-1.0f64..1.0),
        e_scale in prop_oneof![Just(0.0f64), 0.0f64..1.0, 0.0f64..64.0, 0.0f64..2048.0],
        dv in prop::array::uniform3(-1.0f64..1.0),
        zero_axis in 0usize..4,
        s_frac in -1.0f64..1.0,
        ext in prop::array::uniform3(prop_oneof![Just(0.0f64), 0.0f64..0.01, 0.0f64..50.0, 0.0f64..5000.0]),
    ) {
        let mut dv = dv;
        if zero_axis < 3 { dv[zero_axis] = 0.0; }
        let Some(d) = dir(dv) else { return Ok(()) };
        let (o, e, s, lo, hi) = slab_case(x, off, e_scale, d, s_frac, ext);
        let pre = RayPre::new(&Ray::new(glam::Vec3::ZERO, glam::Vec3::new(d[0] as f32, d[1] as f32, d[2] as f32), 0.0, f32::INFINITY));
        let r16 = Ray16::new(&pre, Math::F16, crate::precision::FloatControls::On);
        prop_assert_eq!(r16.m, 1.0);
        let w = up_f32(e + e * TWO_M11 + W_MARGIN);
        let (_tn, tn_lb, tf_ub) = slab16(&o, &r16, w, lo, hi);
        prop_assert!(tn_lb.to_f64() <= s && s <= tf_ub.to_f64(),
            "s={} not in [{}, {}] (o={:?} e={} d={:?} box {:?}..{:?})", s, tn_lb, tf_ub, o, e, d, lo, hi);
    }
}
