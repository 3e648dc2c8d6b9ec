//! The session directory: format, loading, validation, images and their linearization, ground
//! truth. See `docs/session-format.md`.

pub mod capture;
