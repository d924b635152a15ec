//! Round-to-nearest-even emulated with integer operations and exact products: fp32 → fp16
//! ([`rte16_emulated`], [`rte16_by_add`]), fp32 addition ([`add_rte_emulated`]) and division
//! ([`div_rte_emulated`]), each step for step what `glsl/half.glsl` does where a device has no
//! float controls, and each tested against the native operation.

/// Round-to-nearest-even of `x` to fp16, returned exactly as f32, computed the way the
/// kernels without fp16 arithmetic do it (`glsl/half.glsl`, `rte16`): integer
/// operations on the bits and one exact power-of-two product. Equal to
/// `f16::from_f32(x).to_f32()` for every x (tested).
pub fn rte16_emulated(x: f32) -> f32 {
    let u = x.to_bits();
    let sgn = u & 0x8000_0000;
    let a = u & 0x7fff_ffff;
    if a >= 0x7f80_0000 {
        return x;
    }
    if a >= 0x477f_f000 {
        return f32::from_bits(sgn | 0x7f80_0000);
    }
    let e = (a >> 23) as i32 - 127;
    if e < -25 {
        return f32::from_bits(sgn);
    }
    let m = (a & 0x7f_ffff) | 0x80_0000;
    let lsb = (e - 10).max(-24);
    let sh = (lsb - (e - 23)) as u32;
    let mut q = m >> sh;
    let rem = m & ((1 << sh) - 1);
    let half = 1 << (sh - 1);
    if rem > half || (rem == half && q & 1 == 1) {
        q += 1;
    }
    let r = q as f32 * f32::from_bits(((lsb + 127) as u32) << 23);
    f32::from_bits(r.to_bits() | sgn)
}

/// Round-to-nearest-even of `x` to fp16, returned exactly as f32, the way the kernels with
/// float controls (fp32 additions rounded to nearest even) but without fp16 arithmetic do it
/// (`glsl/half.glsl`, `rte16`): adding `m = 1.5 · 2^(e + 13)`, e = x's exponent clamped to fp16's
/// (−14…16), leaves the sum in one binade whose fp32 spacing is fp16's at e, so the addition
/// rounds x to fp16 (ties to even: m is an even multiple of that spacing) and subtracting m is
/// exact. A dozen branch-free operations in place of `rte16_emulated`'s branches. Equal to
/// `f16::from_f32(x).to_f32()` for every x (tested).
pub fn rte16_by_add(x: f32) -> f32 {
    let u = x.to_bits();
    let sgn = u & 0x8000_0000;
    let eb = ((u & 0x7fff_ffff) >> 23).clamp(113, 143);
    let m = f32::from_bits(((eb + 13) << 23) | 0x40_0000);
    let r = (x + m) - m;
    let r = if r.abs() >= 65536.0 { f32::INFINITY } else { r.abs() };
    f32::from_bits(r.to_bits() | sgn)
}

/// `a + b` rounded to nearest even, computed the way the kernels built without float controls
/// do it (`glsl/layout/f16h.glsl`, `add_rte`): integer operations on the bits (three guard
/// bits, sticky), so the result is the IEEE sum whatever the device's own rounding. Used for the
/// few fp32 additions a child frame is derived with, which must match the encoder bit for bit.
/// Equal to `a + b` for all finite inputs whose sum is finite (tested).
pub fn add_rte_emulated(a: f32, b: f32) -> f32 {
    let (mut ua, mut ub) = (a.to_bits(), b.to_bits());
    if (ua & 0x7fff_ffff) < (ub & 0x7fff_ffff) {
        std::mem::swap(&mut ua, &mut ub);
    }
    let (ea, eb) = ((ua >> 23) & 0xff, (ub >> 23) & 0xff);
    let ma = if ea == 0 { ua & 0x7f_ffff } else { (ua & 0x7f_ffff) | 0x80_0000 };
    let mb = if eb == 0 { ub & 0x7f_ffff } else { (ub & 0x7f_ffff) | 0x80_0000 };
    let (ea, eb) = (ea.max(1) as i32, eb.max(1) as i32);
    if mb == 0 {
        // b = ±0: a + b = a, except +0 + −0 = +0.
        return if ma == 0 { f32::from_bits(ua & ub & 0x8000_0000) } else { f32::from_bits(ua) };
    }
    let sign = ua & 0x8000_0000;
    let d = (ea - eb) as u32;
    let big = ma << 3;
    let small = if d > 26 {
        1
    } else {
        let m = mb << 3;
        (m >> d) | u32::from(m & ((1u32 << d) - 1) != 0)
    };
    let (mut s, mut e) = if (ua ^ ub) & 0x8000_0000 == 0 { (big + small, ea) } else { (big - small, ea) };
    if s == 0 {
        return 0.0;
    }
    if s >= 1 << 27 {
        s = (s >> 1) | (s & 1);
        e += 1;
    } else {
        let n = 31 - s.leading_zeros() as i32; // bit index of the leading one
        let shift = (26 - n).min(e - 1).max(0);
        s <<= shift;
        e -= shift;
    }
    let mut m = s >> 3;
    let rem = s & 7;
    if rem > 4 || (rem == 4 && m & 1 == 1) {
        m += 1;
    }
    if m >= 1 << 24 {
        m >>= 1;
        e += 1;
    }
    if e >= 255 {
        return f32::from_bits(sign | 0x7f80_0000);
    }
    let field = if m >= 1 << 23 { (e as u32) << 23 } else { 0 };
    f32::from_bits(sign | field | (m & 0x7f_ffff))
}

