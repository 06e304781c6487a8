//! Finds stalled processes from the data alone.
//!
//! A process whose newest input is newer than its newest output for longer than the stall
//! timeout has stopped handling its input (iceoryx2 reports a SIGSTOPped process as alive). A
//! plant on a clock must also publish every period. Checked each time the monitor drains its
//! queues, so detection comes within one poll of the timeout. The wait is dated by the data's
//! own publish stamps, not by when the monitor saw them: a monitor held up by a busy machine
//! still detects a stall when it is due.

use std::collections::VecDeque;

use crate::contract::protocol::ChildEvent;
use crate::contract::role::{Role, Topic};
use crate::monitor::join::PerTopic;

/// Inputs kept per stage while it does not answer: a second at 4 kHz, far past any stall
/// timeout's use (only the oldest dates the wait).
const MAX_UNANSWERED: usize = 4096;

pub struct StallWatch {
    timeout_ns: u64,
    /// The plant's period when it ticks on a clock (real time); None when it waits for each
    /// command (lockstep).
    plant_period_ns: Option<u64>,
    /// The plant's last tick: after it, silence is the end of the run.
    last_tick: u64,
    /// Newest k seen per topic.
    newest: PerTopic<Option<u64>>,
    /// When the newest state was published.
    state_seen_ns: u64,
    /// When the newest command was published.
    command_seen_ns: u64,
    /// Per stage's input topic, the inputs its stage has not answered yet: (k, publish stamp).
    unanswered: PerTopic<VecDeque<(u64, u64)>>,
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
            command_seen_ns: clock(),
            unanswered: PerTopic::default(),
            waiting: [None; Role::LOOP.len()],
            stalled: [false; Role::LOOP.len()],
            clock,
        }
    }

    /// A sample of loop `k` published at `published_ns` (0: not stamped) arrived on `topic`.
    pub fn saw(&mut self, topic: Topic, k: u64, published_ns: u64) {
        let published = if published_ns == 0 { (self.clock)() } else { published_ns };
        let newer = self.newest[topic].is_none_or(|n| k > n);
        if topic == Topic::State && newer {
            self.state_seen_ns = published;
        }
        if topic == Topic::Command && newer {
            self.command_seen_ns = published;
        }
        self.newest[topic] = self.newest[topic].max(Some(k));
        for role in Role::LOOP {
            let (Some(input), Some(output)) = (role.input(), role.output()) else { continue };
            if role == Role::Plant {
                continue;
            }
            if topic == input && newer && self.unanswered[input].len() < MAX_UNANSWERED {
                self.unanswered[input].push_back((k, published));
            }
            if topic == output {
                // A stage's output k answers its input k.
                while self.unanswered[input].front().is_some_and(|(i, _)| *i <= k) {
                    self.unanswered[input].pop_front();
                }
            }
        }
    }

    /// Whether `role`'s input waits, and since when if the data tells.
    fn waiting(&self, role: Role, now: u64) -> (bool, Option<u64>) {
        let (Some(input), Some(output)) = (role.input(), role.output()) else {
            return (false, None);
        };
        let (input, output) = (self.newest[input], self.newest[output]);
        if role != Role::Plant {
            // A stage's output k answers its input k; the wait dates from the first input
            // left unanswered.
            let waits = input.is_some_and(|i| output.is_none_or(|o| i > o));
            let since = self.unanswered[role.input().expect("a stage has an input")].front().map(|(_, ns)| *ns);
            return (waits, since.filter(|_| waits));
        }
        if self.newest[Topic::State].is_some_and(|k| k >= self.last_tick) {
            return (false, None);
        }
        match self.plant_period_ns {
            // Command k answers state k: the plant waits once the command for its newest
            // state is in, since that command was sent (a plant that keeps up waits a moment
            // every loop, which is no stall).
            None => {
                let waits = input.is_some_and(|i| output.is_none_or(|o| i >= o));
                (waits, Some(self.command_seen_ns).filter(|_| waits))
            }
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
            // Dated by the data where it tells: the oldest input still unanswered moves on as
            // answers come, so a stage whose answers all come late (a delay fault, a transport
            // delay) but come is not stalled, and one that answers again has resumed.
            let since = match since {
                Some(since) => *self.waiting[i].insert(since),
                None => *self.waiting[i].get_or_insert(now),
            };
            let over = now.saturating_sub(since) >= self.timeout_ns;
            if over && !self.stalled[i] {
                self.stalled[i] = true;
                events.push(ChildEvent::Stall { process: role.name().to_owned(), since_ns: since, detected_ns: now });
            } else if !over && std::mem::take(&mut self.stalled[i]) {
                events.push(ChildEvent::Resumed { process: role.name().to_owned(), at_ns: now });
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
            watch.saw(topic, k, 0);
        }
    }

    #[test]
    fn a_stage_holding_its_input_past_the_timeout_is_reported_once_then_resumes() {
        let (mut watch, now) = watch(None);
        whole_loop(&mut watch, 0);
        // The estimator has measurements 1 (published at 1010 ms) and no estimate 1 from here on.
        now.set(1010 * MS);
        watch.saw(Topic::State, 1, 0);
        watch.saw(Topic::Measurements, 1, 0);
        assert_eq!(watch.check(), []);
        now.set(1059 * MS);
        assert_eq!(watch.check(), []);
        now.set(1060 * MS);
        assert_eq!(watch.check(), [stall("estimator", 1010, 1060)]);
        now.set(1200 * MS);
        assert_eq!(watch.check(), [], "reported once");
        watch.saw(Topic::Estimate, 1, 0);
        now.set(1201 * MS);
        assert_eq!(watch.check(), [ChildEvent::Resumed { process: "estimator".into(), at_ns: 1201 * MS }]);
    }

    /// A controller whose every command comes 30 ms late (a delay fault, pipelined) always has
    /// an input unanswered, but never one for 50 ms: it is not stalled.
    #[test]
    fn a_stage_answering_every_input_late_is_not_stalled() {
        let (mut watch, now) = watch(None);
        whole_loop(&mut watch, 0);
        for k in 1..100 {
            now.set((1000 + k) * MS);
            for topic in [Topic::State, Topic::Measurements, Topic::Estimate] {
                watch.saw(topic, k, (1000 + k) * MS);
            }
            if k > 30 {
                watch.saw(Topic::Command, k - 30, (1000 + k - 30) * MS);
            }
            assert_eq!(watch.check(), [], "loop {k}");
        }
    }

    /// A monitor held up by a busy machine sees the estimate of loop 1 only 40 ms after it was
    /// published, and no command answers it: the controller's wait dates from the publish
    /// stamp, so the stall is due (and reported) 50 ms after it, not 50 ms after the monitor
    /// noticed. The same for a plant on a clock whose last state the monitor saw late.
    #[test]
    fn a_late_monitor_dates_the_wait_from_the_publish_stamps() {
        let (mut watch, now) = watch(None);
        whole_loop(&mut watch, 0);
        now.set(1040 * MS);
        watch.saw(Topic::State, 1, 1000 * MS);
        watch.saw(Topic::Measurements, 1, 1000 * MS);
        watch.saw(Topic::Estimate, 1, 1000 * MS);
        watch.saw(Topic::Estimate, 2, 1001 * MS);
        assert_eq!(watch.check(), []);
        now.set(1050 * MS);
        assert_eq!(watch.check(), [stall("controller", 1000, 1050)]);

        let (mut on_clock, now) = self::watch(Some(MS));
        now.set(1080 * MS);
        for topic in Topic::ALL {
            on_clock.saw(topic, 0, 1000 * MS);
        }
        assert_eq!(on_clock.check(), [stall("plant", 1000, 1080)]);
    }

    #[test]
    fn a_lockstep_plant_waits_once_the_command_for_its_newest_state_is_in() {
        let (mut watch, now) = watch(None);
        whole_loop(&mut watch, 0);
        // Command 0 is in and state 1 never comes.
        now.set(1001 * MS);
        assert_eq!(watch.check(), []);
        now.set(1049 * MS);
        assert_eq!(watch.check(), []);
        // Dated from command 0's arrival.
        now.set(1050 * MS);
        assert_eq!(watch.check(), [stall("plant", 1000, 1050)]);
    }

    /// A lockstep plant that keeps up still waits a moment for each command: checks that always
    /// land in that moment, loop after loop, see no stall.
    #[test]
    fn a_lockstep_plant_that_answers_each_command_at_once_is_not_stalled() {
        let (mut watch, now) = watch(None);
        for k in 0..200 {
            now.set((1000 + k) * MS);
            whole_loop(&mut watch, k);
            assert_eq!(watch.check(), [], "loop {k}");
        }
    }

    #[test]
    fn a_plant_on_a_clock_stalls_when_no_state_comes_for_a_period() {
        let (mut watch, now) = watch(Some(MS));
        now.set(1000 * MS);
        watch.saw(Topic::State, 0, 0);
        // Nothing has been published downstream yet, but the plant must tick every ms.
        now.set(1000 * MS + MS / 2);
        assert_eq!(watch.check(), []);
        now.set(1030 * MS);
        watch.check();
        now.set(1050 * MS);
        // The sensors have not answered state 0 either, for as long.
        assert_eq!(watch.check(), [stall("plant", 1000, 1050), stall("sensors", 1000, 1050)]);
    }

    #[test]
    fn after_the_last_tick_silence_is_the_end_of_the_run() {
        let (mut watch, now) = watch(Some(MS));
        whole_loop(&mut watch, 99);
        now.set(5000 * MS);
        assert_eq!(watch.check(), []);
    }
}
