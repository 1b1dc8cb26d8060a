//! The terminal UI's tests, in one binary: whole frames rendered from recorded vehicle states
//! (insta snapshots in `snapshots/`), the UI driven against the embedded twin, and the import
//! rules of the UI's modules read from the sources.

#[path = "../ui_support/mod.rs"]
mod ui_support;

mod air;
mod battery;
mod control;
mod fleet_list;
mod frames;
mod guard;
mod layers;
mod layouts;
mod map;
mod mission_keys;
mod operator;
mod progress;
mod targets;
