//! Firmware simulator: the firmware's own sequencer driven by a simulated clock and camera/flash models, on a pseudo-terminal.
