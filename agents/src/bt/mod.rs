//! The behavior-tree engine: text format, shape, run-time semantics.
pub mod parse;
pub mod render;
pub mod replay;
pub mod spec;
pub mod status;
pub mod tree;
