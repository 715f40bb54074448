//! Fidelity of obj files (see tests/fidelity.rs).
