//! The trigger controller's sequencing logic as a sans-IO state machine (no_std): events and a u64 microsecond clock in, pin actions and messages out.