/// The significand of a non-zero |x| (its bits, sign cleared) normalised to [2^23, 2^24), and
/// e with |x| = m·2^(e − 150), subnormals included (`significand` in `glsl/ray.glsl`).
pub fn significand(x: u32) -> (u32, i32) {
    let (e, m) = ((x >> 23) as i32, x & 0x7f_ffff);
    if e == 0 {
        let s = m.leading_zeros() as i32 - 8;
        (m << s, 1 - s)
    } else {
        (m | 0x80_0000, e)
    }
}

/// `a / b` rounded to nearest even, computed the way every kernel divides where a result must
/// be the CPU's bit for bit (`glsl/ray.glsl`, `div_rte`): Vulkan allows fp32 division an error
/// of 2.5 ulp (RADV multiplies by a reciprocal), so the
/// quotient's significand comes from integer operations, the native division giving only the
/// first estimate. Equal to `a / b` for finite `a` and finite non-zero `b` (tested, with the
/// estimate off by up to 100 units either way); `b = 0` divides natively.
pub fn div_rte_emulated(a: f32, b: f32) -> f32 {
    div_rte_nudged(a, b, 0)
}

/// [`div_rte_emulated`] with its estimate moved by `nudge` units (as a device's division may).
fn div_rte_nudged(a: f32, b: f32, nudge: i32) -> f32 {
    let (ua, ub) = (a.to_bits(), b.to_bits());
    let sgn = (ua ^ ub) & 0x8000_0000;
    let (xa, xb) = (ua & 0x7fff_ffff, ub & 0x7fff_ffff);
    if xb == 0 {
        return a / b;
    }
    if xa == 0 {
        return f32::from_bits(sgn);
    }
    // Significands in [2^23, 2^24): a = ma·2^(ea − 150), b = mb·2^(eb − 150).
    let (ma, ea) = significand(xa);
    let (mb, eb) = significand(xb);
    // The quotient's significand g = floor(ma·2^sh / mb) lies in [2^23, 2^24); the result is
    // (g + rem/mb)·2^(e − 150) with e biased.
    let sh: u32 = if ma >= mb { 23 } else { 24 };
    let mut e = ea - eb + 127 - (sh as i32 - 23);
    let alo = ma << sh; // the low word of ma·2^sh: the remainder below is small
    let estimate = (ma as f32 / mb as f32 * (1u32 << sh) as f32) as u32;
    let mut g = (estimate as i32 + nudge).clamp(0x80_0000, 0xff_ffff) as u32;
    let mut rem = alo.wrapping_sub(g.wrapping_mul(mb)) as i32; // exact while |estimate − g| < 128
    while rem < 0 {
        g -= 1;
        rem += mb as i32;
    }
    while rem >= mb as i32 {
        g += 1;
        rem -= mb as i32;
    }
    let r2 = (rem as u32) << 1;
    if e >= 1 {
        if r2 > mb || (r2 == mb && g & 1 == 1) {
            g += 1;
        }
        if g == 0x100_0000 {
            g = 0x80_0000;
            e += 1;
        }
        if e >= 255 {
            return f32::from_bits(sgn | 0x7f80_0000);
        }
        return f32::from_bits(sgn | ((e as u32) << 23) | (g & 0x7f_ffff));
    }
    // Subnormal: the significand keeps g >> s.
    let s = (1 - e) as u32;
    if s > 24 {
        return f32::from_bits(sgn);
    }
    let mut q = g >> s;
    let low = g & ((1u32 << s) - 1);
    let half = 1u32 << (s - 1);
    if low > half || (low == half && (rem != 0 || q & 1 == 1)) {
        q += 1;
    }
    f32::from_bits(sgn | q)
}

#[cfg(test)]
mod tests {
    use super::super::next_up;
    use super::*;
    use half::f16;

