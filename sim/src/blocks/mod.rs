//! The hardware blocks, one a module, named after the block. They know the architecture
//! parameters and one another in pipeline order, never a machine or a fidelity level.

pub mod depth_pipeline;
pub mod depth_prefetch;
pub mod fifo;
pub mod fragment_generator;
pub mod fragment_input;
pub mod geometry;
pub mod host;
pub mod image_engine;
pub mod interleave;
pub mod memory_port;
pub mod merge_network;
pub mod occlusion_engine;
pub mod occlusion_unit;
pub mod occu_control;
pub mod occu_stage;
pub mod rtl_occu;
pub mod waveform;
pub mod write_buffer;
