//! Fidelity of off_stl files (see tests/fidelity.rs).
