//! One level's voxel coordinates, on the host or on a GPU, copied to the other side only when
//! something there reads them: a GPU's forward pass down-samples its levels on the device and the
//! host never needs their coordinates.

use std::any::Any;
use std::fmt;
use std::sync::{Arc, OnceLock};

use crate::geometry::attachments::Attachments;
use crate::geometry::coords::Coord;

/// Reads a device level's coordinates back to the host.
type ReadBack = Box<dyn Fn() -> Vec<Coord> + Send + Sync>;

/// The voxel coordinates of one level of a sparse network.
pub struct LevelCoords {
    len: usize,
    host: OnceLock<Arc<[Coord]>>,
    /// How to fetch the coordinates of a level made on a device.
    read_back: Option<ReadBack>,
    /// The coordinates on devices (uploaded, or where the level was made).
    attachments: Attachments,
}

impl fmt::Debug for LevelCoords {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("LevelCoords").field("len", &self.len).field("on_host", &self.host.get().is_some()).finish()
    }
}

impl LevelCoords {
    /// A level whose coordinates are on the host.
    pub fn on_host(coords: Arc<[Coord]>) -> Self {
        Self { len: coords.len(), host: OnceLock::from(coords), read_back: None, attachments: Attachments::default() }
    }

    /// A level made on a device: `on_device` holds its `len` coordinates there, `read_back`
    /// fetches them the first time the host asks.
    #[cfg_attr(not(feature = "cube"), allow(dead_code))]
    pub(crate) fn on_device<T: Any + Send + Sync>(len: usize, on_device: Arc<T>, read_back: impl Fn() -> Vec<Coord> + Send + Sync + 'static) -> Self {
        let attachments = Attachments::default();
        attachments.insert(on_device);
        Self { len, host: OnceLock::new(), read_back: Some(Box::new(read_back)), attachments }
    }

    /// Number of voxels.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether the level has no voxels.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The coordinates on the host (read back from the device the first time for a device level).
    pub fn host(&self) -> &Arc<[Coord]> {
        self.host.get_or_init(|| {
            let read_back = self.read_back.as_ref().expect("a level without host coordinates was made on a device");
            read_back().into()
        })
    }

    /// Whether the coordinates are on the host (always, except for a device level nothing on the
    /// host has read).
    pub fn is_on_host(&self) -> bool {
        self.host.get().is_some()
    }

    /// The level's form of type `T` that `matches` (its coordinates on one device), made with
    /// `make` the first time.
    pub fn attachment<T: Any + Send + Sync>(&self, matches: impl Fn(&T) -> bool, make: impl FnOnce() -> T) -> Arc<T> {
        self.attachments.get_or_make(matches, make)
    }
}

/// The voxel counts of the coarser levels a chain of down-samplings (kernel = stride, one per
/// entry of `kernels`) makes from `coords` at tensor stride `stride`: what a GPU's forward pass
/// needs on the host to shape its tensors, counted here so that nothing is read back from the
/// device while it runs.
pub(crate) fn coarse_level_sizes(coords: &[Coord], stride: i32, kernels: &[usize]) -> Vec<usize> {
    let mut level: Vec<Coord> = coords.to_vec();
    let mut stride = stride;
    let mut sizes = Vec::with_capacity(kernels.len());
    for &kernel in kernels {
        stride *= kernel as i32;
        // A coarser floor of a floor is the coarser floor: each level from the one before.
        for c in &mut level {
            *c = [c[0], c[1].div_euclid(stride) * stride, c[2].div_euclid(stride) * stride, c[3].div_euclid(stride) * stride];
        }
        level.sort_unstable();
        level.dedup();
        sizes.push(level.len());
    }
    sizes
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::kernel_map::KernelMap;

    #[test]
    fn coarse_level_sizes_are_the_down_maps_levels() {
        let coords: Vec<Coord> = (0..5000).map(|i: i32| [i % 3, (i * 7919) % 97 - 48, (i * 104_729) % 61 - 30, (i * 13) % 9 - 4]).collect::<std::collections::BTreeSet<_>>().into_iter().collect();
        let kernels = [2, 2, 3, 2];
        let mut expected = Vec::new();
        let (mut level, mut stride) = (coords.clone(), 1);
        for &k in &kernels {
            level = KernelMap::down(&level, k, stride).unwrap().1;
            stride *= k as i32;
            expected.push(level.len());
        }
        assert_eq!(coarse_level_sizes(&coords, 1, &kernels), expected);
        assert!(expected.windows(2).all(|w| w[1] < w[0]), "the scene must shrink level by level: {expected:?}");
    }
}
