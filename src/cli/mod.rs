//! The commands of the command line, one module each, and what they share.

pub mod args;
pub mod batch;
pub mod contact;
pub mod files;
pub mod info;
pub mod input;
pub mod measure;
pub mod order;
pub mod orderings;
pub mod pick;
pub mod render;
pub mod slice;
pub mod view;
