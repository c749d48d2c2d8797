//! JRDB `calibration/defaults.yaml`.
use std::path::Path;

use data_jrdb::Calibration;
use pmunet_fuzz::{Bounded, bounded};

#[global_allocator]
static A: Bounded = Bounded;

fn main() {
    afl::fuzz!(|data: &[u8]| {
        // A YAML node takes ~100 bytes; aliases are bounded by the parser's own repetition limit.
        bounded(data.len(), 256, || {
            if let Ok(text) = std::str::from_utf8(data) {
                let _ = Calibration::parse(text, Path::new("defaults.yaml"));
            }
        });
    });
}
