//! The integration tests, as one test binary: each module is one subject's tests, run against
//! the real `looplab` binary (which starts the real processes over real iceoryx2 shared memory).
//! One binary links LoopLab once instead of once per subject, which is most of the suite's build
//! time. Run one subject with `cargo test --release --test suite pendulum::`.
//! `user_stage_errors` stays its own binary: it has its own `main`.

mod common;
mod figure_check;

mod answers;
mod c_and_rust_stages;
mod catalog;
mod cli;
mod compare;
mod controller_restart;
mod dashboard;
mod declared;
mod declared_metrics;
mod diff;
mod faults;
mod fip;
mod fmu_plant;
mod layers;
mod loop_runtime;
mod mcap;
mod netns;
mod pendulum;
mod plot;
mod python_plant;
mod python_stage;
mod quadcopter;
mod recorded;
mod remote;
mod replay;
mod security;
mod soak;
mod summary_schema;
mod tethered;
mod tiltrotor;
mod trajectory_hashes;
