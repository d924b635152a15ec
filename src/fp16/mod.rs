//! IEEE binary16 helpers: exact directed rounding for the encoder, and the conservative
//! fp32 → fp16 conversions the traversal uses (written so a shader can do the same with
//! round-to-nearest conversions only).
//!
//! Arithmetic on `half::f16` converts to f32, operates, and rounds back to nearest-even.
//! Because f32 carries 24 ≥ 2·11 + 2 significand bits, this double rounding equals a single
//! correctly rounded fp16 operation for +, −, ×, ÷ (Figueroa 1995), which is what GPU
//! `float16_t` arithmetic does.
//!
//! The roundings a shader without float controls or fp16 arithmetic emulates with integer
//! operations (`glsl/half.glsl`'s `rte16`, `add_rte`, `div_rte`) are in [`emulated`].

pub mod emulated;
pub use emulated::*;

use half::f16;

/// Largest finite fp16 value.
pub const F16_MAX: f32 = 65504.0;
/// [`up_f32`]'s nudge: |x|·NUDGE_REL + NUDGE_ABS, more than half an fp16 ulp of x.
pub const NUDGE_REL: f32 = 1.0 / 1024.0;
pub const NUDGE_ABS: f32 = 1.0 / 16_777_216.0;

/// The next fp16 value towards +inf.
pub fn next_up(x: f16) -> f16 {
    let b = x.to_bits();
    if x.is_nan() || x == f16::INFINITY {
        return x;
    }
    if b == 0x8000 || b == 0 {
        return f16::from_bits(1);
    }
    if b & 0x8000 == 0 {
        f16::from_bits(b + 1)
    } else {
        f16::from_bits(b - 1)
    }
}

/// The next fp16 value towards −inf.
pub fn next_down(x: f16) -> f16 {
    f16::from_bits(next_up(f16::from_bits(x.to_bits() ^ 0x8000)).to_bits() ^ 0x8000)
}

/// Largest fp16 value ≤ x (exact; x finite).
pub fn down_f64(x: f64) -> f16 {
    let h = f16::from_f64(x);
    if h.to_f64() > x {
        next_down(h)
    } else {
        h
    }
}

/// Smallest fp16 value ≥ x (exact; x finite).
pub fn up_f64(x: f64) -> f16 {
    let h = f16::from_f64(x);
    if h.to_f64() < x {
        next_up(h)
    } else {
        h
    }
}

/// An fp16 value ≥ x using one round-to-nearest conversion: x is nudged up by more than half
/// an fp16 ulp first (|x|·2⁻¹⁰ + 2⁻²⁴); values that would round to the largest finite fp16
/// but exceed it become +inf. The shader mirrors this exactly.
#[inline]
pub fn up_f32(x: f32) -> f16 {
    let y = x + x.abs() * NUDGE_REL + NUDGE_ABS;
    if y > F16_MAX {
        f16::INFINITY
    } else {
        f16::from_f32(y)
    }
}

/// An fp16 value ≤ x; see [`up_f32`].
#[inline]
pub fn down_f32(x: f32) -> f16 {
    -up_f32(-x)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn directed_rounding_every_bit_pattern_neighbourhood() {
        // Exhaustive over all finite fp16 values: points just above/below each value and
        // the midpoints to its neighbours round in the stated direction.
        for b in 0..=0xffffu16 {
            let h = f16::from_bits(b);
            if !h.is_finite() {
                continue;
            }
            let x = h.to_f64();
            assert_eq!(down_f64(x).to_f64(), x);
            assert_eq!(up_f64(x).to_f64(), x);
            let up = next_up(h);
            if up.is_finite() {
                let mid = 0.5 * (x + up.to_f64());
                assert!(down_f64(mid).to_f64() <= mid && up_f64(mid).to_f64() >= mid);
                assert_eq!(down_f64(mid), if h.to_bits() == 0x8000 { f16::from_bits(0) } else { h });
                let xf = mid as f32;
                assert!(up_f32(xf).to_f64() >= xf as f64, "{xf}");
                assert!(down_f32(xf).to_f64() <= xf as f64, "{xf}");
            }
            assert!(up_f32(x as f32).to_f64() >= x);
            assert!(down_f32(x as f32).to_f64() <= x);
        }
    }

    #[test]
    fn f16_ops_are_correctly_rounded() {
        // Spot check of the double-rounding claim against exact f64 arithmetic.
        let vals: Vec<f16> = (0..=0xffffu16).step_by(97).map(f16::from_bits).filter(|h| h.is_finite()).collect();
        for &a in &vals {
            for &b in vals.iter().step_by(13) {
                for (got, exact) in [
                    (a + b, a.to_f64() + b.to_f64()),
                    (a - b, a.to_f64() - b.to_f64()),
                    (a * b, a.to_f64() * b.to_f64()),
                ] {
                    assert_eq!(got, f16::from_f64(exact), "{a} {b}");
                }
            }
        }
    }
}
