//! A vehicle's command link that takes a new command only every `period_s` (a radio uplink)
//! and holds it in between, and what it costs: how old the data behind the applied command
//! are when the vehicle starts acting on it.

use std::collections::VecDeque;

use crate::model::scenario::Row;

/// Takes the command of the first tick of each link slot and holds it for the slot.
#[derive(Debug, Clone)]
pub struct CommandLink<const N: usize> {
    period_s: f64,
    /// The command taken last and the slot it was taken in; None after a restart, until the
    /// next slot.
    taken: Option<(u64, [f64; N])>,
}

impl<const N: usize> CommandLink<N> {
    /// `period_s` 0: the link passes every tick's command.
    pub fn new(period_s: f64) -> Self {
        Self { period_s, taken: None }
    }

    /// The command the vehicle acts on over the tick from t: the link's, or the one given.
    pub fn through(&mut self, t: f64, u: &[f64]) -> [f64; N] {
        let mut command = [0.0; N];
        command.copy_from_slice(&u[..N]);
        if self.period_s <= 0.0 {
            return command;
        }
        // A tiny margin so that a tick that lands on a slot boundary in exact arithmetic does.
        let slot = ((t + 1e-9) / self.period_s).floor() as u64;
        match self.taken {
            Some((taken, held)) if taken == slot => held,
            _ => {
                self.taken = Some((slot, command));
                command
            }
        }
    }

    /// Forgets the held command (a restarted plant).
    pub fn reset(&mut self) {
        self.taken = None;
    }
}

/// Loops kept to match applied commands: longer than any command link's hold.
const COMMANDS_KEPT: usize = 512;

/// For metrics: how long the command in effect had been held, and how old the oldest sample
/// behind it was, when each period began.
#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub struct ActuationAge {
    /// The last loops' (t, command, oldest sample time behind it), to find the loop whose
    /// command the vehicle is acting on.
    recent: VecDeque<(f64, Vec<f64>, f64)>,
    hold_sum: f64,
    hold_max: f64,
    age_sum: f64,
    age_max: f64,
    n: usize,
}

impl ActuationAge {
    /// Finds the loop whose command the actuator applied over the period that ended now (the
    /// newest one with exactly that command) and records how long it had been held and how
    /// old its data were when the period began.
    pub fn observe(&mut self, row: &Row, inputs: usize) {
        if let Some(&(began, _, _)) = self.recent.back() {
            let found = self.recent.iter().rev().find(|(_, command, _)| command[..] == row.applied[..inputs]);
            if let Some((computed_at, _, sample_time)) = found {
                let (hold, age) = (began - computed_at, began - sample_time);
                self.hold_sum += hold;
                self.hold_max = self.hold_max.max(hold);
                self.age_sum += age;
                self.age_max = self.age_max.max(age);
                self.n += 1;
            }
        }
        // The oldest sample the command was computed from.
        let sample_time = row.readings.iter().filter(|r| r.valid != 0).map(|r| r.sample_time).fold(row.t, f64::min);
        self.recent.push_back((row.t, row.command[..inputs].to_vec(), sample_time));
        if self.recent.len() > COMMANDS_KEPT {
            self.recent.pop_front();
        }
    }

    /// `command_hold_mean_s`, `command_hold_max_s`, `actuation_data_age_mean_s`,
    /// `actuation_data_age_max_s`; nothing before the first matched period.
    pub fn metrics(&self) -> Vec<(&'static str, f64)> {
        if self.n == 0 {
            return Vec::new();
        }
        let n = self.n as f64;
        vec![
            ("command_hold_mean_s", self.hold_sum / n),
            ("command_hold_max_s", self.hold_max),
            ("actuation_data_age_mean_s", self.age_sum / n),
            ("actuation_data_age_max_s", self.age_max),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_link_takes_the_first_command_of_each_slot() {
        // 45 Hz at 1 kHz: slots start at ticks 0, 23 (22.2 ms), 45, 67.
        let mut link = CommandLink::<1>::new(1.0 / 45.0);
        let taken: Vec<f64> = (0..70).map(|k| link.through(k as f64 * 1e-3, &[k as f64])[0]).collect();
        assert_eq!(taken[0..23], [0.0; 23]);
        assert_eq!(taken[23..45], [23.0; 22]);
        assert_eq!(taken[45..67], [45.0; 22]);
        assert_eq!(taken[67], 67.0);
        link.reset();
        assert_eq!(link.through(0.0685, &[9.0]), [9.0]);
        assert_eq!(CommandLink::<1>::new(0.0).through(0.5, &[3.0]), [3.0]);
    }
}
