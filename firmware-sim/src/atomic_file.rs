//! Whole-file writes that a crash cannot tear, for the twin's parameter and mission files:
//! vtol-link's text files, the same the ground station keeps its parameter files with.

pub use vtol_link::text_file::{TextFileError, check_writable, read_text, write_text};
