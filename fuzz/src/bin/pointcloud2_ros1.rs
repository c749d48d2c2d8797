//! ROS 1 `sensor_msgs/PointCloud2` in ROS 1's serialization (a `.bag`'s messages).
use data_jrdb::ReadLimits;
use data_jrdb::pointcloud2::decode_ros1;
use pmunet_fuzz::{Bounded, bounded};

#[global_allocator]
static A: Bounded = Bounded;

fn main() {
    afl::fuzz!(|data: &[u8]| {
        // The points take at most 3 times the data (x, y and z may share 4 bytes); the fields at
        // most the data again (each at least 13 bytes of it, checked before they are reserved).
        bounded(4 * data.len() + (1 << 16), 4, || {
            let _ = decode_ros1(data, &ReadLimits::NONE);
            let _ = decode_ros1(data, &ReadLimits { max_points: 1000, max_data_bytes: 1 << 16 });
        });
    });
}
