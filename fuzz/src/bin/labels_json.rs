//! JRDB `labels_3d` JSON, and the evaluator's JSON detection files (the same reader family).
use std::path::Path;

use pmunet_fuzz::{Bounded, bounded};

#[global_allocator]
static A: Bounded = Bounded;

fn main() {
    afl::fuzz!(|data: &[u8]| {
        // serde_json's Value takes up to ~40 bytes per one-byte token (`[0,0,…]`).
        bounded(data.len(), 64, || {
            if let Ok(text) = std::str::from_utf8(data) {
                let _ = data_jrdb::labels::parse_labels_json(text, Path::new("fuzz.json"));
            }
        });
    });
}
