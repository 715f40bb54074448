//! Independent references the library is tested against: sequential, whole-mesh versions of what
//! the engine runs patch by patch, written with their own arithmetic so that a shared mistake is
//! unlikely. The library never runs them; each module also tests its references themselves.

pub mod lowpass;
pub mod rings;
