//! Timing models of the occlusion-query hardware. This crate does no file IO.
//!
//! - [`arch`]: architecture parameters (one documented table per machine), TOML and `--set`.
//! - [`o2`]: the O2-like machine: [`O2Machine`] consumes [`occsim_traces::Event`]s and
//!   produces a [`Report`]. Its blocks, one module each, in pipeline order:
//!   [`fragment_input`] -> [`fifo`] -> [`depth_pipeline`] ([`depth_prefetch`],
//!   [`write_buffer`]) -> [`fifo`] -> [`occlusion_unit`] ([`occlusion_engine`]) ->
//!   [`occu_control`], all sharing one [`memory_port`].
//! - [`ir`]: the InfiniteReality-like machine: [`IrMachine`]. Its blocks: [`interleave`],
//!   [`fragment_generator`] (one per board), [`image_engine`] (each with its own
//!   [`occlusion_unit`] and [`occu_control`] through [`occu_stage`]), [`merge_network`]
//!   (the two merge stages).
//! - [`occu_stage`]: the seam choosing the OccU's fidelity on either machine: `cycle`
//!   (event timestamps) or `rtl` ([`rtl_occu`]: the `occsim-rtl` register-transfer model
//!   clocked every cycle, with [`waveform`] VCD dumps; at the IR, of Image Engine 0 of
//!   board 0).
//! - [`machine`]: [`MachineModel`], the machine an architecture names (the entry point).
//! - [`fidelity`]: the fidelity ladder (functional, [`analytic`], [`sampled`], cycle, rtl) and its
//!   common [`LevelResult`]; [`effects`]: only the effect models a trace can observe.
//! - [`report`]: the replay report (serde) and its text form.
//!
//! The model is an exact event-timestamp formulation of an in-order pipeline: each block
//! computes the cycle a fragment leaves from the cycle it arrives and the cycle the block is
//! free; FIFO back-pressure comes from the departure cycle of the entry `capacity` places
//! earlier; the memory port grants requests in a fixed order. The timing rules are stated
//! in each block's module documentation and summarised in [`o2`].
//!
//! Invariants:
//! - this crate does no file IO (architectures are parsed from `&str`);
//! - counts equal the functional golden model's, saturated to `counter_bits`;
//! - every cycle is a monotone function of earlier cycles taken in a fixed order, so making any
//!   block faster (more engines, say) never makes a query finish later;
//! - same events and architecture, same report, bit for bit.

pub mod arch;
pub mod blocks;
pub mod effects;
pub mod error;
mod golden_check;
pub mod levels;
pub mod machines;
pub mod report;

pub use arch::{Arch, ArchError, IrArch, O2Arch};
pub use blocks::occu_stage::OccuModel;
pub use blocks::waveform::WaveformOptions;
pub use effects::{Effects, EffectsChoice};
pub use error::SimError;
pub use levels::{Fidelity, LevelModel, LevelResult};
pub use machines::ir::IrMachine;
pub use machines::o2::O2Machine;
pub use machines::MachineModel;
pub use report::Report;
