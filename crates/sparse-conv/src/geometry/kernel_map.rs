//! Kernel maps (rulebooks): which input row feeds which output row through which kernel offset.

use std::fmt;
use std::any::Any;
use std::sync::{Arc, OnceLock};

use rayon::prelude::*;

use crate::geometry::attachments::Attachments;
use crate::geometry::coords::{Coord, CoordError, CoordIndex, pack};
use crate::geometry::level::LevelCoords;
use crate::parallel::SyncPtr;

/// Marks "no row" in a [`NeighborTable`].
pub const NONE: u32 = u32::MAX;

/// For each row of one side of a map, the row of the other side at each kernel offset.
///
/// Row-major `rows × volume`; `NONE` where nothing is there. Every map kind of the network has at
/// most one partner per (row, offset), so one table per direction describes a map completely.
pub struct NeighborTable {
    rows: usize,
    volume: usize,
    data: Vec<u32>,
}

impl NeighborTable {
    fn empty(rows: usize, volume: usize) -> Self {
        Self { rows, volume, data: vec![NONE; rows * volume] }
    }

    /// Rows of this side.
    pub fn rows(&self) -> usize {
        self.rows
    }

    /// Kernel volume (offsets per row).
    pub fn volume(&self) -> usize {
        self.volume
    }

    /// The partners of `row`, one per offset.
    #[inline]
    pub fn row(&self, row: usize) -> &[u32] {
        &self.data[row * self.volume..(row + 1) * self.volume]
    }

    /// The whole table, row-major.
    pub fn as_slice(&self) -> &[u32] {
        &self.data
    }
}

/// The (input, output) pairs of a map grouped by offset: the layout of the weight gradient.
pub struct OffsetPairs {
    /// `start[k]..start[k + 1]` indexes the pairs of offset `k`.
    pub start: Vec<usize>,
    /// The input row of each pair.
    pub input: Vec<u32>,
    /// The output row of each pair.
    pub output: Vec<u32>,
}

/// What a map computes, which also keys the cache of a [`crate::SparseTensor`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum MapKind {
    /// Odd kernel `k`, output coordinates = input coordinates.
    Submanifold {
        /// Kernel size (odd).
        kernel: usize,
    },
    /// Kernel = stride = `kernel`: outputs at `floor(c / (kernel·s))·(kernel·s)`.
    Down {
        /// Kernel size and stride.
        kernel: usize,
    },
    /// The transposed `Down` map: outputs land on the finer level's coordinates.
    Up {
        /// Kernel size and stride of the `Down` map it reverses.
        kernel: usize,
    },
}

/// A rulebook between an input and an output coordinate set.
///
/// `out_table` drives the forward (output-stationary gather), `in_table` the feature gradient
/// (the same gather over the transposed map); transposing a map swaps them at no cost.
pub struct KernelMap {
    kind: MapKind,
    n_in: usize,
    n_out: usize,
    volume: usize,
    /// Built with the map, except for a deferred map: on first host use.
    out_table: OnceLock<Arc<NeighborTable>>,
    /// What a deferred map's tables are made from (on a device, or on the host if it asks).
    deferred: Option<Deferred>,
    /// Built with the map for down maps (a deferred one's with `out_table`, on first host use);
    /// for submanifold maps it is the mirror of `out_table`, made only if something asks (the
    /// kernels run on `pairs`).
    in_table: OnceLock<Arc<NeighborTable>>,
    pairs: OnceLock<OffsetPairs>,
    pairs_by_input: OnceLock<OffsetPairs>,
    /// What a backend derives from the map and keeps with it (e.g. the tables uploaded to a GPU).
    attachments: Attachments,
}

/// Where a deferred map's tables come from (a GPU backend makes the down-sampling ones).
#[cfg_attr(not(feature = "cube"), allow(dead_code))]
pub(crate) enum Deferred {
    /// The submanifold map over a level at a tensor stride: built from its coordinates.
    Submanifold { level: Arc<LevelCoords>, stride: i32 },
    /// A down-sampling map from a level at a tensor stride, built on a device with the coarse
    /// level (its device tables attached to it).
    Down { fine: Arc<LevelCoords>, stride: i32 },
    /// The transposed map of a deferred down-sampling map: its tables swapped.
    Up { down: Arc<KernelMap> },
}

