//! Coded targets: AprilTag tag36h11 detection with sub-pixel corners, and printable target sheets.

pub mod tag36h11;
