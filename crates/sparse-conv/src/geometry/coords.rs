//! Batch-indexed integer voxel coordinates and their hash index.

use std::fmt;

/// One voxel: `[batch, x, y, z]`, in finest-level voxel units.
pub type Coord = [i32; 4];

/// Bits of each spatial axis in a packed key (signed range ±131,072 voxels: ±6.5 km at 5 cm).
const AXIS_BITS: u32 = 18;
/// Bits of the batch index in a packed key (1,024 samples per batch).
const BATCH_BITS: u32 = 64 - 3 * AXIS_BITS;
const AXIS_MIN: i64 = -(1 << (AXIS_BITS - 1));
const AXIS_MAX: i64 = (1 << (AXIS_BITS - 1)) - 1;
const BATCH_MAX: i64 = (1 << BATCH_BITS) - 1;

/// Why a coordinate set cannot be indexed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum CoordError {
    /// A coordinate lies outside the range a packed key can hold.
    OutOfRange {
        /// The row of the coordinate.
        row: usize,
        /// The coordinate.
        coord: Coord,
    },
    /// The same voxel appears twice: a sparse tensor holds each voxel once.
    Duplicate {
        /// The row of its first occurrence.
        first: usize,
        /// The row of the repeat.
        second: usize,
        /// The voxel.
        coord: Coord,
    },
    /// Features and coordinates disagree on the number of voxels.
    FeatureRows {
        /// Feature rows.
        features: usize,
        /// Coordinates.
        coords: usize,
    },
    /// A coordinate of a level of tensor stride `stride` is not a multiple of it.
    OffGrid {
        /// The row of the coordinate.
        row: usize,
        /// The coordinate.
        coord: Coord,
        /// The level's tensor stride.
        stride: i32,
    },
}

impl fmt::Display for CoordError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CoordError::OutOfRange { row, coord } => write!(
                f,
                "voxel coordinate {coord:?} at row {row} is out of range (batch 0..={BATCH_MAX}, x/y/z {AXIS_MIN}..={AXIS_MAX})"
            ),
            CoordError::Duplicate { first, second, coord } => {
                write!(f, "voxel {coord:?} appears twice (rows {first} and {second})")
            }
            CoordError::FeatureRows { features, coords } => {
                write!(f, "{features} feature rows for {coords} voxel coordinates")
            }
            CoordError::OffGrid { row, coord, stride } => {
                write!(f, "voxel coordinate {coord:?} at row {row} is not a multiple of the tensor stride {stride}")
            }
        }
    }
}

impl std::error::Error for CoordError {}

/// Packs a coordinate into one 64-bit key, or `None` when it is out of the key's range.
///
/// Negative spatial coordinates are allowed; the batch index is part of the key, so samples of
/// one batch never meet in a lookup.
#[inline]
pub fn pack(c: Coord) -> Option<u64> {
    let [b, x, y, z] = c.map(i64::from);
    if !(0..=BATCH_MAX).contains(&b) {
        return None;
    }
    let mut key = b as u64;
    for v in [x, y, z] {
        if !(AXIS_MIN..=AXIS_MAX).contains(&v) {
            return None;
        }
        key = (key << AXIS_BITS) | ((v - AXIS_MIN) as u64);
    }
    Some(key)
}

const EMPTY: u64 = u64::MAX;

/// Open-addressing hash from packed coordinate to row.
///
/// Linear probing over a power-of-two table at most half full; the multiplicative hash spreads
/// the structured keys of a voxel grid well enough that probes stay short.
#[derive(Clone)]
pub struct CoordIndex {
    keys: Vec<u64>,
    rows: Vec<u32>,
    mask: usize,
    /// `64 − log2(slots)`: a slot is the top bits of the key's multiplicative hash.
    shift: u32,
}

impl CoordIndex {
    /// Indexes `coords`, row `i` for `coords[i]`.
    pub fn build(coords: &[Coord]) -> Result<Self, CoordError> {
        let mut index = Self::with_capacity(coords.len());
        for (row, &c) in coords.iter().enumerate() {
            let key = pack(c).ok_or(CoordError::OutOfRange { row, coord: c })?;
            if let Err(first) = index.insert(key, row as u32) {
                return Err(CoordError::Duplicate { first: first as usize, second: row, coord: c });
            }
        }
        Ok(index)
    }

