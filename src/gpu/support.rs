//! What a device can run, per variant: the features its layout and math need, the float
//! controls its kernel declares, and the packet implementation and subgroup size it uses. A
//! device is never refused as a whole: what it lacks becomes one skipped line per variant.

use super::DeviceInfo;
use crate::layout::{LayoutId, Needs};
use crate::precision::{FcChoice, FloatControls, Math};
use crate::variant::{Buffers, DeviceBuild, KernelId, KernelSpec, PacketImpl, Variant};
use rspirv::spirv::ExecutionMode::{self, RoundingModeRTE, SignedZeroInfNanPreserve};

/// A float-control execution mode a kernel declares: (SPIR-V execution mode, float width).
pub type FloatMode = (ExecutionMode, u32);

/// The execution modes the kernel of `v` declares: with float controls on, round-to-nearest-even
/// and signed-zero/inf/NaN preservation for fp32, and for fp16 when the layout computes in fp16
/// in this math mode; with them off, none.
pub fn float_modes(v: &Variant) -> Vec<FloatMode> {
    if v.fc == FloatControls::Off {
        return Vec::new();
    }
    let mut m = vec![(RoundingModeRTE, 32), (SignedZeroInfNanPreserve, 32)];
    if needs(v.layout, v.math).float16 {
        m.extend([(RoundingModeRTE, 16), (SignedZeroInfNanPreserve, 16)]);
    }
    m
}

fn needs(layout: LayoutId, math: Math) -> Needs {
    (layout.info().needs)(math)
}

/// The device feature behind a float mode.
fn mode_feature(info: &DeviceInfo, (mode, width): FloatMode) -> (&'static str, bool) {
    match (mode, width) {
        (RoundingModeRTE, 16) => ("shaderRoundingModeRTEFloat16", info.fp16_rte),
        (RoundingModeRTE, _) => ("shaderRoundingModeRTEFloat32", info.fp32_rte),
        (_, 16) => ("shaderSignedZeroInfNanPreserveFloat16", info.preserve_16),
        _ => ("shaderSignedZeroInfNanPreserveFloat32", info.preserve_32),
    }
}

/// `Ok` when `info`'s device can run the kernels of `v` as built (its float controls
/// included), else what it lacks, in one line.
pub fn check(info: &DeviceInfo, v: &Variant) -> Result<(), String> {
    let l = v.layout.info();
    let n = (l.needs)(v.math);
    let mut missing = Vec::new();
    if n.storage16 && !info.storage_16bit {
        missing.push("storageBuffer16BitAccess");
    }
    if n.float16 && !info.shader_float16 {
        missing.push("shaderFloat16");
    }
    if v.buffers == crate::variant::Buffers::Addressed && !info.buffer_device_address {
        missing.push("bufferDeviceAddress");
    }
    match v.fc {
        FloatControls::On => missing
            .extend(float_modes(v).into_iter().map(|m| mode_feature(info, m)).filter(|(_, ok)| !ok).map(|(n, _)| n)),
        FloatControls::Off if !l.float_controls_off => {
            return Err(format!("{} has no kernel build without float controls", v.layout))
        }
        FloatControls::Off => {}
    }
    if missing.is_empty() {
        Ok(())
    } else {
        Err(format!("{} needs {}, which the device lacks", v.name(false), missing.join(", ")))
    }
}

/// The variant this device runs for `v` under `--float-controls choice` (auto: on where the
/// device has the modes, else off where the layout has such a build), or why it cannot run
/// (auto: what the build without float controls lacks, where the layout has one — the
/// feature that really stands in the way, such as shaderFloat16 on SwiftShader).
pub fn resolve(info: &DeviceInfo, v: Variant, choice: FcChoice) -> Result<Variant, String> {
    match choice {
        FcChoice::On => check(info, &v.with_fc(FloatControls::On)).map(|_| v.with_fc(FloatControls::On)),
        FcChoice::Off => check(info, &v.with_fc(FloatControls::Off)).map(|_| v.with_fc(FloatControls::Off)),
        FcChoice::Auto => {
            let on = v.with_fc(FloatControls::On);
            match check(info, &on) {
                Ok(()) => Ok(on),
                Err(why) => check(info, &v.with_fc(FloatControls::Off))
                    .map(|_| v.with_fc(FloatControls::Off))
                    .map_err(|off| if v.layout.info().float_controls_off { off } else { why }),
            }
        }
    }
}

