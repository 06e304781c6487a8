//! Joining the five messages of each loop by k: the parts arrive per topic, in loop order on
//! each topic but not across topics, and go out as whole loops in order.

use std::collections::{BTreeMap, VecDeque};
use std::ops::{Index, IndexMut};

use crate::contract::msg::{Command, Estimate, Header, LoopRecord, Measurements, PlantState};
use crate::contract::report::HOPS;
use crate::contract::role::Topic;

/// One message the recorder takes (the contract's `LoopMessage`). Samples are moved, not boxed:
/// one copy per sample, no allocation on the receive path.
pub use crate::contract::msg::LoopMessage as Sample;

/// The parts of one loop that have arrived.
#[derive(Debug, Default, Clone)]
pub struct LoopParts {
    pub state: Option<PlantState>,
    pub measurements: Option<Measurements>,
    pub estimate: Option<Estimate>,
    pub command: Option<Command>,
    pub record: Option<LoopRecord>,
}

impl LoopParts {
    fn put(&mut self, sample: Sample) {
        match sample {
            Sample::State(s) => self.state = Some(s),
            Sample::Measurements(s) => self.measurements = Some(s),
            Sample::Estimate(s) => self.estimate = Some(s),
            Sample::Command(s) => self.command = Some(s),
            Sample::Loop(s) => self.record = Some(s),
        }
    }

    /// Whether the part from `topic` is here.
    pub fn has(&self, topic: Topic) -> bool {
        match topic {
            Topic::State => self.state.is_some(),
            Topic::Measurements => self.measurements.is_some(),
            Topic::Estimate => self.estimate.is_some(),
            Topic::Command => self.command.is_some(),
            Topic::Loop => self.record.is_some(),
        }
    }

    /// The header of the part from `topic`, if it is here.
    pub fn header(&self, topic: Topic) -> Option<Header> {
        match topic {
            Topic::State => self.state.map(|m| m.header),
            Topic::Measurements => self.measurements.map(|m| m.header),
            Topic::Estimate => self.estimate.map(|m| m.header),
            Topic::Command => self.command.map(|m| m.header),
            Topic::Loop => self.record.map(|m| m.header),
        }
    }

    /// Plant publish of the state to the command reaching the plant, from the loop record.
    pub fn end_to_end_ns(&self) -> Option<u64> {
        self.record.map(|r| r.header.trace.end_to_end_ns())
    }

    /// Whether the loop missed its deadline (real time, `wall_clock`): its record says so, its
    /// state went out and no command ever reached the plant, or nothing of it came at all (a
    /// tick the plant never woke for). None where that is not known (a part other than the state
    /// and the record arrived) and in lockstep, which has no deadline. The plant counts the same
    /// loops (`PlantCore::advance`: late or no command; `skipped_ticks`: no tick).
    pub fn deadline_missed(&self, wall_clock: bool) -> Option<bool> {
        let nothing = self.measurements.is_none() && self.estimate.is_none() && self.command.is_none();
        match (&self.record, &self.state) {
            (Some(r), _) => Some(r.deadline_miss != 0),
            (None, Some(_)) if wall_clock => Some(true),
            (None, None) if wall_clock && nothing => Some(true),
            _ => None,
        }
    }

    /// Each hop of [`HOPS`], from the loop record.
    pub fn hops_ns(&self) -> Option<[u64; HOPS.len()]> {
        self.record.map(|r| {
            let stamps = r.header.trace.stamps();
            HOPS.map(|(_, from, to)| stamps[to].saturating_sub(stamps[from]))
        })
    }
}

/// One value per topic.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PerTopic<T>([T; Topic::ALL.len()]);

impl<T> Index<Topic> for PerTopic<T> {
    type Output = T;
    fn index(&self, topic: Topic) -> &T {
        // Topic's declaration order is the order of Topic::ALL (checked in the tests).
        &self.0[topic as usize]
    }
}

impl<T> IndexMut<Topic> for PerTopic<T> {
    fn index_mut(&mut self, topic: Topic) -> &mut T {
        &mut self.0[topic as usize]
    }
}

