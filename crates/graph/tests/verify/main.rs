//! The graph crate's integration tests, one module per subject, linked as one test binary: one
//! link of the crate and its dependencies for the whole suite instead of one per file.

mod api;
mod bakes;
mod common;
mod cost;
mod coverage;
mod demo_graphs;
mod errors;
mod filter;
mod finite;
mod flake;
mod geometry;
mod hextile;
mod logic;
mod mtlx_features;
mod noise_identity;
mod ramp;
mod random_graphs;
mod shading_models;
mod suite;