/// What a device makes of a kernel to build, decided once ([`decide`]): the kernel it builds,
/// the subgroup size its pipeline is pinned to and what the build takes from the device.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Decision {
    /// The variant with its float controls resolved and its buffers, in the packet
    /// implementation the device runs; timed as decided ([`Decision::with_stats`] gives
    /// the counting build).
    pub id: KernelId,
    /// The subgroup size the pipeline is pinned to (`None`: the driver's).
    pub pin: Option<u32>,
    /// What the device's build takes from it: fp64, 16-bit storage, the SPIR-V version, the
    /// private arrays its compiler keeps in registers and where the next entry is held.
    pub build: DeviceBuild,
}

impl Decision {
    /// The same decision for the timed (`false`) or counting (`true`) build.
    pub fn with_stats(self, stats: bool) -> Decision {
        Decision { id: self.id.with_stats(stats), ..self }
    }

    /// The same decision for a scene read through `buffers` (set when the scene is uploaded):
    /// by address needs `bufferDeviceAddress`.
    pub fn reading(self, info: &DeviceInfo, buffers: Buffers) -> Result<Decision, String> {
        if buffers == self.id.variant.buffers {
            return Ok(self);
        }
        admit(info, &KernelId { variant: self.id.variant.with_buffers(buffers), ..self.id })
    }
}

/// The device's one decision for a kernel: its float controls under `k.fc` ([`resolve`]), the
/// packet implementation (the one asked for at P > 1, else the device's [`packet_plan`]), then
/// [`admit`]. `Err`: why the device cannot run it, in one line.
pub fn decide(info: &DeviceInfo, k: &KernelSpec) -> Result<Decision, String> {
    let v = resolve(info, k.variant, k.fc)?;
    admit(info, &KernelId::new(v, packet_impl(info, k), false))
}

/// The packet implementation kernel `k` runs in: the one asked for at P > 1, else the
/// device's [`packet_plan`].
pub fn packet_impl(info: &DeviceInfo, k: &KernelSpec) -> PacketImpl {
    k.imp.filter(|_| k.variant.packet > 1).unwrap_or_else(|| packet_plan(info, k.variant.packet).0)
}

/// Whether the device runs kernel `k` exactly as given (its features: [`check`]; its packet
/// implementation: subgroup operations and a subgroup that holds the packet), with the
/// subgroup size to pin.
pub fn admit(info: &DeviceInfo, k: &KernelId) -> Result<Decision, String> {
    check(info, &k.variant)?;
    let pin = subgroup_pin(info, k)?;
    Ok(Decision { id: k.with_stats(false), pin, build: info.build() })
}

/// The subgroup size a kernel's pipeline is pinned to: for the subgroup packet implementation,
/// the size planned for its P where the device allows pinning; otherwise none, and then the
/// reported size must hold the packet.
fn subgroup_pin(info: &DeviceInfo, k: &KernelId) -> Result<Option<u32>, String> {
    let (v, imp) = (&k.variant, k.imp);
    if imp == PacketImpl::Hybrid && !has_subgroup_arithmetic(info) {
        return Err(format!(
            "{}: hybrid packets need subgroup arithmetic in compute shaders (device: {})",
            k.name(),
            info.name
        ));
    }
    if imp != PacketImpl::Subgroup {
        return Ok(None);
    }
    if !has_subgroup_clustered(info) {
        return Err(format!(
            "{}: subgroup packets need clustered subgroup operations in compute shaders, which {} lacks \
             (the hybrid packets run there)",
            k.name(),
            info.name
        ));
    }
    let pin = packet_plan(info, v.packet).1;
    if pin.is_none() && v.packet > info.subgroup_size as usize {
        return Err(format!(
            "{}: packets of {} need a subgroup of at least {} (device: {})",
            k.name(),
            v.packet,
            v.packet,
            info.subgroup_size
        ));
    }
    Ok(pin)
}

