//! Handles to the registered layouts ([`LayoutId`], over [`super::REGISTRY`], which
//! `layout/mod.rs` lists one line per layout) and the object-safe face every layout gets
//! ([`DynLayout`], through [`Plug`]).

use super::traverse::{LoopWork, Reads};
use super::{EncodeError, Encoded, Layout, LayoutInfo, TriBuffer, REGISTRY};
use crate::base::{Counters, Hit, Ray};
use crate::bvh::WideBvh;
use crate::precision::{FloatControls, Math};
use crate::scene::Scene;
use std::marker::PhantomData;
use thiserror::Error;

/// Names layouts had before, still read from configs and result files.
const RENAMED: &[(&str, &str)] = &[("f16h-seed", "f16h-poster")];

/// A name that is no registered layout.
#[derive(Debug, Error, PartialEq)]
#[error("unknown layout '{name}' (use {known})")]
pub struct UnknownLayout {
    pub name: String,
    pub known: String,
}

/// A handle to a registered layout.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct LayoutId(u8);

impl LayoutId {
    /// Every layout, in registry order.
    pub fn all() -> impl Iterator<Item = LayoutId> {
        (0..REGISTRY.len()).map(|i| LayoutId(i as u8))
    }

    /// The layout called `name` (or once called so).
    pub fn parse(name: &str) -> Result<LayoutId, UnknownLayout> {
        let name = RENAMED.iter().find(|(old, _)| *old == name).map_or(name, |(_, new)| new);
        Self::all()
            .find(|l| l.name() == name)
            .ok_or_else(|| UnknownLayout { name: name.to_string(), known: Self::names() })
    }

    /// The layout implemented by `L`.
    pub fn of<L: Layout>() -> LayoutId {
        Self::parse(L::INFO.name).expect("every Layout is registered")
    }

    /// The fp32 layout every other is compared with.
    pub fn f32() -> LayoutId {
        Self::of::<super::f32::F32>()
    }

    /// The poster's layout in the poster's math (fp16 box tests): the headline's numerator.
    pub fn poster() -> (LayoutId, Math) {
        let l = Self::of::<super::f16h::F16h>();
        (l, l.default_math())
    }

    /// "f32, f16h or q8".
    pub fn names() -> String {
        let n: Vec<&str> = Self::all().map(|l| l.name()).collect();
        match n.split_last() {
            Some((last, rest)) if !rest.is_empty() => format!("{} or {last}", rest.join(", ")),
            _ => n.join(""),
        }
    }

    /// The layout's implementation.
    pub fn imp(self) -> &'static dyn DynLayout {
        REGISTRY[self.0 as usize]
    }

    /// Everything known of the layout besides its hooks.
    pub fn info(self) -> &'static LayoutInfo {
        self.imp().info()
    }

    pub fn name(self) -> &'static str {
        self.info().name
    }

    /// The default math mode (the first of the layout's modes).
    pub fn default_math(self) -> Math {
        self.info().maths[0]
    }
}

impl std::fmt::Display for LayoutId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for LayoutId {
    type Err = UnknownLayout;
    fn from_str(s: &str) -> Result<LayoutId, UnknownLayout> {
        LayoutId::parse(s)
    }
}

/// The object-safe face of a [`Layout`], implemented once for all of them by [`Plug`].
pub trait DynLayout: Send + Sync {
    fn info(&self) -> &'static LayoutInfo;
    fn encode(&self, scene: &Scene, w: &WideBvh) -> Result<Encoded, EncodeError>;
    /// The CPU reference: rays in packets of `p` (1: single rays) in math mode `math`.
    fn trace(&self, enc: &Encoded, rays: &[Ray], p: usize, math: Math, fc: FloatControls) -> (Vec<Hit>, Vec<Counters>);
    /// How often the kernel's loops run for packets of `p` rays (1: single rays) in waves of
    /// `wave` rays (in lockstep, and each packet on its own): [`super::traverse::loop_work`].
    #[allow(clippy::too_many_arguments)]
    fn loop_work(
        &self,
        enc: &Encoded,
        rays: &[Ray],
        p: usize,
        wave: usize,
        math: Math,
        fc: FloatControls,
    ) -> (LoopWork, LoopWork);
    /// Every packet's reads of the scene's buffers, pass by pass: [`super::traverse::mem_reads`].
    fn mem_reads(&self, enc: &Encoded, rays: &[Ray], p: usize, math: Math, fc: FloatControls) -> Vec<Vec<Reads>>;
}

/// The [`DynLayout`] of a [`Layout`] (`layout/mod.rs`'s `layouts!` list makes one per layout).
pub struct Plug<L>(PhantomData<fn() -> L>);

