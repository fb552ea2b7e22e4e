//! One module per subcommand.

pub mod arch;
pub mod corpus;
pub mod count;
pub mod culling;
pub mod demo;
pub mod fidelity;
pub mod latency;
pub mod raster_args;
pub mod replay;
pub mod sensitivity;
pub mod sweep;
pub mod timeline;
pub mod trace;
pub mod workload_args;
