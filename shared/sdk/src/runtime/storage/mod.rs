//! The run's storage: its private folder in shared memory (the secret in its names, the clean-up
//! of what a run left), files mapped or written there never through a link, and the snapshots a
//! restarted process goes on from.

pub mod private_file;
pub mod run_file;
pub mod run_storage;
pub mod shared_file;
pub mod shm_secret;
pub mod snapshot;
