// fp16 in the kernels, mirroring src/fp16 (mod.rs: the directed roundings, `up16`/`down16`
// as fp16::up_f32; emulated.rs: `rte16`, `add_rte`, each tested there against the native
// operation): the fp16 value types per math mode and the roundings a build without float
// controls or fp16 arithmetic emulates. Constants (F16_MAX, NUDGE_*) come from interface.glsl.
// fp16 values: `float16_t` with fp16 arithmetic (MATH_F16, MATH_MIXED); in MATH_F32 they are
// held exactly in fp32 and the few fp16 roundings are emulated (rte16), so that mode uses 16-bit
// storage only and runs on devices without shaderFloat16. Every value and bound is the same.
#ifdef MATH_F32
#define HALF float
#define HVEC3 vec3
#define LOADH(x) float(x)
#define HINF INF
#define TO_HALF(x) rte16(x)
const float H0 = 0.0;
#else
#define HALF float16_t
#define HVEC3 f16vec3
#define LOADH(x) (x)
#define HINF float16_t(uintBitsToFloat(0x7f800000u))
#ifdef FC_OFF
#define TO_HALF(x) float16_t(rte16(x))
#else
#define TO_HALF(x) float16_t(x)
#endif
const float16_t H0 = float16_t(0.0);
#endif

// Origin type: fp32 in the fp32 math mode, fp16 otherwise (the Entry's `o` has the same type).
#ifdef MATH_F32
#define OVEC vec3
#define OCONV(x) (x)
#else
#define OVEC f16vec3
#define OCONV(x) TO_HALF(x)
#endif

int frexp_exp(float x) {
    int e = int((floatBitsToUint(x) >> 23) & 0xffu);
    return e == 0 ? -126 : e - 126;
}
float pow2(int e) { return uintBitsToFloat(uint(e + 127) << 23); }

#ifdef FC_OFF
// Round-to-nearest-even of x to fp16, returned exactly in fp32: integer operations on the
// bits and one exact power-of-two product, so it needs no fp16 arithmetic (fp16.rs,
// rte16_emulated, takes the same steps and is tested against the conversion for every fp16
// value, midpoint and neighbour).
float rte16(float x) {
    uint u = floatBitsToUint(x);
    uint sgn = u & 0x80000000u;
    uint a = u & 0x7fffffffu;
    if (a >= 0x7f800000u) return x;                                   // inf, NaN
    if (a >= 0x477ff000u) return uintBitsToFloat(sgn | 0x7f800000u);  // >= 65520 rounds to inf
    int e = int(a >> 23) - 127;
    if (e < -25) return uintBitsToFloat(sgn);                         // below half of 2^-24
    uint m = (a & 0x7fffffu) | 0x800000u;                             // x = m * 2^(e - 23)
    int lsb = max(e - 10, -24);                                       // fp16's last place
    uint sh = uint(lsb - (e - 23));                                   // 13..24
    uint q = m >> sh;
    uint rem = m & ((1u << sh) - 1u);
    uint halfway = 1u << (sh - 1u);
    if (rem > halfway || (rem == halfway && (q & 1u) == 1u)) q++;
    precise float r = float(q) * pow2(lsb);
    return uintBitsToFloat(floatBitsToUint(r) | sgn);
}
#else
// Round-to-nearest-even of x to fp16, returned exactly in fp32, with the build's RTE fp32
// additions (fp16.rs, rte16_by_add, tested like rte16_emulated): x + m, m = 1.5 * 2^(e + 13)
// with x's exponent e clamped to fp16's, lies in one binade spaced as fp16 at e, so the sum
// rounds x to fp16 and subtracting m is exact. Branch-free: no bit-by-bit rounding.
float rte16(float x) {
    uint u = floatBitsToUint(x);
    uint eb = clamp((u & 0x7fffffffu) >> 23, 113u, 143u);
    float m = uintBitsToFloat(((eb + 13u) << 23) | 0x400000u);
    precise float s = x + m;
    precise float r = s - m;
    float a = abs(r) >= 65536.0 ? INF : abs(r);
    return uintBitsToFloat(floatBitsToUint(a) | (u & 0x80000000u));
}
#endif

// a + b rounded to nearest even with integer operations only: three guard bits and a sticky
// bit (fp16.rs, add_rte_emulated, takes the same steps and is tested against IEEE addition).
// Without float controls, the fp32 additions a child frame is derived with go through it, so
// frames are the encoder's bit for bit on any device.
float add_rte(float a, float b) {
    uint ua = floatBitsToUint(a);
    uint ub = floatBitsToUint(b);
    if ((ua & 0x7fffffffu) < (ub & 0x7fffffffu)) { uint t = ua; ua = ub; ub = t; }
    uint ea = (ua >> 23) & 0xffu;
    uint eb = (ub >> 23) & 0xffu;
    uint ma = ea == 0u ? (ua & 0x7fffffu) : ((ua & 0x7fffffu) | 0x800000u);
    uint mb = eb == 0u ? (ub & 0x7fffffu) : ((ub & 0x7fffffu) | 0x800000u);
    int iea = int(max(ea, 1u));
    int ieb = int(max(eb, 1u));
    if (mb == 0u) return ma == 0u ? uintBitsToFloat(ua & ub & 0x80000000u) : uintBitsToFloat(ua);
    uint sgn = ua & 0x80000000u;
    uint d = uint(iea - ieb);
    uint big = ma << 3;
    uint small = 1u;
    if (d <= 26u) {
        uint m = mb << 3;
        small = (m >> d) | ((m & ((1u << d) - 1u)) != 0u ? 1u : 0u);
    }
    uint s = ((ua ^ ub) & 0x80000000u) == 0u ? big + small : big - small;
    int e = iea;
    if (s == 0u) return 0.0;
    if (s >= (1u << 27)) {
        s = (s >> 1) | (s & 1u);
        e += 1;
    } else {
        int sh = max(min(26 - findMSB(s), e - 1), 0);
        s <<= uint(sh);
        e -= sh;
    }
    uint m = s >> 3;
    uint rem = s & 7u;
    if (rem > 4u || (rem == 4u && (m & 1u) == 1u)) m++;
    if (m >= (1u << 24)) { m >>= 1; e += 1; }
    uint field = m >= (1u << 23) ? (uint(e) << 23) : 0u;
    return uintBitsToFloat(sgn | field | (m & 0x7fffffu));
}

// An fp16 value >= x with one round-to-nearest conversion (fp16::up_f32). Without float
// controls, the largest finite fp16 stands for inf (only where box tests are skipped).
HALF up16(float x) {
    precise float y = x + abs(x) * NUDGE_REL + NUDGE_ABS;
#ifdef FC_OFF
    return y > F16_MAX ? HALF(F16_MAX) : TO_HALF(y);
#else
    return y > F16_MAX ? HINF : TO_HALF(y);
#endif
}
HALF down16(float x) { return -up16(-x); }