/// The subgroup size a packet kernel of `p` rays is built for: the smallest power of two ≥ p the
/// device can be pinned to (with `subgroupSizeControl`), else the device's reported size.
/// `None`: no subgroup can hold the packet (the shared-memory implementation is used).
pub fn packet_subgroup(p: usize, subgroup: u32, control: Option<(u32, u32)>) -> Option<u32> {
    if p <= 1 {
        return None;
    }
    match control {
        Some((lo, hi)) => {
            let want = (p as u32).next_power_of_two().max(lo);
            (want <= hi).then_some(want)
        }
        None => (p <= subgroup as usize).then_some(subgroup),
    }
}

/// Whether a subgroup of this device (pinned where it allows) holds a packet of `p` rays.
pub fn subgroup_holds(info: &DeviceInfo, p: usize) -> bool {
    let control = info.subgroup_size_control.then_some((info.min_subgroup_size, info.max_subgroup_size));
    packet_subgroup(p, info.subgroup_size, control).is_some()
}

/// The packet implementation for `p` rays and the subgroup size to pin (`None`: leave the
/// driver's choice, which is the reported size): a subgroup when one holds the packet and the
/// device has clustered subgroup operations, else the hybrid (subgroup arithmetic, then shared
/// memory; a workgroup of P invocations, so it also serves packets a subgroup holds) where the
/// device has subgroup arithmetic in compute, else shared memory.
pub fn packet_plan(info: &DeviceInfo, p: usize) -> (PacketImpl, Option<u32>) {
    let control = info.subgroup_size_control.then_some((info.min_subgroup_size, info.max_subgroup_size));
    match packet_subgroup(p, info.subgroup_size, control) {
        _ if p == 1 => (PacketImpl::Single, None),
        Some(size) if has_subgroup_clustered(info) => (PacketImpl::Subgroup, control.map(|_| size)),
        _ if has_subgroup_arithmetic(info) => (PacketImpl::Hybrid, None),
        _ => (PacketImpl::Shared, None),
    }
}

/// Subgroup basic and arithmetic operations in compute shaders (the hybrid packets need them).
pub fn has_subgroup_arithmetic(info: &DeviceInfo) -> bool {
    let (basic, arithmetic) = (1u32, 1u32 << 2);
    info.subgroup_ops & basic != 0 && info.subgroup_ops & arithmetic != 0
}

/// Clustered subgroup operations besides the arithmetic (the subgroup packets reduce each
/// cluster of P invocations with them). SwiftShader has arithmetic but not these: its
/// compiler warns "UNSUPPORTED: Group operation: 3" (ClusteredReduce) and returns wrong values.
pub fn has_subgroup_clustered(info: &DeviceInfo) -> bool {
    let clustered = 1u32 << 6;
    has_subgroup_arithmetic(info) && info.subgroup_ops & clustered != 0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn packets_without_clustered_operations_go_hybrid_or_shared() {
        let mut info = DeviceInfo { subgroup_size: 4, subgroup_ops: 0xff, ..Default::default() };
        assert_eq!(packet_plan(&info, 4).0, PacketImpl::Subgroup);
        info.subgroup_ops &= !(1 << 6);
        for p in [4, 8, 64] {
            assert_eq!(packet_plan(&info, p), (PacketImpl::Hybrid, None), "P {p}");
        }
        info.subgroup_ops &= !(1 << 2);
        assert_eq!(packet_plan(&info, 4), (PacketImpl::Shared, None));
        assert_eq!(packet_plan(&info, 1).0, PacketImpl::Single);
    }

    #[test]
    fn packet_choice_for_every_subgroup_size() {
        for size in [4u32, 8, 16, 32, 64, 128] {
            for p in [1usize, 4, 8, 16, 32, 64] {
                // Without size control: the reported size must hold the packet.
                let fixed = packet_subgroup(p, size, None);
                assert_eq!(fixed, (p > 1 && p <= size as usize).then_some(size), "size {size}, P {p}");
                // With control over [4, size]: pinned to the smallest size that holds P.
                let pinned = packet_subgroup(p, size, Some((4, size)));
                assert_eq!(pinned, (p > 1 && p <= size as usize).then_some((p as u32).max(4)), "size {size}, P {p}");
            }
        }
        // A device whose smallest size exceeds P pins its smallest (clusters of P inside it).
        assert_eq!(packet_subgroup(4, 32, Some((32, 64))), Some(32));
        assert_eq!(packet_subgroup(64, 32, Some((32, 64))), Some(64));
        assert_eq!(packet_subgroup(64, 32, Some((8, 32))), None);
    }
}
