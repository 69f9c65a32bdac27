//! Verification of the footprint crate against independent computations.

#![allow(clippy::needless_range_loop, clippy::wrong_self_convention)]

mod block;
mod common;
mod fd;
mod mc;
mod mirror;
mod robust;
mod texture;