impl fmt::Debug for KernelMap {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        // A deferred map's tables are not built for a debug print.
        let pairs = self.out_table.get().map(|t| t.data.iter().filter(|&&i| i != NONE).count());
        f.debug_struct("KernelMap")
            .field("kind", &self.kind)
            .field("n_in", &self.n_in)
            .field("n_out", &self.n_out)
            .field("pairs", &pairs)
            .finish()
    }
}

impl KernelMap {
    /// What this map computes.
    pub fn kind(&self) -> MapKind {
        self.kind
    }

    /// Rows of the input coordinate set.
    pub fn n_in(&self) -> usize {
        self.n_in
    }

    /// Rows of the output coordinate set.
    pub fn n_out(&self) -> usize {
        self.n_out
    }

    /// Number of kernel offsets (the weight's first dimension).
    pub fn volume(&self) -> usize {
        self.volume
    }

    /// For each output row, its input row at each offset.
    pub fn out_table(&self) -> &NeighborTable {
        self.out_table_arc()
    }

    fn out_table_arc(&self) -> &Arc<NeighborTable> {
        self.out_table.get_or_init(|| {
            let (out_table, in_table) = self.host_tables();
            if let Some(in_table) = in_table {
                let _ = self.in_table.set(in_table);
            }
            out_table
        })
    }

    /// A deferred map's tables built on the host: the output side's, and the input side's where it
    /// is not the mirror of the output side's.
    fn host_tables(&self) -> (Arc<NeighborTable>, Option<Arc<NeighborTable>>) {
        let built = "coordinates of a sparse tensor are validated and on their level's grid";
        match (self.deferred.as_ref().expect("a map that is not deferred has its tables"), self.kind) {
            (Deferred::Submanifold { level, stride }, MapKind::Submanifold { kernel }) => {
                let coords = level.host();
                let index = CoordIndex::build(coords).expect(built);
                (KernelMap::submanifold(coords, &index, kernel, *stride).out_table_arc().clone(), None)
            }
            (Deferred::Down { fine, stride }, MapKind::Down { kernel }) => {
                let (map, _) = KernelMap::down(fine.host(), kernel, *stride).expect(built);
                (map.out_table_arc().clone(), Some(map.in_table_arc().clone()))
            }
            (Deferred::Up { down }, _) => (down.in_table_arc().clone(), Some(down.out_table_arc().clone())),
            (_, kind) => unreachable!("a deferred map of kind {kind:?} from another kind's source"),
        }
    }

    /// What a deferred map's tables are made from, for a GPU backend to build its own.
    #[cfg_attr(not(feature = "cube"), allow(dead_code))]
    pub(crate) fn deferred(&self) -> Option<&Deferred> {
        self.deferred.as_ref()
    }

    /// Whether the host tables exist (always, except for a deferred map nothing on the host has
    /// read yet).
    pub fn has_host_tables(&self) -> bool {
        self.out_table.get().is_some()
    }

    /// For each input row, its output row at each offset.
    pub fn in_table(&self) -> &NeighborTable {
        self.in_table_arc()
    }

    fn in_table_arc(&self) -> &Arc<NeighborTable> {
        // A deferred down or up map's input side is set with its output side.
        let out_table = self.out_table_arc();
        self.in_table.get_or_init(|| Arc::new(mirror(out_table)))
    }

    /// The offset whose pairs are `(r, r)` for every row (the submanifold centre), if any.
    pub fn identity_offset(&self) -> Option<usize> {
        matches!(self.kind, MapKind::Submanifold { .. }).then_some(self.volume() / 2)
    }

    /// Number of (input, output) pairs over all offsets.
    pub fn num_pairs(&self) -> usize {
        self.out_table_arc().data.iter().filter(|&&i| i != NONE).count()
    }

    /// The pairs grouped by offset, ordered by output row within an offset (the forward's
    /// destination order); built on first use.
    pub fn pairs(&self) -> &OffsetPairs {
        self.pairs.get_or_init(|| grouped_by_offset(self.out_table_arc()))
    }

