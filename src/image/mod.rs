//! Layer 1: images. The film and its pixel accumulator, PNG and EXR
//! output written atomically, shard files and their merge, and error
//! metrics between images.

pub mod film;
pub mod lines;
pub mod metrics;
pub mod output;
pub mod shard;