/// Holds the parts of each loop until the loop is settled, then hands the loops out in order.
///
/// A loop is settled once every part is either here or will never come: each topic delivers
/// in loop order, so a newer loop on a topic means this loop's part from it was skipped or lost.
/// A loop still open after `window` newer ones goes as it is.
#[derive(Debug)]
pub struct Joiner {
    window: u64,
    /// The loops from the next one on, in order (a loop nothing has arrived of yet is empty),
    /// up to `window` + 1 of them: the parts of at most that many loops are waiting in a run.
    pending: VecDeque<LoopParts>,
    /// Parts of loops further ahead than that (after a gap), until `pending` reaches them.
    far: BTreeMap<u64, LoopParts>,
    /// The next loop to hand out.
    next_k: u64,
    /// Per topic, the newest loop received.
    newest: PerTopic<Option<u64>>,
}

impl Joiner {
    pub fn new(window: u64) -> Self {
        Self { window, pending: VecDeque::new(), far: BTreeMap::new(), next_k: 0, newest: PerTopic::default() }
    }

    /// Starts at loop `k` instead of 0 (a restarted monitor: the loops before were the last one's).
    pub fn start_at(&mut self, k: u64) {
        self.next_k = k;
    }

    /// The next loop to hand out: every loop before it has gone.
    pub fn next_k(&self) -> u64 {
        self.next_k
    }

    /// Takes a sample; false if its loop has gone out already (the part came too late).
    pub fn put(&mut self, sample: Sample) -> bool {
        let (k, topic) = sample.key();
        self.newest[topic] = self.newest[topic].max(Some(k));
        if k < self.next_k {
            return false;
        }
        match self.slot(k) {
            Some(parts) => parts.put(sample),
            None => self.far.entry(k).or_default().put(sample),
        }
        true
    }

    /// How many loops `pending` holds at most.
    fn reach(&self) -> u64 {
        self.window + 1
    }

    /// Loop k's place in `pending`, if it is within reach.
    fn slot(&mut self, k: u64) -> Option<&mut LoopParts> {
        let i = k - self.next_k;
        if i >= self.reach() {
            return None;
        }
        let i = i as usize;
        if self.pending.len() <= i {
            self.pending.resize_with(i + 1, LoopParts::default);
        }
        Some(&mut self.pending[i])
    }

    fn newest_any(&self) -> Option<u64> {
        Topic::ALL.iter().filter_map(|&t| self.newest[t]).max()
    }

    /// The next loop, if it is settled.
    pub fn next_settled(&mut self) -> Option<(u64, LoopParts)> {
        let newest = self.newest_any()?;
        let k = self.next_k;
        let part = self.pending.front();
        let settled =
            Topic::ALL.iter().all(|&t| part.is_some_and(|p| p.has(t)) || self.newest[t].is_some_and(|n| n > k));
        if k > newest || !(settled || newest >= k + self.window) {
            return None;
        }
        Some(self.pop())
    }

    /// The next loop, settled or not, up to the newest loop received: once everything has
    /// arrived, the loops still waiting for parts go as they are.
    pub fn next_remaining(&mut self) -> Option<(u64, LoopParts)> {
        self.newest_any().is_some_and(|newest| self.next_k <= newest).then(|| self.pop())
    }

    /// The first loop still held, after those handed out, that has a part from `topic`: what a
    /// stage sent next after a loop it skipped.
    pub fn next_with(&self, topic: Topic) -> Option<&LoopParts> {
        self.pending.iter().chain(self.far.values()).find(|parts| parts.has(topic))
    }

