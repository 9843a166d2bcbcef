//! cocog file formats: COLMAP, LLFF, transforms.json, 3DGS PLY, glTF `KHR_gaussian_splatting`,
//! single-channel EXR and images. This crate knows nothing of the pipeline; stages convert.

mod atomic;
mod bytes;
pub mod colmap;
pub mod error;
pub mod exr_map;
pub mod glb;
pub mod images;
pub mod lens_model;
pub mod llff;
pub mod nerf;
mod npy_header;
pub mod ply;
pub mod pose;
pub mod rng;
pub mod safetensors_layout;
pub mod splats;
pub mod spz;

pub use atomic::write_atomic;
pub use error::{FormatError, Result};
pub use ply::PointCloud;
pub use splats::Splats;
