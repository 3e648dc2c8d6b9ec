//! What the commands print: one module per command whose report is more than a line or two,
//! holding its text tables and lines and its hand-built JSON (the `cmd/` modules only parse
//! flags into the library's configs, call the library and hand its results here).

pub mod capture;
pub mod derender;
pub mod ingest;
pub mod poses;
pub mod targets;
