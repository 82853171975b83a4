//! Command-line commands that look at scenes.

pub mod input;
pub mod scenes;