    fn pop(&mut self) -> (u64, LoopParts) {
        let k = self.next_k;
        self.next_k = k + 1;
        let parts = self.pending.pop_front().unwrap_or_default();
        // The loop that came within reach, if parts of it came early.
        let newly_reached = self.next_k + self.reach() - 1;
        if let Some(early) = self.far.remove(&newly_reached) {
            *self.slot(newly_reached).expect("within reach") = early;
        }
        (k, parts)
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    pub(crate) fn state(k: u64) -> Sample {
        let mut s = PlantState::default();
        s.header.k = k;
        Sample::State(s)
    }
    pub(crate) fn measurements(k: u64) -> Sample {
        let mut s = Measurements::default();
        s.header.k = k;
        Sample::Measurements(s)
    }
    pub(crate) fn estimate(k: u64) -> Sample {
        let mut s = Estimate::default();
        s.header.k = k;
        Sample::Estimate(s)
    }
    pub(crate) fn command(k: u64) -> Sample {
        let mut s = Command::default();
        s.header.k = k;
        Sample::Command(s)
    }
    pub(crate) fn record(k: u64) -> Sample {
        let mut s = LoopRecord::default();
        s.header.k = k;
        s.sequence = k + 1;
        Sample::Loop(s)
    }
    /// The five messages of loop k, in the order data flows.
    pub(crate) fn whole(k: u64) -> [Sample; 5] {
        [state(k), measurements(k), estimate(k), command(k), record(k)]
    }

    /// Which parts each loop handed out has.
    fn shape(parts: &LoopParts) -> String {
        Topic::ALL.iter().map(|&t| if parts.has(t) { t.name().chars().next().unwrap() } else { '-' }).collect()
    }

    /// Puts each sample and returns the loops that became settled, with their parts.
    fn feed(joiner: &mut Joiner, samples: impl IntoIterator<Item = Sample>) -> Vec<(u64, String)> {
        let mut out = vec![];
        for sample in samples {
            joiner.put(sample);
            while let Some((k, parts)) = joiner.next_settled() {
                out.push((k, shape(&parts)));
            }
        }
        out
    }

    #[test]
    fn topics_index_in_the_order_of_all() {
        for (i, topic) in Topic::ALL.into_iter().enumerate() {
            assert_eq!(topic as usize, i);
        }
    }

    #[test]
    fn a_loop_goes_out_once_all_five_parts_are_here() {
        let mut joiner = Joiner::new(8);
        let [s, m, e, c, r] = whole(0);
        assert_eq!(feed(&mut joiner, [s, m, e, c]), []);
        assert_eq!(feed(&mut joiner, [r]), [(0, "smecl".to_string())]);
        assert_eq!(joiner.next_k(), 1);
    }

    #[test]
    fn parts_arriving_out_of_order_across_topics_still_join() {
        let mut joiner = Joiner::new(8);
        // Records lag behind: loops 0 and 1 wait for theirs, then go in order.
        let out = feed(&mut joiner, [state(0), state(1), measurements(0), measurements(1), estimate(1), estimate(0)]);
        assert_eq!(out, []);
        let out = feed(&mut joiner, [command(1), command(0), record(1)]);
        // Loop 0's record will never come now that loop 1's is here; loop 1 is whole.
        assert_eq!(out, [(0, "smec-".to_string()), (1, "smecl".to_string())]);
    }

    #[test]
    fn a_newer_loop_on_every_topic_settles_a_loop_with_parts_missing() {
        let mut joiner = Joiner::new(100);
        let out = feed(&mut joiner, [state(0), measurements(0), record(0)]);
        assert_eq!(out, []);
        // Estimate and command of loop 0 were dropped: loop 1's on those topics settle it.
        let out = feed(&mut joiner, [state(1), measurements(1), estimate(1)]);
        assert_eq!(out, []);
        let out = feed(&mut joiner, [command(1)]);
        assert_eq!(out, [(0, "sm--l".to_string())]);
    }

    #[test]
    fn a_loop_still_open_after_the_window_goes_as_it_is() {
        let mut joiner = Joiner::new(3);
        // The record topic is silent: nothing tells that loop 0's record will not come.
        let mut out = vec![];
        for k in 0..4 {
            out.extend(feed(&mut joiner, [state(k), measurements(k), estimate(k), command(k)]));
        }
        assert_eq!(out, [(0, "smec-".to_string())], "loop 3 is the window's end for loop 0");
        assert_eq!(joiner.next_k(), 1);
    }

    #[test]
    fn a_part_after_its_loop_went_out_is_refused() {
        let mut joiner = Joiner::new(8);
        feed(&mut joiner, whole(0));
        feed(&mut joiner, [state(1), measurements(1), estimate(1), command(1), record(1)]);
        assert!(!joiner.put(record(0)), "loop 0 has gone");
        assert!(joiner.put(state(2)));
    }

    #[test]
    fn the_remaining_loops_go_at_the_end_up_to_the_newest() {
        let mut joiner = Joiner::new(8);
        let out = feed(&mut joiner, [state(0), state(1), state(2), measurements(0)]);
        assert_eq!(out, []);
        let mut rest = vec![];
        while let Some((k, parts)) = joiner.next_remaining() {
            rest.push((k, shape(&parts)));
        }
        assert_eq!(rest, [(0, "sm---".to_string()), (1, "s----".to_string()), (2, "s----".to_string())]);
    }

    #[test]
    fn parts_far_ahead_of_the_next_loop_wait_until_it_reaches_them() {
        let mut joiner = Joiner::new(3);
        let mut out = feed(&mut joiner, whole(0));
        // Loop 9's state comes while the next loop is 1 (a gap on every topic): it settles loops 1
        // to 6 as they are.
        out.extend(feed(&mut joiner, [state(9)]));
        out.extend(feed(&mut joiner, [measurements(9), estimate(9), command(9), record(9)]));
        let shapes: Vec<(u64, &str)> = out.iter().map(|(k, shape)| (*k, shape.as_str())).collect();
        let mut expected = vec![(0, "smecl")];
        expected.extend((1..9).map(|k| (k, "-----")));
        expected.push((9, "smecl"));
        assert_eq!(shapes, expected);
    }

    /// The joiner as it was written first, with every waiting loop in a map: the model the
    /// joiner must behave as.
    struct Model {
        window: u64,
        pending: BTreeMap<u64, LoopParts>,
        next_k: u64,
        newest: PerTopic<Option<u64>>,
    }

    impl Model {
        fn put(&mut self, sample: Sample) -> bool {
            let (k, topic) = sample.key();
            self.newest[topic] = self.newest[topic].max(Some(k));
            if k < self.next_k {
                return false;
            }
            self.pending.entry(k).or_default().put(sample);
            true
        }

        fn next_settled(&mut self) -> Option<(u64, LoopParts)> {
            let newest = Topic::ALL.iter().filter_map(|&t| self.newest[t]).max()?;
            let k = self.next_k;
            let part = self.pending.get(&k);
            let settled =
                Topic::ALL.iter().all(|&t| part.is_some_and(|p| p.has(t)) || self.newest[t].is_some_and(|n| n > k));
            if k > newest || !(settled || newest >= k + self.window) {
                return None;
            }
            self.next_k = k + 1;
            Some((k, self.pending.remove(&k).unwrap_or_default()))
        }
    }

    #[test]
    fn the_joiner_hands_out_what_a_map_of_every_waiting_loop_does() {
        // Random streams: each topic in loop order with parts skipped, the topics interleaved
        // unevenly, jumps far ahead, and parts that come too late.
        let mut seed = 0x2545_F491_4F6C_DD1Du64;
        let mut random = move |n: u64| {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed % n
        };
        for round in 0..200 {
            let window = 1 + random(12);
            let (mut joiner, mut model) = (
                Joiner::new(window),
                Model { window, pending: BTreeMap::new(), next_k: 0, newest: PerTopic::default() },
            );
            let mut next = [0u64; 5];
            for _ in 0..400 {
                let topic = random(5) as usize;
                let k = match random(20) {
                    0 => next[topic] + random(40),
                    1 => next[topic].saturating_sub(random(5)),
                    _ => next[topic] + random(2),
                };
                next[topic] = next[topic].max(k + 1);
                let sample = [state, measurements, estimate, command, record][topic](k);
                assert_eq!(joiner.put(sample), model.put(sample), "round {round}");
                loop {
                    let (got, expected) = (joiner.next_settled(), model.next_settled());
                    assert_eq!(
                        got.as_ref().map(|(k, p)| (*k, shape(p))),
                        expected.as_ref().map(|(k, p)| (*k, shape(p)))
                    );
                    if got.is_none() {
                        break;
                    }
                }
            }
        }
    }

    #[test]
    fn a_restarted_monitor_starts_at_its_first_loop() {
        let mut joiner = Joiner::new(8);
        joiner.start_at(40);
        assert!(!joiner.put(state(39)), "the last monitor's loop");
        let out = feed(&mut joiner, whole(40));
        assert_eq!(out, [(40, "smecl".to_string())]);
    }

    #[test]
    fn latencies_come_from_the_record_stamps() {
        let mut record = LoopRecord::default();
        record.header.trace = crate::contract::msg::LoopTrace {
            plant_publish: 100,
            sensors_receive: 110,
            sensors_publish: 130,
            estimator_receive: 135,
            estimator_publish: 175,
            controller_receive: 180,
            controller_publish: 200,
            plant_receive: 260,
        };
        let parts = LoopParts { record: Some(record), ..Default::default() };
        assert_eq!(parts.end_to_end_ns(), Some(160));
        assert_eq!(parts.hops_ns(), Some([10, 20, 5, 40, 5, 20, 60]));
        assert_eq!(LoopParts::default().hops_ns(), None);
    }
}