    /// An empty index sized for `n` keys.
    pub fn with_capacity(n: usize) -> Self {
        let cap = (2 * n.max(8)).next_power_of_two();
        Self { keys: vec![EMPTY; cap], rows: vec![0; cap], mask: cap - 1, shift: 64 - cap.trailing_zeros() }
    }

    #[inline]
    fn slot(&self, key: u64) -> usize {
        // The top bits (Fibonacci hashing): keys of neighbouring voxels differ in their low bits,
        // and middle bits of the product left them in clusters that lengthened the probes.
        (key.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> self.shift) as usize
    }

    /// Inserts `key → row`; if the key is present, leaves it and returns its row as the error.
    pub fn insert(&mut self, key: u64, row: u32) -> Result<(), u32> {
        let mut s = self.slot(key);
        loop {
            let k = self.keys[s];
            if k == EMPTY {
                self.keys[s] = key;
                self.rows[s] = row;
                return Ok(());
            }
            if k == key {
                return Err(self.rows[s]);
            }
            s = (s + 1) & self.mask;
        }
    }

    /// The row of a packed key.
    #[inline]
    pub fn get_key(&self, key: u64) -> Option<u32> {
        let mut s = self.slot(key);
        loop {
            let k = self.keys[s];
            if k == key {
                return Some(self.rows[s]);
            }
            if k == EMPTY {
                return None;
            }
            s = (s + 1) & self.mask;
        }
    }

    /// Starts loading `key`'s slot into the cache: a caller with many keys to look up prefetches
    /// them all first, so their cache misses overlap instead of following one another.
    #[inline]
    pub fn prefetch_key(&self, key: u64) {
        let s = self.slot(key);
        #[cfg(target_arch = "x86_64")]
        // SAFETY: a prefetch has no effect on memory; the addresses are inside the slots.
        unsafe {
            use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
            _mm_prefetch::<_MM_HINT_T0>(self.keys.as_ptr().wrapping_add(s).cast());
            _mm_prefetch::<_MM_HINT_T0>(self.rows.as_ptr().wrapping_add(s).cast());
        }
        #[cfg(not(target_arch = "x86_64"))]
        let _ = s;
    }

    /// The row of a coordinate.
    #[inline]
    pub fn get(&self, c: Coord) -> Option<u32> {
        pack(c).and_then(|k| self.get_key(k))
    }
}

impl fmt::Debug for CoordIndex {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("CoordIndex").field("capacity", &self.keys.len()).finish()
    }
}

/// Checks that `coords` are valid for a sparse tensor: in range and without duplicates.
pub fn validate(coords: &[Coord]) -> Result<(), CoordError> {
    CoordIndex::build(coords).map(|_| ())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn negative_and_batched_coordinates_are_distinct_keys() {
        let coords = vec![[0, -1, -2, -3], [1, -1, -2, -3], [0, 1, 2, 3], [0, AXIS_MAX as i32, 0, AXIS_MIN as i32]];
        let index = CoordIndex::build(&coords).unwrap();
        for (row, &c) in coords.iter().enumerate() {
            assert_eq!(index.get(c), Some(row as u32));
        }
        assert_eq!(index.get([2, -1, -2, -3]), None);
        assert_eq!(index.get([0, 0, 0, 0]), None);
    }

    #[test]
    fn out_of_range_and_duplicates_are_errors() {
        let err = CoordIndex::build(&[[0, 0, 0, 0], [0, 1 << 20, 0, 0]]).err().unwrap();
        assert!(matches!(err, CoordError::OutOfRange { row: 1, .. }));
        let err = CoordIndex::build(&[[0, 0, 0, 0], [-1, 0, 0, 0]]).err().unwrap();
        assert!(matches!(err, CoordError::OutOfRange { row: 1, .. }));
        let err = CoordIndex::build(&[[0, 5, 0, 0], [0, 1, 0, 0], [0, 5, 0, 0]]).err().unwrap();
        assert_eq!(err, CoordError::Duplicate { first: 0, second: 2, coord: [0, 5, 0, 0] });
    }
}
