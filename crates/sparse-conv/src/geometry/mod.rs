//! Where the op's work is: voxel coordinates and their index, the kernel maps that pair input and
//! output voxels per offset (on the host, and a GPU's own submanifold maps), and the GPU's tile
//! plans over those maps (on the host, or on the GPU from the tables there).

pub(crate) mod attachments;
pub mod coords;
#[cfg(feature = "cube")]
pub(crate) mod device_down;
#[cfg(feature = "cube")]
pub(crate) mod device_maps;
#[cfg(feature = "cube")]
pub(crate) mod device_tiles;
pub mod kernel_map;
pub mod level;
#[cfg(feature = "cube")]
pub(crate) mod row_tiles;
