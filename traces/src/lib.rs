//! The front half of occsim's data flow: scene -> rasterizer -> golden model -> fragment trace.
//!
//! - [`scene`]: the text scene language (one OpenGL-like command a line).
//! - [`raster`]: the exact reference rasterizer (integer edge functions, no epsilons).
//! - [`golden`]: the functional golden model (depth buffer and query semantics).
//! - [`trace`]: the `.occt` binary fragment trace format (streaming reader and writer).
//! - [`retile`]: `--retile GxH`, replacing brief queries' tiles by a grid (results recomputed).
//! - [`rng`]: the one random generator (SplitMix64) of scenes, streams, tests and benchmarks.
//! - [`builtin`]: built-in scenes (`demo`, `hardcases`).
//! - [`workloads`]: walkthrough workloads: parametric scenes, camera paths and the culling
//!   drivers that issue occlusion queries while the golden model answers them.

// The docs explain how the public items work, linking the private items that do it: read
// them with `cargo doc --document-private-items` (CI builds them so, every link checked).
#![allow(rustdoc::private_intra_doc_links)]

pub mod builtin;
pub mod depth_layout;
mod depth_run;
pub mod event;
mod geometry;
pub mod golden;
pub mod hit_list;
#[cfg(target_arch = "x86_64")]
mod masked_lanes;
pub mod query;
pub mod raster;
pub mod retile;
pub mod rng;
pub mod rounds;
pub mod scene;
pub mod state;
pub mod trace;
pub mod words;
pub mod workloads;

pub use event::{Event, Fragment, GeometryBatch, HostWork, Span};
pub use hit_list::{Hit, HitList};
pub use query::{
    QueryMode, QueryResult, QueryShape, QuerySpec, QueryTotals, RunTally, Tile, TileResult,
};
pub use scene::{Command, SceneError, SceneLine};
pub use state::{DepthFunc, Rect};

/// Version of the generator, recorded in every trace header.
pub const GENERATOR_VERSION: &str = concat!("occsim-traces ", env!("CARGO_PKG_VERSION"));
