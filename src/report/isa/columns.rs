//! Columns that mean the same on every vendor, filled from each driver's own statistics (its
//! names kept in [`IsaRow::stats`]): registers per thread, private memory per thread, spill
//! instructions, occupancy, instructions and the compiler's cycle estimate. A *thread* is one
//! invocation: a lane of an AMD wave, an Adreno fiber, an Intel work-item (a channel of a SIMD
//! thread), an NVIDIA thread, a Mali or VideoCore thread. Each vendor's file (`crate::vendor`)
//! says how its statistics map to them and where each comes from (docs/vendors.md prints it).

use super::IsaRow;
use crate::vendor::{Input, Neutral, VendorId};

impl IsaRow {
    /// Fills the vendor-neutral columns from the driver's statistics through its vendor's
    /// mapping (and, where the driver has none, from the disassembly counts).
    pub(super) fn normalize(&mut self) {
        self.vendor = VendorId::of_driver(&self.driver);
        let n = match self.vendor.get() {
            Some(v) => (v.neutral)(&Input {
                stats: &self.stats,
                generation: &self.generation,
                subgroup_size: self.subgroup_size,
                private_ops: self.asm.and_then(|a| a.scratch_loads.zip(a.scratch_stores)),
            }),
            None => Neutral { instructions: self.instructions, ..Neutral::default() },
        };
        (self.registers, self.private_bytes, self.spills, self.occupancy) =
            (n.registers, n.private_bytes, n.spills, n.occupancy);
        self.occupancy_unit = self.vendor.get().and_then(|v| v.occupancy).map_or("", |o| o.unit).to_string();
        (self.instructions, self.cycles) = (n.instructions, n.cycles);
    }
}
