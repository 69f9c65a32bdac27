//! The renderer's integration tests, one binary with a module per subject (one link instead of
//! eight): closed-form radiance, bad input, the tile cache, footprints against Monte Carlo,
//! MaterialX materials, partial opacity, footprints deferred at hits without textures, split renders merged from pass files, Mitsuba's reference images, selective caching and Embree against the built-in BVH.

mod analytic;
mod bad_input;
mod caching;
mod deferred_footprints;
mod embree;
mod exhaustive;
mod footprint_mc;
mod mtlx;
mod opacity;
mod passes;
mod pixel_textures;
mod reference;
mod selective;