    /// The same pairs ordered by input row within an offset (the feature gradient's destination
    /// order, which lets its kernel run by destination blocks); built on first use.
    pub fn pairs_by_input(&self) -> &OffsetPairs {
        self.pairs_by_input.get_or_init(|| match self.kind {
            // (i, o) at offset k is (o, i) at the negated offset `volume − 1 − k`: those
            // pairs, already ordered by their output, with the sides swapped.
            MapKind::Submanifold { .. } => {
                let by_output = self.pairs();
                let volume = self.volume();
                let mut pairs = OffsetPairs { start: vec![0], input: Vec::with_capacity(by_output.input.len()), output: Vec::with_capacity(by_output.input.len()) };
                for k in 0..volume {
                    let mirrored = by_output.start[volume - 1 - k]..by_output.start[volume - k];
                    pairs.input.extend_from_slice(&by_output.output[mirrored.clone()]);
                    pairs.output.extend_from_slice(&by_output.input[mirrored]);
                    pairs.start.push(pairs.input.len());
                }
                pairs
            }
            // The input table's rows are inputs, its entries outputs.
            _ => {
                let OffsetPairs { start, input, output } = grouped_by_offset(self.in_table_arc());
                OffsetPairs { start, input: output, output: input }
            }
        })
    }

    /// The first attachment of type `T` that `matches`, made with `make` and kept if there is none.
    ///
    /// Backends keep derived forms of the map here (device copies of its tables) so that every
    /// layer sharing the map shares them too.
    pub fn attachment<T: Any + Send + Sync>(&self, matches: impl Fn(&T) -> bool, make: impl FnOnce() -> T) -> Arc<T> {
        self.attachments.get_or_make(matches, make)
    }

    /// The transposed map of a shared `map`: a deferred down-sampling map's stays deferred (a GPU
    /// reuses its device tables, swapped); any other is [`KernelMap::transposed`].
    pub fn transpose_of(map: &Arc<KernelMap>) -> KernelMap {
        match (&map.deferred, map.kind) {
            (Some(Deferred::Down { .. }), MapKind::Down { kernel }) => KernelMap {
                kind: MapKind::Up { kernel },
                n_in: map.n_out,
                n_out: map.n_in,
                volume: map.volume,
                out_table: OnceLock::new(),
                deferred: Some(Deferred::Up { down: map.clone() }),
                in_table: OnceLock::new(),
                pairs: OnceLock::new(),
                pairs_by_input: OnceLock::new(),
                attachments: Attachments::default(),
            },
            _ => map.transposed(),
        }
    }

    /// The same rulebook read backwards: inputs become outputs, offsets keep their index.
    pub fn transposed(&self) -> KernelMap {
        let kind = match self.kind {
            MapKind::Down { kernel } => MapKind::Up { kernel },
            MapKind::Up { kernel } => MapKind::Down { kernel },
            k @ MapKind::Submanifold { .. } => k,
        };
        KernelMap {
            kind,
            n_in: self.n_out,
            n_out: self.n_in,
            volume: self.volume,
            out_table: OnceLock::from(self.in_table_arc().clone()),
            deferred: None,
            in_table: OnceLock::from(self.out_table_arc().clone()),
            pairs: OnceLock::new(),
            pairs_by_input: OnceLock::new(),
            attachments: Attachments::default(),
        }
    }

