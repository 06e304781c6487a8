//! Finds stalled processes from the data alone.
//!
//! A process whose newest input is newer than its newest output for longer than the stall
//! timeout has stopped handling its input (iceoryx2 reports a SIGSTOPped process as alive). A
//! plant on a clock must also publish every period. Checked each time the monitor drains its
//! queues, so detection comes within one poll of the timeout.

use crate::contract::protocol::ChildEvent;
use crate::contract::role::{Role, Topic};
use crate::monitor::join::PerTopic;

pub struct StallWatch {
    timeout_ns: u64,
    /// The plant's period when it ticks on a clock (real time); None when it waits for each
    /// command (lockstep).
    plant_period_ns: Option<u64>,
    /// The plant's last tick: after it, silence is the end of the run.
    last_tick: u64,
    /// Newest k seen per topic.
    newest: PerTopic<Option<u64>>,
    /// When the monitor last saw a new state.
    state_seen_ns: u64,
    /// Per process of [`Role::LOOP`]: since when its input has waited, and whether it was reported.
    waiting: [Option<u64>; Role::LOOP.len()],
    stalled: [bool; Role::LOOP.len()],
    /// CLOCK_MONOTONIC in ns (a fake clock in the tests).
    clock: Box<dyn Fn() -> u64>,
}

impl StallWatch {
    pub fn new(timeout_ns: u64, loops: u64, plant_period_ns: Option<u64>, clock: Box<dyn Fn() -> u64>) -> Self {
        Self {
            timeout_ns,
            plant_period_ns,
            last_tick: loops.saturating_sub(1),
            newest: PerTopic::default(),
            state_seen_ns: clock(),
            waiting: [None; Role::LOOP.len()],
            stalled: [false; Role::LOOP.len()],
            clock,
        }
    }

    /// A sample of loop `k` arrived on `topic`.
    pub fn saw(&mut self, topic: Topic, k: u64) {
        if topic == Topic::State && self.newest[topic].is_none_or(|n| k > n) {
            self.state_seen_ns = (self.clock)();
        }
        self.newest[topic] = self.newest[topic].max(Some(k));
    }

    /// Whether `role`'s input waits, and since when if the data tells.
    fn waiting(&self, role: Role, now: u64) -> (bool, Option<u64>) {
        let (Some(input), Some(output)) = (role.input(), role.output()) else {
            return (false, None);
        };
        let (input, output) = (self.newest[input], self.newest[output]);
        if role != Role::Plant {
            // A stage's output k answers its input k.
            return (input.is_some_and(|i| output.is_none_or(|o| i > o)), None);
        }
        if self.newest[Topic::State].is_some_and(|k| k >= self.last_tick) {
            return (false, None);
        }
        match self.plant_period_ns {
            // Command k answers state k: the plant waits once the command for its newest
            // state is in.
            None => (input.is_some_and(|i| output.is_none_or(|o| i >= o)), None),
            // Its input is its clock: a state is due every period, so silence dates from the last.
            Some(period) => (now > self.state_seen_ns + period, Some(self.state_seen_ns)),
        }
    }

    /// Events for processes that stalled or came back since the last check.
    pub fn check(&mut self) -> Vec<ChildEvent> {
        let now = (self.clock)();
        let mut events = vec![];
        for (i, role) in Role::LOOP.into_iter().enumerate() {
            let (waiting, since) = self.waiting(role, now);
            if !waiting {
                self.waiting[i] = None;
                if std::mem::take(&mut self.stalled[i]) {
                    events.push(ChildEvent::Resumed { process: role.name().to_owned(), at_ns: now });
                }
                continue;
            }
            let since = *self.waiting[i].get_or_insert(since.unwrap_or(now));
            if !self.stalled[i] && now - since >= self.timeout_ns {
                self.stalled[i] = true;
                events.push(ChildEvent::Stall { process: role.name().to_owned(), since_ns: since, detected_ns: now });
            }
        }
        events
    }
}

#[cfg(test)]
mod tests {
    use std::cell::Cell;
    use std::rc::Rc;

    use super::*;

    const MS: u64 = 1_000_000;

    /// A watch with a 50 ms timeout over 100 loops, and the hand that moves its clock.
    fn watch(plant_period_ns: Option<u64>) -> (StallWatch, Rc<Cell<u64>>) {
        let now = Rc::new(Cell::new(1000 * MS));
        let clock = now.clone();
        (StallWatch::new(50 * MS, 100, plant_period_ns, Box::new(move || clock.get())), now)
    }

    fn stall(process: &str, since_ms: u64, detected_ms: u64) -> ChildEvent {
        ChildEvent::Stall { process: process.into(), since_ns: since_ms * MS, detected_ns: detected_ms * MS }
    }

    /// One whole loop k seen by the monitor.
    fn whole_loop(watch: &mut StallWatch, k: u64) {
        for topic in Topic::ALL {
            watch.saw(topic, k);
        }
    }

    #[test]
    fn a_stage_holding_its_input_past_the_timeout_is_reported_once_then_resumes() {
        let (mut watch, now) = watch(None);
        whole_loop(&mut watch, 0);
        watch.saw(Topic::State, 1);
        watch.saw(Topic::Measurements, 1);
        // The estimator has measurements 1 and no estimate 1 from here on.
        now.set(1010 * MS);
        assert_eq!(watch.check(), []);
        now.set(1059 * MS);
        assert_eq!(watch.check(), []);
        now.set(1060 * MS);
        assert_eq!(watch.check(), [stall("estimator", 1010, 1060)]);
        now.set(1200 * MS);
        assert_eq!(watch.check(), [], "reported once");
        watch.saw(Topic::Estimate, 1);
        now.set(1201 * MS);
        assert_eq!(watch.check(), [ChildEvent::Resumed { process: "estimator".into(), at_ns: 1201 * MS }]);
    }

    #[test]
    fn a_lockstep_plant_waits_once_the_command_for_its_newest_state_is_in() {
        let (mut watch, now) = watch(None);
        whole_loop(&mut watch, 0);
        // Command 0 is in and state 1 never comes.
        now.set(1001 * MS);
        assert_eq!(watch.check(), []);
        now.set(1051 * MS);
        assert_eq!(watch.check(), [stall("plant", 1001, 1051)]);
    }

    #[test]
    fn a_plant_on_a_clock_stalls_when_no_state_comes_for_a_period() {
        let (mut watch, now) = watch(Some(MS));
        now.set(1000 * MS);
        watch.saw(Topic::State, 0);
        // Nothing has been published downstream yet, but the plant must tick every ms.
        now.set(1000 * MS + MS / 2);
        assert_eq!(watch.check(), []);
        now.set(1030 * MS);
        watch.check();
        now.set(1050 * MS);
        assert_eq!(watch.check(), [stall("plant", 1000, 1050)]);
    }

    #[test]
    fn after_the_last_tick_silence_is_the_end_of_the_run() {
        let (mut watch, now) = watch(Some(MS));
        whole_loop(&mut watch, 99);
        now.set(5000 * MS);
        assert_eq!(watch.check(), []);
    }
}
