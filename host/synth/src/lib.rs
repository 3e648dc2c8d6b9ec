//! Synthetic measurement sessions with ground truth: scenes, procedural head, physically based image formation.
