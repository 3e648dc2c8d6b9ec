//! From the camera's card to a session.
//!
//! * [`matching`]: which camera file is which of the controller's exposures, by time (the camera
//!   clock's offset and drift estimated by a monotone alignment), with test shots, missing files,
//!   duplicates and other bodies reported by name and ambiguous cases refused.

pub mod matching;
