//! One module per subcommand.

pub mod arch;
pub mod count;
pub mod demo;
pub mod fidelity;
pub mod replay;
pub mod sweep;
pub mod trace;