    /// Submanifold map of an odd `kernel` over `coords` at tensor stride `stride`.
    ///
    /// Offset `k` is `(dx, dy, dz)·stride` with each of dx, dy, dz in `-r..=r` (r = kernel / 2),
    /// enumerated x-major; the centre is `k = volume / 2` and offset `volume - 1 - k` is the
    /// negation of offset `k`, which lets the build look up half of the neighbours.
    pub fn submanifold(coords: &[Coord], index: &CoordIndex, kernel: usize, stride: i32) -> KernelMap {
        assert!(kernel % 2 == 1, "submanifold kernel size must be odd, got {kernel}");
        let offsets = offsets(kernel, -(kernel as i32 / 2), stride);
        let volume = offsets.len();
        let centre = volume / 2;
        let n = coords.len();
        let mut table = NeighborTable::empty(n, volume);
        table.data.par_chunks_mut(volume).zip(coords.par_iter()).enumerate().for_each(
            |(o, (row, c))| {
                // A group of neighbours' keys first, their slots prefetched, then the probes: the
                // probes' cache misses overlap (the table is larger than L2).
                for (group, ds) in offsets[..centre].chunks(PROBE_GROUP).enumerate() {
                    let mut keys = [None; PROBE_GROUP];
                    for (key, d) in keys.iter_mut().zip(ds) {
                        *key = neighbour_key(*c, *d);
                        if let Some(key) = *key {
                            index.prefetch_key(key);
                        }
                    }
                    for (j, key) in keys[..ds.len()].iter().enumerate() {
                        if let Some(i) = key.and_then(|key| index.get_key(key)) {
                            row[group * PROBE_GROUP + j] = i;
                        }
                    }
                }
                row[centre] = o as u32;
            },
        );
        // Mirror: if o sees i at offset k, then i sees o at the negated offset. In parallel: the
        // first halves are only read, and each slot (i, volume − 1 − k) of a second half is
        // written by the one o that i's neighbour at that offset is.
        let data = SyncPtr(table.data.as_mut_ptr());
        let data = &data;
        (0..n).into_par_iter().for_each(|o| {
            for k in 0..centre {
                // SAFETY: in bounds (o < n, k < volume, i < n); slot (o, k < centre) is not
                // written in this loop, slot (i, volume − 1 − k) by this o only (see above).
                unsafe {
                    let i = data.0.wrapping_add(o * volume + k).read();
                    if i != NONE {
                        data.0.wrapping_add(i as usize * volume + (volume - 1 - k)).write(o as u32);
                    }
                }
            }
        });
        KernelMap {
            kind: MapKind::Submanifold { kernel },
            n_in: n,
            n_out: n,
            volume,
            out_table: OnceLock::from(Arc::new(table)),
            deferred: None,
            in_table: OnceLock::new(),
            pairs: OnceLock::new(),
            pairs_by_input: OnceLock::new(),
            attachments: Attachments::default(),
        }
    }

    /// The submanifold map of [`KernelMap::submanifold`] without its tables: a GPU backend builds
    /// them on the device from `coords` (`crate::geometry::device_maps`), the host only where
    /// something on the host reads them. What a GPU's forward pass makes of each level, so that
    /// the host never hashes or probes the level's voxels.
    pub fn submanifold_deferred(level: Arc<LevelCoords>, kernel: usize, stride: i32) -> KernelMap {
        assert!(kernel % 2 == 1, "submanifold kernel size must be odd, got {kernel}");
        let n = level.len();
        KernelMap {
            kind: MapKind::Submanifold { kernel },
            n_in: n,
            n_out: n,
            volume: kernel.pow(3),
            out_table: OnceLock::new(),
            deferred: Some(Deferred::Submanifold { level, stride }),
            in_table: OnceLock::new(),
            pairs: OnceLock::new(),
            pairs_by_input: OnceLock::new(),
            attachments: Attachments::default(),
        }
    }

    /// The down-sampling map of [`KernelMap::down`] from `fine` (tensor stride `stride`) to a level
    /// of `n_out` voxels, whose tables a GPU backend built and keeps in `device_tables` (the host
    /// builds its own from `fine` only where something on the host reads them).
    #[cfg_attr(not(feature = "cube"), allow(dead_code))]
    pub(crate) fn down_deferred<T: Any + Send + Sync>(fine: Arc<LevelCoords>, kernel: usize, stride: i32, n_out: usize, device_tables: Arc<T>) -> KernelMap {
        let attachments = Attachments::default();
        attachments.insert(device_tables);
        KernelMap {
            kind: MapKind::Down { kernel },
            n_in: fine.len(),
            n_out,
            volume: kernel.pow(3),
            out_table: OnceLock::new(),
            deferred: Some(Deferred::Down { fine, stride }),
            in_table: OnceLock::new(),
            pairs: OnceLock::new(),
            pairs_by_input: OnceLock::new(),
            attachments,
        }
    }

