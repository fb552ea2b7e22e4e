//! Timing models of the occlusion-query hardware. This crate does no file IO.
//!
//! Grouped by what each part is, every import pointing down this list:
//! - [`arch`]: architecture parameters (one documented table per machine), TOML and `--set`;
//!   [`report`]: the replay report (serde) and its text form; [`effects`]: only the effect
//!   models a trace can observe; [`error`]: what can go wrong.
//! - [`blocks`]: the hardware blocks, one a module. The O2's, in pipeline order:
//!   [`blocks::fragment_input`] -> [`blocks::fifo`] -> [`blocks::depth_pipeline`]
//!   ([`blocks::depth_prefetch`], [`blocks::write_buffer`]) -> [`blocks::fifo`] ->
//!   [`blocks::occlusion_unit`] ([`blocks::occlusion_engine`]) -> [`blocks::occu_control`],
//!   all sharing one [`blocks::memory_port`]. The InfiniteReality's: [`blocks::interleave`],
//!   [`blocks::fragment_generator`] (one per board), [`blocks::image_engine`] (each with its
//!   own Occlusion Unit and OccU Control), [`blocks::merge_network`] (the two merge stages).
//!   [`blocks::occu_stage`] is the seam choosing the OccU's fidelity on either machine:
//!   `cycle` (event timestamps) or `rtl` ([`blocks::rtl_occu`]: the `occsim-rtl`
//!   register-transfer model clocked every cycle, with [`blocks::waveform`] VCD dumps).
//! - [`machines`]: [`machines::o2`] ([`O2Machine`]) and [`machines::ir`] ([`IrMachine`])
//!   assemble the blocks; [`MachineModel`] is the machine an architecture names.
//! - [`levels`]: the fidelity ladder (functional, analytic, sampled, cycle, rtl), each ending
//!   in the common [`LevelResult`]; [`LevelModel`] is the entry point at any level.
//! - [`replay`]: a trace and options in (level, effects choice, retiling, waveform), a
//!   level's result out: replaying from Rust without the command line.
//! - [`sensitivity`]: the bands of the headline results over the plausible ranges of the
//!   parameters we inferred (which architectures to replay, and the bands their results give).
//!
//! The model is an exact event-timestamp formulation of an in-order pipeline: each block
//! computes the cycle a fragment leaves from the cycle it arrives and the cycle the block is
//! free; FIFO back-pressure comes from the departure cycle of the entry `capacity` places
//! earlier; the memory port grants requests in a fixed order. The timing rules are stated
//! in each block's module documentation and summarised in [`machines::o2`].
//!
//! Invariants:
//! - this crate does no file IO (architectures are parsed from `&str`);
//! - counts equal the functional golden model's, saturated to `counter_bits`;
//! - every cycle is a monotone function of earlier cycles taken in a fixed order, so making any
//!   block faster (more engines, say) never makes a query finish later;
//! - same events and architecture, same report, bit for bit.

// The docs explain how the public items work, linking the private items that do it: read
// them with `cargo doc --document-private-items` (CI builds them so, every link checked).
#![allow(rustdoc::private_intra_doc_links)]

pub mod arch;
pub mod blocks;
pub mod effects;
pub mod error;
mod golden_check;
pub mod levels;
pub mod machines;
pub mod replay;
pub mod report;
pub mod sensitivity;
pub mod timeline;

pub use arch::{Arch, ArchError, IrArch, O2Arch};
pub use blocks::occu_stage::OccuModel;
pub use blocks::waveform::{WaveformOptions, WriteSeek};
pub use effects::{Effects, EffectsChoice};
pub use error::SimError;
pub use levels::{Fidelity, LevelModel, LevelResult};
pub use machines::ir::IrMachine;
pub use machines::o2::O2Machine;
pub use machines::{MachineBuilder, MachineModel};
pub use report::Report;
