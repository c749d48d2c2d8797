//! ROS 2 `sensor_msgs/msg/PointCloud2` in CDR (a recording's messages).
use data_jrdb::ReadLimits;
use data_jrdb::pointcloud2::decode_cdr;
use pmunet_fuzz::{Bounded, bounded};

#[global_allocator]
static A: Bounded = Bounded;

fn main() {
    afl::fuzz!(|data: &[u8]| {
        // The points take at most 3 times the data (x, y and z may share 4 bytes); serde's
        // cautious pre-allocation of a declared sequence (the fields) takes up to 1 MiB more.
        bounded(data.len() + (1 << 20), 4, || {
            let _ = decode_cdr(data, &ReadLimits::NONE);
            let _ = decode_cdr(data, &ReadLimits { max_points: 1000, max_data_bytes: 1 << 16 });
        });
    });
}
