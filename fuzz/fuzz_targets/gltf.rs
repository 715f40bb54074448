//! Fuzz the glTF readers on arbitrary bytes, as a GLB and as `.gltf` JSON (whose external buffers
//! are refused here: bytes have no directory): each must return a mesh or a one-line error, never
//! panic, and a mesh it returns must be valid (see `check`).
#![no_main]

use libfuzzer_sys::fuzz_target;
use vcsmooth::io::Format;

#[path = "../common/check.rs"]
mod check;

fuzz_target!(|data: &[u8]| {
    check::read(data, Format::Glb, "fuzz.glb");
    check::read(data, Format::Gltf, "fuzz.gltf");
});
