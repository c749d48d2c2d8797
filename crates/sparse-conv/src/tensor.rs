//! `SparseTensor`: voxel features with their coordinates, tensor stride and shared map cache.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use burn::tensor::Tensor;

use crate::profile::{Kernel, in_kernel};
use crate::geometry::coords::{Coord, CoordError, CoordIndex};
use crate::geometry::kernel_map::{KernelMap, MapKind};
use crate::geometry::level::{LevelCoords, coarse_level_sizes};

/// Features `[N, C]` on the voxels `coords` of one level of a sparse network.
///
/// Every tensor derived from one input (by convolutions, norms, concatenations) shares one
/// [`MapCache`], so a U-Net builds each level's coordinates and each kernel map once per forward
/// pass and its transposed convolutions reuse the down-sampling maps, as torchsparse does. On a
/// GPU (with [`crate::GpuMaps::Device`]) the coarser levels and every map are made on the device,
/// and a coarse level's coordinates come to the host only if something there reads them.
#[derive(Clone, Debug)]
pub struct SparseTensor {
    features: Tensor<2>,
    level: Arc<LevelCoords>,
    stride: i32,
    cache: Arc<MapCache>,
}

impl SparseTensor {
    /// A stride-1 tensor; the coordinates must be unique and in range.
    pub fn new(features: Tensor<2>, coords: Vec<Coord>) -> Result<Self, CoordError> {
        let rows = features.dims()[0];
        if rows != coords.len() {
            return Err(CoordError::FeatureRows { features: rows, coords: coords.len() });
        }
        let index = CoordIndex::build(&coords)?;
        let level = Arc::new(LevelCoords::on_host(coords.into()));
        let cache = MapCache::default();
        {
            let mut state = cache.state.lock().unwrap();
            state.levels.insert(1, level.clone());
            state.indexes.insert(1, Arc::new(index));
        }
        Ok(Self { features, level, stride: 1, cache: Arc::new(cache) })
    }

    /// Voxel features, `[N, C]`.
    pub fn features(&self) -> Tensor<2> {
        self.features.clone()
    }

    /// Consumes the tensor, keeping its features.
    pub fn into_features(self) -> Tensor<2> {
        self.features
    }

    /// Voxel coordinates in finest-level units (multiples of the stride); a level made on a GPU
    /// reads them back the first time.
    pub fn coords(&self) -> &Arc<[Coord]> {
        self.level.host()
    }

    /// This level's coordinates, wherever they are.
    pub fn level(&self) -> &Arc<LevelCoords> {
        &self.level
    }

    /// Tensor stride: the voxel size of this level in finest-level voxels.
    pub fn stride(&self) -> i32 {
        self.stride
    }

    /// Number of voxels.
    pub fn num_voxels(&self) -> usize {
        self.level.len()
    }

    /// Number of feature channels.
    pub fn channels(&self) -> usize {
        self.features.dims()[1]
    }

    /// The same voxels with other features (same rows).
    pub fn with_features(&self, features: Tensor<2>) -> Self {
        assert_eq!(features.dims()[0], self.level.len(), "new features must keep one row per voxel");
        Self { features, level: self.level.clone(), stride: self.stride, cache: self.cache.clone() }
    }

    /// Applies `f` to the features.
    pub fn map_features(self, f: impl FnOnce(Tensor<2>) -> Tensor<2>) -> Self {
        let features = f(self.features);
        Self { features, ..self }
    }

    /// Concatenates the channels of two tensors on identical coordinates: `[self, other]`.
    pub fn cat(&self, other: &SparseTensor) -> Self {
        self.assert_same_voxels(other);
        self.with_features(crate::ops::concat::concat_channels(self.features.clone(), other.features.clone()))
    }

    /// [`Self::cat`] within each of `copies` orientation copies (orientation-major channels,
    /// [`crate::modules::turns`]): copy r's channels of `self`, then copy r's of `other`.
    pub fn cat_copies(&self, other: &SparseTensor, copies: usize) -> Self {
        if copies == 1 {
            return self.cat(other);
        }
        self.assert_same_voxels(other);
        let (rows, a, b) = (self.num_voxels(), self.channels(), other.channels());
        let split = |t: &SparseTensor, c: usize| t.features().reshape([rows, copies, c / copies]);
        self.with_features(Tensor::cat(vec![split(self, a), split(other, b)], 2).reshape([rows, a + b]))
    }

