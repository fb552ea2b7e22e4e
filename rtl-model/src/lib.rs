//! Bit-accurate register-transfer model of the Occlusion Unit: its occlusion engines, the
//! unit sequencer that keeps them in lockstep, and OccU Control (round-robin hit arbiter,
//! write buffer, record sequencer).
//!
//! Architecture invariants:
//! - no floats anywhere (`#![deny(clippy::float_arithmetic)]`; times are integer cycles and
//!   picoseconds);
//! - every register has a fixed width; values are stored in `u64`/`u32` and masked to it;
//! - two-phase discipline: each cycle [`OccuRtl::step`] first evaluates every wire from the
//!   current registers and inputs ([`OccuRtl::eval`], `&self`), then latches the registers
//!   from those wires ([`OccuRtl::latch`]); a waveform probe sees both in between; cycles
//!   that [`OccuRtl::quiet_cycles`] proves would latch nothing but the tile step may be
//!   jumped in bulk ([`OccuRtl::skip_quiet_cycles`]), with the same registers after;
//! - the crate knows nothing of the simulator (`occsim-sim` depends on it, not the reverse);
//! - no IO besides the waveform encoders' `std::io::Write` (and, for [`fst`], `Seek`).
//!
//! Blocks, one module each: [`bits`] (fixed-width helpers), [`occlusion_engine`],
//! [`occu_control`], [`occlusion_unit`] (the top level and its ports); the model's own
//! shortcut [`tile_locator`] (not hardware); waveforms: [`wave`]
//! (the one writer: declarations and change detection) with two encoders, [`vcd`] and [`fst`].

// The docs explain how the public items work, linking the private items that do it: read
// them with `cargo doc --document-private-items` (CI builds them so, every link checked).
#![allow(rustdoc::private_intra_doc_links)]
#![deny(clippy::float_arithmetic)]
#![forbid(unsafe_code)]

pub mod bits;
pub mod fst;
pub mod occlusion_engine;
pub mod occlusion_unit;
pub mod occu_control;
pub mod tile_locator;
pub mod vcd;
pub mod wave;

pub use occlusion_unit::{
    CycleInputs, CycleOutputs, FragmentPort, OccuParams, OccuRtl, QueryConfig, ResultPath, TileRect,
};
pub use occu_control::Word;
