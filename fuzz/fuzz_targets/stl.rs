//! Fuzz the STL reader on arbitrary bytes: it must return a mesh or a one-line error, never
//! panic, and a mesh it returns must be valid (see `check`).
#![no_main]

use libfuzzer_sys::fuzz_target;
use vcsmooth::io::Format;

#[path = "../common/check.rs"]
mod check;

fuzz_target!(|data: &[u8]| check::read(data, Format::Stl, "fuzz.stl"));
