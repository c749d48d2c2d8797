//! ROS's `sensor_msgs/PointCloud2`: the message every ROS LiDAR driver publishes, decoded from a
//! ROS 2 (CDR) or ROS 1 serialization into points. Any field layout (x, y and z as float32 or
//! float64 at any offset, other fields skipped), organised or not, either byte order; points with
//! a non-finite coordinate (an organised cloud's missing returns) dropped and counted.
//!
//! Every size the message states is checked against the bytes present before anything is
//! allocated for it, as the file readers do.

use serde::Deserialize;

use crate::cloud::ReadLimits;
use crate::error::ErrorKind;

/// `builtin_interfaces/Time` (ROS 2) or `time` (ROS 1): seconds and nanoseconds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
pub struct Stamp {
    /// Seconds.
    pub sec: i64,
    /// Nanoseconds within the second.
    pub nanosec: u32,
}

impl Stamp {
    /// The stamp in seconds.
    pub fn seconds(self) -> f64 {
        self.sec as f64 + self.nanosec as f64 * 1e-9
    }
}

/// A decoded PointCloud2: where and when, and its finite points.
#[derive(Debug, Clone, PartialEq)]
pub struct PointCloud2 {
    /// `header.stamp`.
    pub stamp: Stamp,
    /// `header.frame_id`: the sensor frame the points are in.
    pub frame_id: String,
    /// `height` (1 for an unorganised cloud).
    pub height: u32,
    /// `width`.
    pub width: u32,
    /// The finite points, row by row.
    pub points: Vec<[f32; 3]>,
    /// Points dropped for a non-finite coordinate.
    pub dropped_non_finite: usize,
}

/// The fields a message declares, as both serializations lay them out.
#[derive(Debug, Clone, Deserialize)]
struct PointField {
    name: String,
    offset: u32,
    datatype: u8,
    count: u32,
}

#[derive(Debug, Deserialize)]
struct Ros2Time {
    sec: i32,
    nanosec: u32,
}

#[derive(Debug, Deserialize)]
struct Ros2Header {
    stamp: Ros2Time,
    frame_id: String,
}

/// `sensor_msgs/msg/PointCloud2` as ROS 2 serializes it (CDR); its data borrowed.
#[derive(Debug, Deserialize)]
struct Ros2Message<'a> {
    header: Ros2Header,
    height: u32,
    width: u32,
    fields: Vec<PointField>,
    is_bigendian: bool,
    point_step: u32,
    row_step: u32,
    data: &'a [u8],
    #[allow(dead_code)]
    is_dense: bool,
}

/// The layout of a message's data, whichever serialization carried it.
struct Layout<'a> {
    fields: &'a [PointField],
    is_bigendian: bool,
    height: u32,
    width: u32,
    point_step: u32,
    row_step: u32,
    data: &'a [u8],
}

const FLOAT32: u8 = 7;
const FLOAT64: u8 = 8;

/// Decodes a ROS 2 `sensor_msgs/msg/PointCloud2` message (CDR with its 4-byte encapsulation
/// header, as an MCAP or a ROS 2 bag stores it).
pub fn decode_cdr(bytes: &[u8], limits: &ReadLimits) -> Result<PointCloud2, ErrorKind> {
    let bad = |why: String| ErrorKind::Mismatch(format!("not a CDR sensor_msgs/msg/PointCloud2: {why}"));
    // The encapsulation header: the representation (0 0: big-endian CDR, 0 1: little-endian)
    // and two option bytes; alignment counts from after it.
    let (header, payload) = bytes.split_at_checked(4).ok_or_else(|| bad(format!("{} bytes, shorter than the encapsulation header", bytes.len())))?;
    // The decoder checks every length against the bytes left before it takes them, and borrows
    // the point data.
    let m: Ros2Message = match header[..2] {
        [0, 0] => cdr_encoding::from_bytes::<Ros2Message, byteorder::BigEndian>(payload),
        [0, 1] => cdr_encoding::from_bytes::<Ros2Message, byteorder::LittleEndian>(payload),
        _ => return Err(bad(format!("encapsulation {:02x} {:02x} is not plain CDR (00 00 or 00 01)", header[0], header[1]))),
    }
    .map_err(|e| bad(e.to_string()))?
    .0;
    let layout = Layout { fields: &m.fields, is_bigendian: m.is_bigendian, height: m.height, width: m.width, point_step: m.point_step, row_step: m.row_step, data: m.data };
    let (points, dropped_non_finite) = points(&layout, limits)?;
    Ok(PointCloud2 {
        stamp: Stamp { sec: m.header.stamp.sec as i64, nanosec: m.header.stamp.nanosec },
        frame_id: m.header.frame_id,
        height: m.height,
        width: m.width,
        points,
        dropped_non_finite,
    })
}

