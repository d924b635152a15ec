//! Rust structs with a GLSL (std430) twin, declared once: [`glsl_struct!`] writes the
//! `#[repr(C)]` struct and its GLSL field list, so the two can never drift.

/// A Rust type with a GLSL (std430) counterpart: its GLSL name and its size in bytes.
pub trait GlslType {
    const GLSL: &'static str;
}

impl GlslType for u32 {
    const GLSL: &'static str = "uint";
}
impl GlslType for i32 {
    const GLSL: &'static str = "int";
}
impl GlslType for f32 {
    const GLSL: &'static str = "float";
}
impl GlslType for [f32; 4] {
    const GLSL: &'static str = "vec4";
}

/// A `#[repr(C)]` struct whose fields map one to one onto a GLSL struct or block.
pub trait GlslStruct: bytemuck::Pod {
    /// (field name, GLSL type) in declaration order.
    const FIELDS: &'static [(&'static str, &'static str)];
}

/// Declares a `#[repr(C)]`, `bytemuck::Pod` struct and its GLSL field list from one
/// definition, so the two can never drift. Field types must implement [`GlslType`].
#[macro_export]
macro_rules! glsl_struct {
    ($(#[$m:meta])* pub struct $name:ident { $($(#[$fm:meta])* pub $f:ident : $t:ty),* $(,)? }) => {
        $(#[$m])*
        #[repr(C)]
        #[derive(bytemuck::Pod, bytemuck::Zeroable)]
        pub struct $name { $($(#[$fm])* pub $f: $t),* }
        impl $crate::base::glsl::GlslStruct for $name {
            const FIELDS: &'static [(&'static str, &'static str)] = &[$((stringify!($f), <$t as $crate::base::glsl::GlslType>::GLSL)),*];
        }
    };
}
