//! Command-line commands that look at scenes.

pub mod scenes;