/// Decodes a ROS 1 `sensor_msgs/PointCloud2` message (ROS 1's serialization, as a `.bag` stores
/// it: little-endian, unaligned, each array and string after its 32-bit length).
pub fn decode_ros1(bytes: &[u8], limits: &ReadLimits) -> Result<PointCloud2, ErrorKind> {
    let mut r = Ros1Reader { bytes, at: 0 };
    let _seq = r.u32("header.seq")?;
    let stamp = Stamp { sec: r.u32("header.stamp.secs")? as i64, nanosec: r.u32("header.stamp.nsecs")? };
    let frame_id = r.string("header.frame_id")?;
    let (height, width) = (r.u32("height")?, r.u32("width")?);
    let n = r.u32("fields (count)")? as usize;
    // Each field takes at least 13 bytes: a bound before anything is reserved for them.
    if n > (bytes.len() - r.at) / 13 {
        return Err(ErrorKind::Truncated(format!("{n} fields cannot fit in the {} bytes left", bytes.len() - r.at)));
    }
    let mut fields = Vec::with_capacity(n);
    for _ in 0..n {
        fields.push(PointField { name: r.string("fields[].name")?, offset: r.u32("fields[].offset")?, datatype: r.u8("fields[].datatype")?, count: r.u32("fields[].count")? });
    }
    let is_bigendian = r.u8("is_bigendian")? != 0;
    let (point_step, row_step) = (r.u32("point_step")?, r.u32("row_step")?);
    let len = r.u32("data (length)")? as usize;
    let data = r.take(len, "data")?;
    let layout = Layout { fields: &fields, is_bigendian, height, width, point_step, row_step, data };
    let (points, dropped_non_finite) = points(&layout, limits)?;
    Ok(PointCloud2 { stamp, frame_id, height, width, points, dropped_non_finite })
}

/// A bounds-checked cursor over a ROS 1 message.
struct Ros1Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Ros1Reader<'a> {
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], ErrorKind> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.bytes.len()).ok_or_else(|| {
            ErrorKind::Truncated(format!("a ROS 1 PointCloud2 of {} bytes ends inside `{what}` ({n} bytes at offset {})", self.bytes.len(), self.at))
        })?;
        let out = &self.bytes[self.at..end];
        self.at = end;
        Ok(out)
    }

    fn u8(&mut self, what: &str) -> Result<u8, ErrorKind> {
        Ok(self.take(1, what)?[0])
    }

    fn u32(&mut self, what: &str) -> Result<u32, ErrorKind> {
        Ok(u32::from_le_bytes(self.take(4, what)?.try_into().unwrap()))
    }

    fn string(&mut self, what: &str) -> Result<String, ErrorKind> {
        let n = self.u32(what)? as usize;
        let b = self.take(n, what)?;
        String::from_utf8(b.to_vec()).map_err(|_| ErrorKind::Mismatch(format!("`{what}` is not UTF-8")))
    }
}

