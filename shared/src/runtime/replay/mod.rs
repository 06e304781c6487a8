//! A recording played back: the run's `run.mcap` read back (`recording_reader`) and played into
//! the processes other than the replayed stage (`playback`).

pub mod playback;
pub mod recording_reader;
