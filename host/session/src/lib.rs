//! The session directory: format, loading, validation, images and their linearization, ground truth.