/// The finite points of a message's data, and how many were not.
fn points(l: &Layout, limits: &ReadLimits) -> Result<(Vec<[f32; 3]>, usize), ErrorKind> {
    let field = |name: &str| -> Result<(usize, u8), ErrorKind> {
        let f = l.fields.iter().find(|f| f.name == name).ok_or_else(|| {
            ErrorKind::Mismatch(format!("no `{name}` field (fields: {})", l.fields.iter().map(|f| f.name.as_str()).collect::<Vec<_>>().join(", ")))
        })?;
        let size = match f.datatype {
            FLOAT32 => 4,
            FLOAT64 => 8,
            other => return Err(ErrorKind::Mismatch(format!("field `{name}` has datatype {other}; x, y and z must be FLOAT32 (7) or FLOAT64 (8)"))),
        };
        if f.count != 1 {
            return Err(ErrorKind::Mismatch(format!("field `{name}` has count {}; x, y and z hold one value each", f.count)));
        }
        if f.offset as u64 + size as u64 > l.point_step as u64 {
            return Err(ErrorKind::Mismatch(format!("field `{name}` at offset {} ({size} bytes) runs past point_step {}", f.offset, l.point_step)));
        }
        Ok((f.offset as usize, f.datatype))
    };
    let xyz = [field("x")?, field("y")?, field("z")?];
    let n = l.height as u64 * l.width as u64;
    limits.check_points(usize::try_from(n).unwrap_or(usize::MAX))?;
    if l.height > 0 && (l.row_step as u64) < l.width as u64 * l.point_step as u64 {
        return Err(ErrorKind::Mismatch(format!("row_step {} is less than width {} × point_step {}", l.row_step, l.width, l.point_step)));
    }
    let need = if l.height == 0 || l.width == 0 { 0 } else { (l.height as u64 - 1) * l.row_step as u64 + l.width as u64 * l.point_step as u64 };
    if (l.data.len() as u64) < need {
        return Err(ErrorKind::Truncated(format!("{} data bytes for {} × {} points of {} bytes (rows {} apart): {need} needed", l.data.len(), l.height, l.width, l.point_step, l.row_step)));
    }
    let read = |at: usize, ty: u8| -> f32 {
        if ty == FLOAT32 {
            let b: [u8; 4] = l.data[at..at + 4].try_into().unwrap();
            if l.is_bigendian { f32::from_be_bytes(b) } else { f32::from_le_bytes(b) }
        } else {
            let b: [u8; 8] = l.data[at..at + 8].try_into().unwrap();
            (if l.is_bigendian { f64::from_be_bytes(b) } else { f64::from_le_bytes(b) }) as f32
        }
    };
    let mut out = Vec::with_capacity(n as usize);
    let mut dropped = 0;
    for row in 0..l.height as usize {
        for col in 0..l.width as usize {
            let base = row * l.row_step as usize + col * l.point_step as usize;
            let p = xyz.map(|(off, ty)| read(base + off, ty));
            if p.iter().all(|v| v.is_finite()) {
                out.push(p);
            } else {
                dropped += 1;
            }
        }
    }
    Ok((out, dropped))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A CDR PointCloud2 written by hand, field by field, as ROS 2's serializer lays it out
    /// (little-endian encapsulation, each value aligned to its size from the payload's start).
    fn cdr_message(fields: &[(&str, u32, u8)], point_step: u32, height: u32, width: u32, big: bool, data: &[u8]) -> Vec<u8> {
        let mut b = vec![0u8, 1, 0, 0];
        let align = |b: &mut Vec<u8>, n: usize| {
            while (b.len() - 4) % n != 0 {
                b.push(0);
            }
        };
        let u32_ = |b: &mut Vec<u8>, v: u32| {
            align(b, 4);
            b.extend(v.to_le_bytes());
        };
        let string = |b: &mut Vec<u8>, s: &str| {
            u32_(b, s.len() as u32 + 1);
            b.extend(s.as_bytes());
            b.push(0);
        };
        u32_(&mut b, 12); // stamp.sec
        u32_(&mut b, 500_000_000); // stamp.nanosec
        string(&mut b, "velodyne");
        u32_(&mut b, height);
        u32_(&mut b, width);
        u32_(&mut b, fields.len() as u32);
        for &(name, offset, datatype) in fields {
            string(&mut b, name);
            u32_(&mut b, offset);
            b.push(datatype);
            u32_(&mut b, 1);
        }
        b.push(big as u8);
        u32_(&mut b, point_step);
        u32_(&mut b, point_step * width);
        u32_(&mut b, data.len() as u32);
        b.extend(data);
        b.push(1);
        b
    }

    #[test]
    fn any_layout_and_byte_order_decodes_to_the_same_points() {
        let pts = [[1.0f32, 2.0, 3.0], [-4.5, 0.25, f32::NAN], [7.0, -8.0, 9.5]];
        // x y z intensity ring as float32 (a Velodyne driver's layout), little-endian.
        let mut le = Vec::new();
        for p in pts {
            for v in p {
                le.extend(v.to_le_bytes());
            }
            le.extend(5.0f32.to_le_bytes());
            le.extend(3u16.to_le_bytes());
            le.extend([0, 0]);
        }
        let m = cdr_message(&[("x", 0, 7), ("y", 4, 7), ("z", 8, 7), ("intensity", 12, 7), ("ring", 16, 4)], 20, 1, 3, false, &le);
        let c = decode_cdr(&m, &ReadLimits::NONE).unwrap();
        assert_eq!(c.points, vec![pts[0], pts[2]]);
        assert_eq!((c.dropped_non_finite, c.frame_id.as_str(), c.stamp.seconds()), (1, "velodyne", 12.5));
        // z first, then x and y, as float64, big-endian, organised 1 × 3 rows.
        let mut be = Vec::new();
        for p in pts {
            for v in [p[2], p[0], p[1]] {
                be.extend((v as f64).to_be_bytes());
            }
        }
        let m = cdr_message(&[("z", 0, 8), ("x", 8, 8), ("y", 16, 8)], 24, 3, 1, true, &be);
        let c = decode_cdr(&m, &ReadLimits::NONE).unwrap();
        assert_eq!(c.points, vec![pts[0], pts[2]]);
        assert_eq!((c.height, c.width), (3, 1));
    }

    #[test]
    fn messages_rosbags_serialized_decode() {
        // fuzz/make_seeds.py writes these with rosbags' CDR serializer (points 0, 1, 2, … 47).
        let seeds = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz/seeds/pointcloud2");
        let want: Vec<[f32; 3]> = (0..16).map(|i| [3.0 * i as f32, 3.0 * i as f32 + 1.0, 3.0 * i as f32 + 2.0]).collect();
        for (file, dropped) in [("velodyne_16.cdr", 0), ("organised_4x4.cdr", 1), ("float64_be_16.cdr", 0)] {
            let c = decode_cdr(&std::fs::read(seeds.join(file)).unwrap(), &ReadLimits::NONE).unwrap();
            let expect: Vec<[f32; 3]> = want.iter().enumerate().filter(|&(i, _)| dropped == 0 || i != 5).map(|(_, p)| *p).collect();
            assert_eq!((c.points, c.dropped_non_finite, c.frame_id.as_str(), c.stamp), (expect, dropped, "lidar", Stamp { sec: 1, nanosec: 2 }), "{file}");
        }
    }

    #[test]
    fn ros1_messages_rosbags_serialized_decode() {
        // The same three clouds in ROS 1's serialization (rosbags' `serialize_ros1`).
        let seeds = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz/seeds/pointcloud2_ros1");
        let want: Vec<[f32; 3]> = (0..16).map(|i| [3.0 * i as f32, 3.0 * i as f32 + 1.0, 3.0 * i as f32 + 2.0]).collect();
        for (file, dropped) in [("velodyne_16.ros1", 0), ("organised_4x4.ros1", 1), ("float64_be_16.ros1", 0)] {
            let bytes = std::fs::read(seeds.join(file)).unwrap();
            let c = decode_ros1(&bytes, &ReadLimits::NONE).unwrap();
            let expect: Vec<[f32; 3]> = want.iter().enumerate().filter(|&(i, _)| dropped == 0 || i != 5).map(|(_, p)| *p).collect();
            assert_eq!((c.points, c.dropped_non_finite, c.frame_id.as_str(), c.stamp), (expect, dropped, "lidar", Stamp { sec: 1, nanosec: 2 }), "{file}");
            // Cut anywhere: an error saying where, never a panic.
            for cut in [0, 3, 17, bytes.len() / 2, bytes.len() - 2] {
                let e = decode_ros1(&bytes[..cut], &ReadLimits::NONE).unwrap_err().to_string();
                assert!(e.contains("ends inside") || e.contains("needed") || e.contains("fields cannot fit"), "{file} cut at {cut}: {e}");
            }
        }
    }

    #[test]
    fn bad_messages_say_what_is_wrong() {
        let data = vec![0u8; 36];
        let bad = |m: Vec<u8>| decode_cdr(&m, &ReadLimits::NONE).unwrap_err().to_string();
        assert!(bad(cdr_message(&[("x", 0, 7), ("y", 4, 7)], 12, 1, 3, false, &data)).contains("no `z` field"));
        assert!(bad(cdr_message(&[("x", 0, 7), ("y", 4, 7), ("z", 8, 2)], 12, 1, 3, false, &data)).contains("datatype 2"));
        assert!(bad(cdr_message(&[("x", 0, 7), ("y", 4, 7), ("z", 10, 7)], 12, 1, 3, false, &data)).contains("runs past point_step"));
        assert!(bad(cdr_message(&[("x", 0, 7), ("y", 4, 7), ("z", 8, 7)], 12, 1, 4, false, &data)).contains("48 needed"));
        let mut cut = cdr_message(&[("x", 0, 7), ("y", 4, 7), ("z", 8, 7)], 12, 1, 3, false, &data);
        cut.truncate(cut.len() - 20);
        assert!(bad(cut).contains("not a CDR"));
        let limits = ReadLimits { max_points: 2, max_data_bytes: usize::MAX };
        let e = decode_cdr(&cdr_message(&[("x", 0, 7), ("y", 4, 7), ("z", 8, 7)], 12, 1, 3, false, &data), &limits).unwrap_err().to_string();
        assert!(e.contains("3 points, more than the 2"), "{e}");
    }
}
