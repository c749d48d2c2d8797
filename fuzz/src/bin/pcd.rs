//! PCD in its three encodings, through both readers (all fields kept, and a service's bounded
//! xyz-only read) and the format sniffer.
use data_jrdb::{CloudFormat, NonFinite, ReadLimits, parse_cloud_within, pcd::parse_pcd};
use pmunet_fuzz::{Bounded, bounded, cloud_factor};

#[global_allocator]
static A: Bounded = Bounded;

fn main() {
    afl::fuzz!(|data: &[u8]| {
        bounded(data.len(), cloud_factor(data), || {
            let _ = CloudFormat::sniff(data);
            let _ = parse_pcd(data, NonFinite::Drop);
            let _ = parse_pcd(data, NonFinite::Error);
            let _ = parse_cloud_within(data, CloudFormat::Pcd, &ReadLimits { max_points: 100_000, max_data_bytes: 1 << 22 });
        });
    });
}
