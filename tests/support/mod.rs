//! Helpers shared by integration tests and benchmarks.
#![allow(dead_code)]

pub mod cli;
pub mod gl_replay;