impl<L: Layout> Plug<L> {
    pub const NEW: Plug<L> = Plug(PhantomData);
}

/// Calls `$f::<B>` for the runtime branching factor `$b` — the one place where B becomes a
/// type-level constant.
macro_rules! with_branching {
    ($b:expr, $f:ident $(, $arg:expr)*) => {
        match $b {
            2 => $f::<L, 2>($($arg),*),
            4 => $f::<L, 4>($($arg),*),
            8 => $f::<L, 8>($($arg),*),
            16 => $f::<L, 16>($($arg),*),
            b => unreachable!("branching {b} is checked before encoding"),
        }
    };
}

fn encode_b<L: Layout, const B: usize>(scene: &Scene, w: &WideBvh) -> Result<Encoded, EncodeError> {
    let reordered = L::reorder(w);
    let w = reordered.as_ref().unwrap_or(w);
    let (nodes, root) = L::encode::<B>(w)?;
    let rb = w.nodes[0].bounds;
    Ok(Encoded {
        layout: LayoutId::of::<L>(),
        branching: B,
        nodes: Box::new(nodes),
        push_root: L::push_root(&root),
        root: Box::new(root),
        root_box: rb,
        tris: TriBuffer::new(scene, w),
        max_stack: w.max_stack(),
    })
}

fn trace_b<L: Layout, const B: usize>(
    enc: &Encoded,
    rays: &[Ray],
    p: usize,
    math: Math,
    fc: FloatControls,
) -> (Vec<Hit>, Vec<Counters>) {
    let (nodes, root) = enc.typed::<L, B>().expect("Encoded of another layout or B");
    super::traverse::trace_all::<L, B>(nodes, root, enc, rays, p, math, fc)
}

fn loop_work_b<L: Layout, const B: usize>(
    enc: &Encoded,
    rays: &[Ray],
    p: usize,
    wave: usize,
    math: Math,
    fc: FloatControls,
) -> (LoopWork, LoopWork) {
    let (nodes, root) = enc.typed::<L, B>().expect("Encoded of another layout or B");
    super::traverse::loop_work::<L, B>(nodes, root, enc, rays, p, wave, math, fc)
}

fn mem_reads_b<L: Layout, const B: usize>(
    enc: &Encoded,
    rays: &[Ray],
    p: usize,
    math: Math,
    fc: FloatControls,
) -> Vec<Vec<Reads>> {
    let (nodes, root) = enc.typed::<L, B>().expect("Encoded of another layout or B");
    super::traverse::mem_reads::<L, B>(nodes, root, enc, rays, p, math, fc)
}

impl<L: Layout> DynLayout for Plug<L> {
    fn info(&self) -> &'static LayoutInfo {
        &L::INFO
    }
    fn encode(&self, scene: &Scene, w: &WideBvh) -> Result<Encoded, EncodeError> {
        with_branching!(w.branching, encode_b, scene, w)
    }
    fn trace(&self, enc: &Encoded, rays: &[Ray], p: usize, math: Math, fc: FloatControls) -> (Vec<Hit>, Vec<Counters>) {
        assert!(L::INFO.maths.contains(&math), "{}: math {} is not one of its modes", L::INFO.name, math.name());
        with_branching!(enc.branching, trace_b, enc, rays, p, math, fc)
    }
    fn loop_work(
        &self,
        enc: &Encoded,
        rays: &[Ray],
        p: usize,
        wave: usize,
        math: Math,
        fc: FloatControls,
    ) -> (LoopWork, LoopWork) {
        assert!(L::INFO.maths.contains(&math), "{}: math {} is not one of its modes", L::INFO.name, math.name());
        with_branching!(enc.branching, loop_work_b, enc, rays, p, wave, math, fc)
    }
    fn mem_reads(&self, enc: &Encoded, rays: &[Ray], p: usize, math: Math, fc: FloatControls) -> Vec<Vec<Reads>> {
        with_branching!(enc.branching, mem_reads_b, enc, rays, p, math, fc)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_unique_and_parse_back() {
        for l in LayoutId::all() {
            assert_eq!(LayoutId::parse(l.name()), Ok(l));
            assert_eq!(LayoutId::all().filter(|m| m.name() == l.name()).count(), 1);
            assert!(!l.info().maths.is_empty() && !l.info().glsl.is_empty() && !l.info().summary.is_empty(), "{l}");
        }
        assert_eq!(LayoutId::f32().name(), "f32");
        assert_eq!(LayoutId::parse("f16h-seed").map(|l| l.name()), Ok("f16h-poster"), "the old name still reads");
        let e = LayoutId::parse("f8").unwrap_err().to_string();
        assert!(e.contains("unknown layout 'f8'") && e.contains("f32, f16h"), "{e}");
    }
}
