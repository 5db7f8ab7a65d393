//! The parts of the `clatch` command-line tool that its evaluation harness (`eval/`, `clatch-eval`)
//! builds on: the shared options and the embedded photo with the demo's view of it. Not a published
//! API; the tool itself is `src/main.rs`.

pub mod flags;
pub mod names;
pub mod photo;
