//! Person-MinkUNet's box encoding (spec §1.8): centre offsets from the voxel centre, log-dimensions
//! against a mean size, and bin-based rotation with residuals for every bin.
//!
//! Head channel layout (`2·bins + 7` channels): `[0]` cls logit, `[1..4]` centre offset (m),
//! `[4..7]` `log(l/l̄), log(w/w̄), log(h/h̄)`, `[7..7+bins]` bin logits, `[7+bins..7+2·bins]` bin
//! residuals (radians, not normalised).

use std::f64::consts::{PI, TAU};

use data_jrdb::Box3d;

/// Channel of the classification logit.
pub const CLS: usize = 0;
/// First channel of the centre offset (3 channels).
pub const OFFSET: usize = 1;
/// First channel of the log-dimensions (3 channels).
pub const LOG_DIMS: usize = 4;
/// First channel of the bin logits (`bins` channels; the residuals follow them).
pub const BINS: usize = 7;

/// Wraps an angle into (−π, π].
pub fn wrap_angle(a: f64) -> f64 {
    let r = (a + PI).rem_euclid(TAU) - PI;
    if r <= -PI { r + TAU } else { r }
}

/// A box encoded against one voxel centre: the regression targets of spec §1.9.
#[derive(Debug, Clone, PartialEq)]
pub struct EncodedBox {
    /// Box centre − voxel centre, metres.
    pub offset: [f64; 3],
    /// `log(dim / mean)` for l, w, h.
    pub log_dims: [f64; 3],
    /// The heading's bin, `floor((θ mod 2π) / bin)`.
    pub bin: usize,
    /// `wrap(θ − (j + ½)·bin)` for every bin j.
    pub residuals: Vec<f64>,
}

/// Encodes and decodes boxes; `decode(encode(b)) = b` with the heading wrapped into (−π, π].
#[derive(Debug, Clone, PartialEq)]
pub struct BoxCoder {
    /// Mean (l, w, h), metres.
    pub mean_size: [f64; 3],
    /// Number of rotation bins.
    pub num_bins: usize,
}

impl BoxCoder {
    /// A coder for `num_bins` bins and the given mean size.
    pub fn new(mean_size: [f64; 3], num_bins: usize) -> Self {
        assert!(num_bins > 0, "at least one rotation bin");
        assert!(mean_size.iter().all(|&m| m > 0.0), "mean size must be positive, got {mean_size:?}");
        Self { mean_size, num_bins }
    }

    /// Head channels: cls + offset + log-dims + bin logits + residuals = `2·bins + 7`.
    pub fn channels(&self) -> usize {
        2 * self.num_bins + 7
    }

    /// Width of one rotation bin, radians.
    pub fn bin_width(&self) -> f64 {
        TAU / self.num_bins as f64
    }

    /// Centre of bin `j`, radians in [0, 2π).
    pub fn bin_centre(&self, j: usize) -> f64 {
        (j as f64 + 0.5) * self.bin_width()
    }

    /// The bin of a heading.
    pub fn bin_of(&self, theta: f64) -> usize {
        ((theta.rem_euclid(TAU) / self.bin_width()).floor() as usize).min(self.num_bins - 1)
    }

    /// Encodes `b` against the voxel centre `v`.
    pub fn encode(&self, b: &Box3d, v: [f64; 3]) -> EncodedBox {
        let dims = [b.l, b.w, b.h];
        EncodedBox {
            offset: [b.cx - v[0], b.cy - v[1], b.cz - v[2]],
            log_dims: [0, 1, 2].map(|k| (dims[k] / self.mean_size[k]).ln()),
            bin: self.bin_of(b.rot_z),
            residuals: (0..self.num_bins).map(|j| wrap_angle(b.rot_z - self.bin_centre(j))).collect(),
        }
    }

    /// Heading from a bin and its residual: `(k + ½)·bin + r`, minus 2π when above π.
    pub fn decode_heading(&self, bin: usize, residual: f64) -> f64 {
        let theta = self.bin_centre(bin) + residual;
        if theta > PI { theta - TAU } else { theta }
    }

    /// Decodes an encoding back into a box.
    pub fn decode(&self, e: &EncodedBox, v: [f64; 3]) -> Box3d {
        self.decode_parts(v, e.offset, e.log_dims, e.bin, e.residuals[e.bin])
    }