    /// Down-sampling map with kernel = stride = `kernel` from tensor stride `stride`.
    ///
    /// Returns the map and the output coordinates `floor(c / (kernel·stride))·(kernel·stride)`,
    /// in order of first appearance in `coords` (so the result does not depend on threads).
    pub fn down(coords: &[Coord], kernel: usize, stride: i32) -> Result<(KernelMap, Vec<Coord>), CoordError> {
        assert!(kernel >= 1, "down-sampling kernel must be at least 1");
        let out_stride = stride * kernel as i32;
        let volume = kernel * kernel * kernel;
        let mut index = CoordIndex::with_capacity(coords.len() / 2 + 1);
        let mut out_coords: Vec<Coord> = Vec::new();
        let mut in_table = NeighborTable::empty(coords.len(), volume);
        let mut parent_of = Vec::with_capacity(coords.len());
        for (i, &c) in coords.iter().enumerate() {
            let p = [c[0], c[1].div_euclid(out_stride) * out_stride, c[2].div_euclid(out_stride) * out_stride, c[3].div_euclid(out_stride) * out_stride];
            let rel = [c[1] - p[1], c[2] - p[2], c[3] - p[3]];
            if rel.iter().any(|r| r % stride != 0) {
                return Err(CoordError::OffGrid { row: i, coord: c, stride });
            }
            let k = ((rel[0] / stride) as usize * kernel + (rel[1] / stride) as usize) * kernel + (rel[2] / stride) as usize;
            let key = pack(p).ok_or(CoordError::OutOfRange { row: i, coord: c })?;
            let o = match index.insert(key, out_coords.len() as u32) {
                Ok(()) => {
                    out_coords.push(p);
                    out_coords.len() as u32 - 1
                }
                Err(existing) => existing,
            };
            in_table.data[i * volume + k] = o;
            parent_of.push((o, k));
        }
        let mut out_table = NeighborTable::empty(out_coords.len(), volume);
        for (i, &(o, k)) in parent_of.iter().enumerate() {
            let slot = &mut out_table.data[o as usize * volume + k];
            if *slot != NONE {
                return Err(CoordError::Duplicate { first: *slot as usize, second: i, coord: coords[i] });
            }
            *slot = i as u32;
        }
        let map = KernelMap {
            kind: MapKind::Down { kernel },
            n_in: coords.len(),
            n_out: out_coords.len(),
            volume,
            out_table: OnceLock::from(Arc::new(out_table)),
            deferred: None,
            in_table: OnceLock::from(Arc::new(in_table)),
            pairs: OnceLock::new(),
            pairs_by_input: OnceLock::new(),
            attachments: Attachments::default(),
        };
        Ok((map, out_coords))
    }
}

/// Kernel offsets `(dx, dy, dz)·stride`, each of dx, dy, dz in `lo..lo + kernel`, x-major.
pub(crate) fn offsets(kernel: usize, lo: i32, stride: i32) -> Vec<[i32; 3]> {
    let r = lo..lo + kernel as i32;
    let mut out = Vec::with_capacity(kernel.pow(3));
    for dx in r.clone() {
        for dy in r.clone() {
            for dz in r.clone() {
                out.push([dx * stride, dy * stride, dz * stride]);
            }
        }
    }
    out
}

/// Neighbour lookups whose slots are prefetched together.
const PROBE_GROUP: usize = 16;

/// The packed key of `c + d`, if it is in range.
fn neighbour_key(c: Coord, d: [i32; 3]) -> Option<u64> {
    pack([c[0], c[1].checked_add(d[0])?, c[2].checked_add(d[1])?, c[3].checked_add(d[2])?])
}

/// The in-side table of a submanifold map: input `i` feeds output `o` at offset `k` exactly when
/// `o`'s partner at `k` is `i`, i.e. `i`'s partner at the negated offset is `o`.
fn mirror(table: &NeighborTable) -> NeighborTable {
    let volume = table.volume;
    let mut out = NeighborTable::empty(table.rows, volume);
    out.data.par_chunks_mut(volume).zip(table.data.par_chunks(volume)).for_each(|(dst, src)| {
        for k in 0..volume {
            dst[k] = src[volume - 1 - k];
        }
    });
    out
}

/// Rows per parallel task of [`grouped_by_offset`].
const GROUP_ROWS: usize = 4096;

