//! One module per subcommand.

pub mod count;
pub mod demo;
pub mod sweep;
pub mod trace;
