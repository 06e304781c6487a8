//! A declared system's vectors as the loop sees them ([`Vectors`]): the state message (the
//! state, then the outputs), the input and the estimate from `[system]`, and one signal per
//! sensor, named after it, that picks the components its `reads` name.

use super::system::System;
use crate::config::launch::declared::Source;
use crate::config::launch::{LaunchConfig, LaunchError};
use crate::model::vectors::{Pick, Read, Signal, Vectors};

/// The vectors of `system`, leaked: a process builds its scenario once.
pub fn vectors(c: &LaunchConfig, system: &System) -> Result<&'static Vectors, LaunchError> {
    let n = system.vectors.state.len();
    let mut signals = Vec::new();
    for (name, spec) in &c.sensors {
        let layout = c.signal_of(spec);
        let mut picks = Vec::new();
        for (i, read) in spec.reads.iter().enumerate() {
            let (source, at, _) =
                system.vectors.find(read).map_err(|m| c.error(&format!("sensors.{name}.reads.{i}"), m))?;
            picks.push(match source {
                Source::State => Pick::State(at),
                Source::Output => Pick::State(n + at),
                Source::Input => Pick::Input(at),
            });
        }
        signals.push(Signal { name: layout.name, components: layout.components, read: Read::Picks(picks.leak()) });
    }
    let schema = &c.schema;
    Ok(Box::leak(Box::new(Vectors {
        state: schema.state,
        input: schema.input,
        estimate: schema.estimate,
        signals: signals.leak(),
    })))
}