    /// Decodes one voxel's head output (`channels()` values): the arg-max bin and its residual.
    pub fn decode_row(&self, row: &[f32], v: [f64; 3]) -> Box3d {
        let bins = &row[BINS..BINS + self.num_bins];
        let k = (0..self.num_bins).fold(0, |best, j| if bins[j] > bins[best] { j } else { best });
        let f = |i: usize| row[i] as f64;
        let offset = [f(OFFSET), f(OFFSET + 1), f(OFFSET + 2)];
        let log_dims = [f(LOG_DIMS), f(LOG_DIMS + 1), f(LOG_DIMS + 2)];
        self.decode_parts(v, offset, log_dims, k, f(BINS + self.num_bins + k))
    }

    fn decode_parts(&self, v: [f64; 3], offset: [f64; 3], log_dims: [f64; 3], bin: usize, residual: f64) -> Box3d {
        let [l, w, h] = [0, 1, 2].map(|k| self.mean_size[k] * log_dims[k].exp());
        Box3d { cx: v[0] + offset[0], cy: v[1] + offset[1], cz: v[2] + offset[2], l, w, h, rot_z: self.decode_heading(bin, residual) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn encode_decode_round_trip_is_exact() {
        let coder = BoxCoder::new([0.9, 0.5, 1.7], 12);
        assert_eq!(coder.channels(), 31);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let mut headings: Vec<f64> = (0..500).map(|_| rng.random_range(-10.0..10.0)).collect();
        // Bin edges, ±π and 0 are where an off-by-one would show.
        headings.extend((0..=24).map(|j| j as f64 * PI / 12.0 - PI));
        for theta in headings {
            let b = Box3d { cx: rng.random_range(-20.0..20.0), cy: rng.random_range(-20.0..20.0), cz: rng.random_range(-1.0..1.0),
                l: rng.random_range(0.3..1.5), w: rng.random_range(0.2..1.0), h: rng.random_range(1.0..2.0), rot_z: theta };
            let v = [b.cx + rng.random_range(-0.5..0.5), b.cy - 0.2, b.cz + 0.1];
            let e = coder.encode(&b, v);
            assert!(e.residuals[e.bin].abs() <= coder.bin_width() / 2.0 + 1e-12, "{e:?}");
            assert!(e.residuals.iter().all(|r| r.abs() <= PI));
            let d = coder.decode(&e, v);
            for (a, b) in [(d.cx, b.cx), (d.cy, b.cy), (d.cz, b.cz), (d.l, b.l), (d.w, b.w), (d.h, b.h)] {
                assert!((a - b).abs() < 1e-12, "{d:?} vs {b:?}");
            }
            assert!(d.rot_z > -PI && d.rot_z <= PI);
            assert!((d.rot_z - wrap_angle(theta)).abs() < 1e-9, "θ {theta}: {} vs {}", d.rot_z, wrap_angle(theta));
            // Through the head layout: a row whose arg-max bin is the encoded one decodes the same box.
            let mut row = vec![0f32; coder.channels()];
            row[OFFSET..OFFSET + 3].copy_from_slice(&e.offset.map(|x| x as f32));
            row[LOG_DIMS..LOG_DIMS + 3].copy_from_slice(&e.log_dims.map(|x| x as f32));
            row[BINS + e.bin] = 5.0;
            for (j, r) in e.residuals.iter().enumerate() {
                row[BINS + 12 + j] = *r as f32;
            }
            let r = coder.decode_row(&row, v);
            assert!((r.cx - b.cx).abs() < 1e-5 && (r.l - b.l).abs() < 1e-5);
            assert!(wrap_angle(r.rot_z - theta).abs() < 1e-5);
        }
    }

    #[test]
    fn residuals_follow_spec_example() {
        let coder = BoxCoder::new([0.9, 0.5, 1.7], 12);
        let bin = PI / 6.0;
        let e = coder.encode(&Box3d { cx: 0.0, cy: 0.0, cz: 0.0, l: 0.9, w: 0.5, h: 1.7, rot_z: -0.1 }, [0.0; 3]);
        assert_eq!(e.bin, 11); // −0.1 mod 2π lies in the last bin
        assert!((e.residuals[11] - (TAU - 0.1 - 11.5 * bin)).abs() < 1e-12);
        assert!((e.residuals[0] - (-0.1 - 0.5 * bin)).abs() < 1e-12);
        assert_eq!(e.log_dims, [0.0, 0.0, 0.0]);
    }
}