/// A table's entries as pairs grouped by offset, in table-row order within an offset: the
/// row as `output`, its entry as `input`. Two row-major passes (count, then fill), each over
/// chunks of rows in parallel: a chunk's entries of an offset go after the earlier chunks'.
fn grouped_by_offset(table: &NeighborTable) -> OffsetPairs {
    let volume = table.volume;
    let chunk_len = GROUP_ROWS * volume;
    let counts: Vec<Vec<usize>> = table
        .data
        .par_chunks(chunk_len.max(1))
        .map(|rows| {
            let mut count = vec![0usize; volume];
            for row in rows.chunks_exact(volume) {
                for (k, &i) in row.iter().enumerate() {
                    count[k] += (i != NONE) as usize;
                }
            }
            count
        })
        .collect();
    // Where each chunk's entries of each offset begin: offset by offset, chunk by chunk.
    let mut start = vec![0usize; volume + 1];
    let mut firsts = vec![vec![0usize; volume]; counts.len()];
    let mut next = 0;
    for k in 0..volume {
        start[k] = next;
        for (first, count) in firsts.iter_mut().zip(&counts) {
            first[k] = next;
            next += count[k];
        }
    }
    start[volume] = next;
    let (mut input, mut output) = (vec![0u32; next], vec![0u32; next]);
    let (input_ptr, output_ptr) = (SyncPtr(input.as_mut_ptr()), SyncPtr(output.as_mut_ptr()));
    let (input_ptr, output_ptr) = (&input_ptr, &output_ptr);
    table.data.par_chunks(chunk_len.max(1)).zip(firsts).enumerate().for_each(|(chunk, (rows, mut at))| {
        for (r, row) in rows.chunks_exact(volume).enumerate() {
            for (k, &i) in row.iter().enumerate() {
                if i != NONE {
                    // SAFETY: `at[k]` runs over this chunk's own range of offset k's entries
                    // (its counts, after the earlier chunks'), inside the arrays.
                    unsafe {
                        input_ptr.0.wrapping_add(at[k]).write(i);
                        output_ptr.0.wrapping_add(at[k]).write((chunk * GROUP_ROWS + r) as u32);
                    }
                    at[k] += 1;
                }
            }
        }
    });
    OffsetPairs { start, input, output }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_deferred_map_builds_the_same_tables_on_first_host_use() {
        let coords: Vec<Coord> = vec![[0, 0, 0, 0], [0, 2, 0, 0], [0, 2, 2, 2], [1, 0, 0, 2], [0, -2, -2, -2], [0, 10, 10, 10]];
        let eager = KernelMap::submanifold(&coords, &CoordIndex::build(&coords).unwrap(), 3, 2);
        let deferred = KernelMap::submanifold_deferred(Arc::new(LevelCoords::on_host(coords.clone().into())), 3, 2);
        assert_eq!((deferred.n_in(), deferred.n_out(), deferred.volume()), (6, 6, 27));
        assert!(!deferred.has_host_tables());
        assert_eq!(format!("{deferred:?}"), "KernelMap { kind: Submanifold { kernel: 3 }, n_in: 6, n_out: 6, pairs: None }");
        assert_eq!(deferred.out_table().as_slice(), eager.out_table().as_slice());
        assert!(deferred.has_host_tables());
        assert_eq!(deferred.in_table().as_slice(), eager.in_table().as_slice());
        assert_eq!(deferred.pairs().input, eager.pairs().input);
        assert_eq!(deferred.pairs_by_input().output, eager.pairs_by_input().output);
        assert_eq!(deferred.transposed().out_table().as_slice(), eager.in_table().as_slice());
    }

    #[test]
    fn submanifold_tables_are_consistent() {
        let coords = vec![[0, 0, 0, 0], [0, 1, 0, 0], [0, 1, 1, 1], [1, 0, 0, 1], [0, -1, -1, -1], [0, 5, 5, 5]];
        let index = CoordIndex::build(&coords).unwrap();
        let map = KernelMap::submanifold(&coords, &index, 3, 1);
        assert_eq!(map.volume(), 27);
        for o in 0..coords.len() {
            for k in 0..27 {
                let i = map.out_table().row(o)[k];
                if i != NONE {
                    assert_eq!(map.in_table().row(i as usize)[k], o as u32);
                }
            }
        }
        // [0,0,0,0] neighbours: itself, [0,1,0,0], [0,1,1,1], [0,-1,-1,-1]; not the other sample.
        assert_eq!(map.out_table().row(0).iter().filter(|&&i| i != NONE).count(), 4);
        assert_eq!(map.out_table().row(5).iter().filter(|&&i| i != NONE).count(), 1);
        assert_eq!(map.num_pairs(), map.pairs().input.len());
    }

    #[test]
    fn down_map_groups_children_under_floor_parents() {
        let coords = vec![[0, -1, 0, 0], [0, -2, 1, 1], [0, 0, 0, 0], [1, 0, 0, 0], [0, 3, 3, 3]];
        let (map, out) = KernelMap::down(&coords, 2, 1).unwrap();
        assert_eq!(out, vec![[0, -2, 0, 0], [0, 0, 0, 0], [1, 0, 0, 0], [0, 2, 2, 2]]);
        assert_eq!(map.in_table().row(0)[4], 0); // (-1,0,0) - (-2,0,0) = (1,0,0) → k = 4
        assert_eq!(map.in_table().row(1)[3], 0); // (0,1,1) → k = 3
        assert_eq!(map.out_table().row(3)[7], 4);
        let up = map.transposed();
        assert_eq!((up.n_in(), up.n_out()), (4, 5));
        assert_eq!(up.kind(), MapKind::Up { kernel: 2 });
        assert_eq!(up.out_table().row(4)[7], 3);
    }
    /// Every map's pairs ordered by input hold each offset's pairs of `pairs()`, ascending by
    /// input row (the feature gradient's blocks rely on the order).
    #[test]
    fn pairs_by_input_are_the_pairs_ordered_by_input() {
        let coords: Vec<Coord> = (0..400).map(|i: i32| [i % 2, (i * 7) % 11 - 5, (i * 5) % 9 - 4, (i * 3) % 7 - 3]).collect();
        let mut unique = coords.clone();
        unique.sort();
        unique.dedup();
        let index = CoordIndex::build(&unique).unwrap();
        let sub = KernelMap::submanifold(&unique, &index, 3, 1);
        let (down, _) = KernelMap::down(&unique, 2, 1).unwrap();
        let up = down.transposed();
        for map in [&sub, &down, &up] {
            let (by_out, by_in) = (map.pairs(), map.pairs_by_input());
            assert_eq!(by_out.start, by_in.start, "{:?}: offsets", map.kind());
            for k in 0..map.volume() {
                let range = by_out.start[k]..by_out.start[k + 1];
                let mut want: Vec<(u32, u32)> = by_out.input[range.clone()].iter().copied().zip(by_out.output[range.clone()].iter().copied()).collect();
                want.sort();
                let got: Vec<(u32, u32)> = by_in.input[range.clone()].iter().copied().zip(by_in.output[range].iter().copied()).collect();
                assert_eq!(got, want, "{:?}: offset {k}", map.kind());
            }
        }
        assert!(sub.num_pairs() > unique.len(), "the scene must have neighbours");
    }
    /// The parallel grouping over several chunks of rows gives each offset's pairs in row
    /// order, as one serial pass over the table would.
    #[test]
    fn pairs_group_rows_in_order_across_chunks() {
        let coords: Vec<Coord> = {
            let mut c: Vec<Coord> = (0..30_000).map(|i: i32| [i % 2, (i * 7919) % 41 - 20, (i * 104_729) % 37 - 18, (i * 1_299_709) % 43 - 21]).collect();
            c.sort();
            c.dedup();
            c
        };
        assert!(coords.len() > 2 * GROUP_ROWS, "the scene must span several chunks, has {} rows", coords.len());
        let index = CoordIndex::build(&coords).unwrap();
        let map = KernelMap::submanifold(&coords, &index, 3, 1);
        let (table, volume) = (map.out_table(), map.volume());
        let pairs = map.pairs();
        for k in 0..volume {
            let (input, output): (Vec<u32>, Vec<u32>) =
                (0..table.rows()).filter_map(|o| Some((table.row(o)[k], o as u32)).filter(|(i, _)| *i != NONE)).unzip();
            let range = pairs.start[k]..pairs.start[k + 1];
            assert_eq!(&pairs.input[range.clone()], &input[..], "offset {k}: inputs");
            assert_eq!(&pairs.output[range], &output[..], "offset {k}: outputs");
        }
    }
}

