//! BRDF sample files: the compact binary format, CSV export, Cornell .brdf import/export.
