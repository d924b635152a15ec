//! Precision modes, apart from any layout: the arithmetic of the box tests ([`Math`]) and
//! whether a kernel declares the float controls its exactness relies on ([`FloatControls`],
//! chosen per device by [`FcChoice`]). A leaf: it imports nothing of halftrace's.

/// Arithmetic of a layout's box tests (and origin moves), separate from its storage precision.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, clap::ValueEnum)]
pub enum Math {
    /// fp16 arithmetic (`float16_t`; the poster's mode for f16h).
    #[value(name = "f16", alias = "m16")]
    F16,
    /// fp32 arithmetic (reduced-precision values widened on load).
    #[value(name = "f32", alias = "m32")]
    F32,
    /// fp16 differences and products; fp32 min/max, widening and comparisons.
    #[value(name = "mixed", alias = "mix")]
    Mixed,
}

impl Math {
    /// Name in flags, configs and reports: f16, f32, mixed.
    pub fn name(self) -> &'static str {
        match self {
            Math::F16 => "f16",
            Math::F32 => "f32",
            Math::Mixed => "mixed",
        }
    }
    /// Tag in kernel names: m16, m32, mix.
    pub fn tag(self) -> &'static str {
        match self {
            Math::F16 => "m16",
            Math::F32 => "m32",
            Math::Mixed => "mix",
        }
    }
    /// The kernels' define for this mode.
    pub fn define(self) -> &'static str {
        match self {
            Math::F16 => "MATH_F16",
            Math::F32 => "MATH_F32",
            Math::Mixed => "MATH_MIXED",
        }
    }
}

impl std::str::FromStr for Math {
    type Err = String;
    fn from_str(s: &str) -> Result<Math, String> {
        match s {
            "f16" | "m16" => Ok(Math::F16),
            "f32" | "m32" => Ok(Math::F32),
            "mixed" | "mix" => Ok(Math::Mixed),
            o => Err(format!("unknown math mode '{o}' (use f16, f32 or mixed)")),
        }
    }
}

/// The float-control execution modes of a kernel (SPIR-V 1.4 / `VK_KHR_shader_float_controls`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Default)]
pub enum FloatControls {
    /// The kernel declares round-to-nearest-even and signed-zero/inf/NaN preservation for the
    /// float widths it computes in, and the CPU reference matches it bit for bit.
    #[default]
    On,
    /// The kernel declares none and is written so that any faithful rounding and any inf/NaN
    /// handling keeps its hits exact (only layouts that provide such a build).
    Off,
}

impl FloatControls {
    pub fn name(self) -> &'static str {
        match self {
            FloatControls::On => "on",
            FloatControls::Off => "off",
        }
    }
}

/// `--float-controls`: on, off, or auto (on where the device has the modes, else off where the
/// layout has such a build).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default, serde::Serialize, serde::Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum FcChoice {
    #[default]
    Auto,
    On,
    Off,
}

impl std::str::FromStr for FcChoice {
    type Err = String;
    fn from_str(s: &str) -> Result<FcChoice, String> {
        match s {
            "auto" => Ok(FcChoice::Auto),
            "on" => Ok(FcChoice::On),
            "off" => Ok(FcChoice::Off),
            o => Err(format!("unknown float-controls mode '{o}' (use on, off or auto)")),
        }
    }
}