    /// A xorshift64 generator: the random bit patterns of the emulation tests, reproducible.
    fn xorshift(mut x: u64) -> impl FnMut() -> u64 {
        move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        }
    }

    #[test]
    fn emulated_rte16_equals_the_conversion() {
        let check = |x: f32| {
            let want = f16::from_f32(x).to_f32();
            for (name, got) in [("rte16_emulated", rte16_emulated(x)), ("rte16_by_add", rte16_by_add(x))] {
                assert!(
                    got.to_bits() == want.to_bits() || (got.is_nan() && want.is_nan()),
                    "{name}: {x:e} ({:#x}): {got:e} vs {want:e}",
                    x.to_bits()
                );
            }
        };
        // Every f32 whose exponent reaches fp16 (and a margin), in steps that hit every low
        // bit pattern class, plus every fp16 value, midpoint and their neighbours.
        for bits in (0x3000_0000u32..0x4800_0000).step_by(97).chain((0..0x7f80_0000).step_by(4099)) {
            check(f32::from_bits(bits));
            check(-f32::from_bits(bits));
        }
        for h in 0..=0x7c00u16 {
            let v = f16::from_bits(h).to_f32();
            let n = next_up(f16::from_bits(h)).to_f32();
            let mid = ((v as f64 + n as f64) / 2.0) as f32;
            for x in [v, mid, f32::from_bits(mid.to_bits().wrapping_sub(1)), f32::from_bits(mid.to_bits() + 1)] {
                check(x);
                check(-x);
            }
        }
        for x in [
            0.0,
            -0.0,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::MAX,
            f32::MIN_POSITIVE,
            1e-40,
            65504.0,
            65519.99,
            65520.0,
            2.0f32.powi(-25),
            2.0f32.powi(-26),
            65536.0,
            131072.0,
            1e10,
            3e38,
        ] {
            check(x);
            check(-x);
        }
        assert!(rte16_emulated(f32::NAN).is_nan());
        assert!(rte16_by_add(f32::NAN).is_nan());
    }

    #[test]
    fn emulated_fp32_addition_equals_the_native_one() {
        let mut next = xorshift(0x9e37_79b9_7f4a_7c15);
        let check = |a: f32, b: f32| {
            let want = a + b;
            if !want.is_finite() {
                return;
            }
            let got = add_rte_emulated(a, b);
            assert_eq!(got.to_bits(), want.to_bits(), "{a:e} + {b:e}: {got:e} vs {want:e}");
        };
        for _ in 0..3_000_000 {
            let r = next();
            // Exponents close together (cancellation, carries) and far apart (sticky bits).
            let a = f32::from_bits(r as u32);
            let spread = (r >> 32) as u32 % 40;
            let b_bits =
                ((r >> 40) as u32 & 0x807f_ffff) | ((((a.to_bits() >> 23) & 0xff).saturating_sub(spread) & 0xff) << 23);
            let b = f32::from_bits(b_bits);
            if a.is_finite() && b.is_finite() {
                check(a, b);
                check(a, -b);
                check(b, a);
            }
            let (c, d) = (f32::from_bits(next() as u32), f32::from_bits(next() as u32));
            if c.is_finite() && d.is_finite() {
                check(c, d);
            }
        }
        for (a, b) in [
            (0.0f32, -0.0f32),
            (-0.0, -0.0),
            (1.0, -1.0),
            (1.0, f32::EPSILON / 2.0),
            (1.0, f32::EPSILON / 2.0 + f32::EPSILON / 4.0),
            (f32::MIN_POSITIVE, -f32::MIN_POSITIVE / 2.0),
            (1e-45, 1e-45),
            (16384.0, -0.000_061_035_156),
        ] {
            check(a, b);
            check(-a, -b);
        }
    }

    #[test]
    fn emulated_fp32_division_equals_the_native_one() {
        let mut next = xorshift(0x2545_f491_4f6c_dd1d);
        let check = |a: f32, b: f32, nudge: i32| {
            let want = a / b;
            let got = div_rte_nudged(a, b, nudge);
            assert!(
                got.to_bits() == want.to_bits() || (got.is_nan() && want.is_nan()),
                "{a:e} / {b:e} (estimate {nudge:+}): {got:e} ({:#x}) vs {want:e} ({:#x})",
                got.to_bits(),
                want.to_bits()
            );
        };
        for i in 0..3_000_000u32 {
            let r = next();
            let nudge = [0, 1, -1, 3, -3, 100, -100][i as usize % 7];
            let (a, b) = (f32::from_bits(r as u32), f32::from_bits((r >> 32) as u32));
            if a.is_finite() && b.is_finite() {
                check(a, b, nudge);
            }
            // Quotients near and below the subnormal range, and near overflow.
            let ea = (r >> 24) as u32 % 64;
            let small = f32::from_bits((r as u32 & 0x807f_ffff) | (ea << 23));
            let big = f32::from_bits(((r >> 32) as u32 & 0x807f_ffff) | ((ea + 100) << 23));
            check(small, big, nudge);
            check(big, small, nudge);
            check(f32::from_bits(r as u32 & 0x807f_ffff), b.abs().max(1e-30), nudge);
        }
        for (a, b) in [
            (1.0f32, 3.0f32),
            (0.0, -5.0),
            (-0.0, 5.0),
            (f32::MAX, f32::MIN_POSITIVE),
            (f32::MIN_POSITIVE, f32::MAX),
            (1e-45, 2.0),
            (3e-45, 2.0),
            (1e-45, 1.5),
            (f32::from_bits(0x0000_0003), 2.0),
            (f32::from_bits(0x0080_0001), 2.0),
            (f32::from_bits(0x00ff_ffff), 2.0),
            (1.0, 0.0),
            (-1.0, 0.0),
            (7.0, 7.0),
        ] {
            for nudge in -100..=100 {
                check(a, b, nudge);
                check(-a, b, nudge);
            }
        }
    }
}