    fn assert_same_voxels(&self, other: &SparseTensor) {
        assert!(
            self.stride == other.stride
                && (Arc::ptr_eq(&self.level, &other.level) || self.coords() == other.coords()),
            "sparse concatenation needs identical coordinates (strides {} and {})",
            self.stride,
            other.stride
        );
    }

    /// The submanifold map of an odd `kernel` at this level, built once per cache.
    pub fn submanifold_map(&self, kernel: usize) -> Arc<KernelMap> {
        let key = (MapKind::Submanifold { kernel }, self.stride);
        if let Some(map) = self.cache.get(key) {
            return map;
        }
        let map = if maps_on_device(&self.features) {
            // The GPU kernels build its tables on the device (`geometry::device_maps`).
            Arc::new(KernelMap::submanifold_deferred(self.level.clone(), kernel, self.stride))
        } else {
            in_kernel(Kernel::MapBuild, || {
                let coords = self.coords();
                let index = self.cache.index(self.stride, coords);
                Arc::new(KernelMap::submanifold(coords, &index, kernel, self.stride))
            })
        };
        self.cache.insert(key, map.clone());
        map
    }

    /// The down-sampling map (kernel = stride = `kernel`) from this level and the coarser level's
    /// coordinates, built once per cache.
    pub fn down_map(&self, kernel: usize) -> (Arc<KernelMap>, Arc<LevelCoords>) {
        let key = (MapKind::Down { kernel }, self.stride);
        let out_stride = self.stride * kernel as i32;
        if let Some(map) = self.cache.get(key) {
            return (map, self.cache.level(out_stride).expect("a cached down map has its level"));
        }
        let (map, level) = self.down_on_device(kernel).unwrap_or_else(|| {
            let (map, coords) = in_kernel(Kernel::MapBuild, || KernelMap::down(self.coords(), kernel, self.stride))
                .expect("coordinates of a sparse tensor are validated and on their level's grid");
            (map, Arc::new(LevelCoords::on_host(coords.into())))
        });
        let map = Arc::new(map);
        self.cache.insert(key, map.clone());
        self.cache.state.lock().unwrap().levels.entry(out_stride).or_insert(level);
        (map, self.cache.level(out_stride).unwrap())
    }

    /// The down-sampling map and coarse level built on the device, where this tensor's maps are.
    fn down_on_device(&self, kernel: usize) -> Option<(KernelMap, Arc<LevelCoords>)> {
        if !maps_on_device(&self.features) {
            return None;
        }
        #[cfg(feature = "cube")]
        {
            let coarse = self.cache.state.lock().unwrap().level_sizes.get(&(self.stride * kernel as i32)).copied();
            crate::kernels::cube::down_on_device(&self.features.device(), &self.level, kernel, self.stride, coarse)
        }
        #[cfg(not(feature = "cube"))]
        {
            let _ = kernel;
            None
        }
    }

    /// Makes the down-sampling maps and coordinates of the coarser levels now, one level per
    /// kernel size in `kernels`; later [`SparseTensor::down_map`]s find them in the cache. On a
    /// GPU the levels' voxel counts (tensor shapes) are counted on the host first, from this
    /// level's coordinates, so the device makes the maps without reading anything back; a
    /// `down_map` without this reads the count back, which waits for everything queued.
    pub fn prepare_down_levels(&self, kernels: impl IntoIterator<Item = usize>) {
        let kernels: Vec<usize> = kernels.into_iter().collect();
        if maps_on_device(&self.features) && self.level.is_on_host() {
            let sizes = in_kernel(Kernel::MapBuild, || coarse_level_sizes(self.coords(), self.stride, &kernels));
            let mut state = self.cache.state.lock().unwrap();
            let mut stride = self.stride;
            for (kernel, size) in kernels.iter().zip(sizes) {
                stride *= *kernel as i32;
                state.level_sizes.insert(stride, size);
            }
        }
        let (mut level, mut stride) = (self.level.clone(), self.stride);
        for kernel in kernels {
            // `features` stands for the device only; its rows are the finest level's.
            let at = Self { features: self.features.clone(), level, stride, cache: self.cache.clone() };
            (level, stride) = (at.down_map(kernel).1, stride * kernel as i32);
        }
    }

