//! One module per subcommand.

// Wired into main.rs by the integrator (`culling compare`, `trace gen --scene`).
#[allow(dead_code)]
pub mod culling;
pub mod count;
pub mod demo;
pub mod sweep;
pub mod trace;
#[allow(dead_code)]
pub mod workload_args;
