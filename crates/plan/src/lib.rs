//! Selective caching: which procedural-graph nodes a render should cache as mip-mapped tiles.
//!
//! A short profiling render records, per stream of requests (a material's evaluation of a
//! graph), the footprint levels asked for and the tiles their lookups would read, and per node
//! its cost by level: a [`Profile`]. The [`Model`] predicts, for any set of cached nodes
//! ([`PlanSpec`]) and a final render ([`Target`]), the evaluations, lookups, tile fills, bytes
//! and seconds it will cost ([`Prediction`]); the planner ([`search`]) finds the set it predicts
//! fastest within a memory budget; a [`PlanFile`] stores the choice.
//!
//! The crate knows no scenes, graphs or caches of ours: a profile is plain data another
//! renderer can write (see `docs/selective-caching.md` for the schema and the model's
//! assumptions).

#![deny(missing_docs)]

mod error;
pub mod hash;
pub mod model;
pub mod planfile;
pub mod planner;
pub mod profile;
pub mod richness;

pub use error::{PlanError, Result};
pub use hash::{text_hash, Fnv};
pub use model::{Model, NodePrediction, PlanSpec, Prediction, Target};
pub use planfile::{PlanFile, PlanNode, Summary, PLAN_SCHEMA};
pub use planner::{candidates, search, SearchOptions, SearchResult};
pub use profile::{Profile, PROFILE_SCHEMA};
