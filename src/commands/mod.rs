//! One module per subcommand.

// Wired into main.rs by the integrator (`culling compare`, `trace gen --scene`).
pub mod count;
#[allow(dead_code)]
pub mod culling;
pub mod demo;
pub mod sweep;
pub mod trace;
#[allow(dead_code)]
pub mod workload_args;
