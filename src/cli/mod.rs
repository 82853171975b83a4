//! Command-line commands that look at scenes.

pub mod batch;
pub mod input;
pub mod scenes;