    /// The transposed map back to the finer level this one was down-sampled from with `kernel`,
    /// and that level's coordinates.
    ///
    /// # Panics
    /// If this level was not made by a down-sampling of `kernel` in the same forward pass.
    pub fn up_map(&self, kernel: usize) -> (Arc<KernelMap>, Arc<LevelCoords>, i32) {
        let fine = self.stride / kernel as i32;
        assert!(
            fine >= 1 && fine * kernel as i32 == self.stride,
            "a transposed conv of kernel {kernel} cannot run at tensor stride {}",
            self.stride
        );
        let up_key = (MapKind::Up { kernel }, fine);
        let coords = self.cache.level(fine).expect("the finer level exists when its down map does");
        if let Some(map) = self.cache.get(up_key) {
            return (map, coords, fine);
        }
        let down = self.cache.get((MapKind::Down { kernel }, fine)).unwrap_or_else(|| {
            panic!(
                "a transposed conv at tensor stride {} needs the down-sampling map from stride {fine} built earlier in the same forward pass",
                self.stride
            )
        });
        let map = Arc::new(in_kernel(Kernel::MapBuild, || KernelMap::transpose_of(&down)));
        self.cache.insert(up_key, map.clone());
        (map, coords, fine)
    }

    /// The cache shared by every tensor of this forward pass.
    pub fn cache(&self) -> &Arc<MapCache> {
        &self.cache
    }

    /// A tensor on another level of the same cache.
    pub(crate) fn on_level(&self, features: Tensor<2>, level: Arc<LevelCoords>, stride: i32) -> Self {
        Self { features, level, stride, cache: self.cache.clone() }
    }
}

/// Whether this tensor's maps are made on its device: a GPU's, unless `gpu_maps = "host"`.
fn maps_on_device(features: &Tensor<2>) -> bool {
    on_gpu(features) && crate::KernelOptions::current().gpu_maps == crate::GpuMaps::Device
}

/// Whether the features live on a GPU (a CubeCL device), whose submanifold maps are built there.
fn on_gpu(features: &Tensor<2>) -> bool {
    #[cfg(feature = "cube")]
    return crate::kernels::cube::is_cube_device(&features.device());
    #[cfg(not(feature = "cube"))]
    {
        let _ = features;
        false
    }
}

/// Coordinates of every level and every kernel map of one forward pass.
#[derive(Default, Debug)]
pub struct MapCache {
    state: Mutex<CacheState>,
}

#[derive(Default, Debug)]
struct CacheState {
    levels: HashMap<i32, Arc<LevelCoords>>,
    indexes: HashMap<i32, Arc<CoordIndex>>,
    maps: HashMap<(MapKind, i32), Arc<KernelMap>>,
    /// Voxel counts of coarser levels known on the host before they are made, by tensor stride.
    level_sizes: HashMap<i32, usize>,
}

impl MapCache {
    fn get(&self, key: (MapKind, i32)) -> Option<Arc<KernelMap>> {
        self.state.lock().unwrap().maps.get(&key).cloned()
    }

    fn insert(&self, key: (MapKind, i32), map: Arc<KernelMap>) {
        self.state.lock().unwrap().maps.entry(key).or_insert(map);
    }

    fn level(&self, stride: i32) -> Option<Arc<LevelCoords>> {
        self.state.lock().unwrap().levels.get(&stride).cloned()
    }

    fn index(&self, stride: i32, coords: &[Coord]) -> Arc<CoordIndex> {
        if let Some(index) = self.state.lock().unwrap().indexes.get(&stride) {
            return index.clone();
        }
        let index = Arc::new(CoordIndex::build(coords).expect("levels derived from valid coordinates are valid"));
        self.state.lock().unwrap().indexes.entry(stride).or_insert(index).clone()
    }
}
