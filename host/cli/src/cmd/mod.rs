//! One module per subcommand; each owns its flags and validates them into library configs.

pub mod demo;
pub mod synth;
pub mod sim;
pub mod ports;
pub mod capture;
pub mod targets;
pub mod poses;
pub mod derender;
pub mod fit;
pub mod compare;
pub mod process;
pub mod bench;
