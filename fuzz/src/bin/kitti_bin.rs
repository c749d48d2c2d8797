//! KITTI velodyne `.bin` (float32 x, y, z, intensity records).
use data_jrdb::{CloudFormat, ReadLimits, parse_cloud, parse_cloud_within};
use pmunet_fuzz::{Bounded, bounded};

#[global_allocator]
static A: Bounded = Bounded;

fn main() {
    afl::fuzz!(|data: &[u8]| {
        bounded(data.len(), 4, || {
            let _ = parse_cloud(data, CloudFormat::KittiBin);
            let _ = parse_cloud_within(data, CloudFormat::KittiBin, &ReadLimits { max_points: 10, max_data_bytes: 160 });
        });
    });
}
