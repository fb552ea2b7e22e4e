//! Timing models of the occlusion-query hardware. This crate does no file IO.
