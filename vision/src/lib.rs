//! handeye's vision algorithms. Pure: no I/O, no threads, no clocks (time comes in as
//! arguments), so every algorithm can be tested on synthetic images with exact ground truth.

pub mod affine;
mod cpu;
pub mod grasp;
pub mod image;
pub mod locate;
mod moments;
pub mod pointing;
pub mod rng;
pub mod servo;
pub mod tracker;
mod union_find;
pub mod planner;
