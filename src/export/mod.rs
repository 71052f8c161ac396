//! Exports for other tools: a tracked sequence as BVH motion ([`bvh`]) and results as
//! JSON lines ([`jsonl`]). Meshes are exported by the Python layer (trimesh).

pub mod bvh;
pub mod jsonl;

pub use bvh::{write_bvh, BvhMotion, BVH_NAMES, BVH_PARENTS};
pub use jsonl::{write_jsonl, Json};
