//! NumPy `.npy` (versions 1–3).
use data_jrdb::{CloudFormat, ReadLimits, parse_cloud, parse_cloud_within};
use pmunet_fuzz::{Bounded, bounded, cloud_factor};

#[global_allocator]
static A: Bounded = Bounded;

fn main() {
    afl::fuzz!(|data: &[u8]| {
        bounded(data.len(), cloud_factor(data), || {
            let _ = CloudFormat::sniff(data);
            let _ = parse_cloud(data, CloudFormat::Npy);
            let _ = parse_cloud_within(data, CloudFormat::Npy, &ReadLimits { max_points: 1000, max_data_bytes: 1 << 16 });
        });
    });
}
