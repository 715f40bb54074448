//! Fidelity of gltf files (see tests/fidelity.rs).
