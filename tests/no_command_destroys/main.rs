//! Issue 62, "No command destroys what it was given, hangs, or panics": one test per numbered
//! defect of the reliability pass, named after it, and the property tests over every command
//! that writes a file. Each module owns a group of defects.

#[path = "../common/mod.rs"]
mod common;

mod cli;
mod guard;
mod import;
mod staleness;
