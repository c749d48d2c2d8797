//! KITTI-style label and detection lines (what `eval` and JRDB's toolkit read).
use std::path::Path;

use eval::kitti::{FileKind, parse_str};
use pmunet_fuzz::{Bounded, bounded};

#[global_allocator]
static A: Bounded = Bounded;

fn main() {
    afl::fuzz!(|data: &[u8]| {
        // A parsed object is ~160 bytes and a line holds at least 17 one-byte columns.
        bounded(data.len(), 16, || {
            if let Ok(text) = std::str::from_utf8(data) {
                let _ = parse_str(text, FileKind::GroundTruth, Path::new("gt.txt"));
                let _ = parse_str(text, FileKind::Detections, Path::new("det.txt"));
            }
        });
    });
}
