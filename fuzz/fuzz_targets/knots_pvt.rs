//! Fuzz target: the PVT knot-file parser never panics, and what it accepts keeps its
//! promises. The first byte picks the number of motors.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| qmarc_knots::fuzzing::pvt(data));
