//! The world cloud of one scale (DESIGN steps 1-3, paper section "Spatial Smoothing for LiDAR
//! Factor Extraction"): each frame voxel-downsampled in its own lidar coordinates and moved
//! into the world by the current poses (paper eq. `projection`), PCA normals oriented towards
//! each frame's sensor, and one kernel point per gamma voxel ([`scale_cloud`]). Underneath:
//! the voxel buckets and the kd-tree over their centroids that answer the kernels' radius
//! queries ([`voxel_index`], [`voxel_sort`]), the normals' neighbourhoods ([`neighbour_grid`])
//! and their eigenvectors ([`normals`], [`eigen3`]).

pub(crate) mod deskew;
pub(crate) mod eigen3;
pub(crate) mod neighbour_grid;
pub(crate) mod normals;
pub(crate) mod scale_cloud;
pub(crate) mod voxel_index;
mod voxel_sort;
