//! Integration tests of the world crate, one binary (each file is a module).

/// A small map with two UAVs, two targets and facts, shared by the tests.
mod common;
/// Generated scenarios (`gen:...`): deterministic, valid, verified, clear refusals.
mod generate;
/// Refused maps: every error names `file:line:col` and what was expected.
mod map_errors;
/// The exact optimum of a memoryless UAV and the known-target bound.
mod optimum;
/// `to_text` writes a map that parses back to the same map.
mod round_trip;
/// The thesis's three maps load and their facts hold.
mod thesis_maps;
/// The camera footprint, occlusion at low height, the supercover corner rule.
mod visibility;
