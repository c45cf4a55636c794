//! The grid world: maps, visibility, episodes and the ground truth.
//!
//! - [`map`]: the `.map` file format (parse and write).
//! - [`visibility`]: the camera model, which cells a pose sees.
//! - [`scenario`]: a loaded map with its visibility lookup table and verified facts.
//! - [`optimum`]: the exact best expected episode length of one UAV, the yardstick for
//!   learning curves.
//! - [`sim`]: episodes and the ground truth of one trial.
//! - [`node`]: the `world` process around [`sim::World`].

pub mod error;
pub mod generate;
pub mod map;
pub mod node;
pub mod optimum;
pub mod scenario;
pub mod sim;
pub mod visibility;

pub use error::{MapError, MapErrorKind, OptimumError, WorldError};
pub use map::{parse_map, Cell, Expect, MapFile};
pub use scenario::Scenario;
