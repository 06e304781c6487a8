//! The processes that play a recording back in an open-loop replay (`[replay]`,
//! `looplab replay`): the plant sends its recorded states, each stage other than the replayed one
//! its recorded outputs, loop by loop, in lockstep. They run in the same process runners as
//! the live ones (the plant core, the stage runner), so the replay is stamped, recorded and
//! summarised as any run is, over real shared memory or in one process.
//!
//! A loop the recording has no output of a process for (it was dead, or the monitor missed it)
//! is withheld: sent on marked lost, so the stages after it skip it as they skip a dropped
//! loop. The replayed stage itself skips the loops its recording skipped (`[replay] skipped`,
//! `runtime::stage::task::StageRunner`), so that it computes what the recorded one computed.

use anyhow::{Result, bail};

use crate::config::launch::LaunchConfig;
use crate::config::replay::ReplaySpec;
use crate::contract::msg::{Command, Estimate, Measurements, Message, PlantState};
use crate::contract::role::Role;
use crate::model::layout::VectorLayout;
use crate::model::scenario::{Plant, Scenario};
use crate::runtime::replay::recording_reader::{self, RecordedLoop};
use crate::runtime::stage::task::Task;

/// A recording, loaded for the processes that play it back.
pub struct Playback {
    loops: Vec<RecordedLoop>,
    replay: ReplaySpec,
    state_len: usize,
    input_len: usize,
}

impl Playback {
    /// The recording of `config`'s open-loop replay; None when `config` is not one.
    pub fn load(config: &LaunchConfig, scenario: &dyn Scenario) -> Result<Option<Self>> {
        let Some(replay) = config.replay.clone().filter(|r| !r.closed_loop) else { return Ok(None) };
        let layout = VectorLayout::new(config, scenario);
        let loops = recording_reader::load(&replay.recording, &layout, config.loops())?;
        if loops.iter().all(|l| l.state.is_none()) {
            bail!("{}: the recording holds no state of any loop", replay.recording.display());
        }
        Ok(Some(Self { loops, replay, state_len: layout.state.len(), input_len: layout.input.len() }))
    }

    /// Whether `role` plays back in this replay.
    pub fn plays_back(&self, role: Role) -> bool {
        self.replay.plays_back(role)
    }

    /// The plant that sends the recorded states.
    pub fn plant(&self) -> Box<dyn Plant> {
        let states: Vec<Option<PlantState>> = self.loops.iter().map(|l| l.state).collect();
        let withheld = states.iter().map(|state| withheld(state.as_ref())).collect();
        Box::new(RecordedPlant::new(states, withheld, self.state_len, self.input_len))
    }

    fn task<Out: Message>(&self, pick: impl Fn(&RecordedLoop) -> Option<Out>) -> PlaybackTask<Out> {
        let outputs: Vec<Option<Out>> = self.loops.iter().map(&pick).collect();
        let withheld = outputs.iter().map(|out| withheld(out.as_ref())).collect();
        PlaybackTask { outputs, withheld, last: None }
    }

    pub fn sensors(&self) -> PlaybackTask<Measurements> {
        self.task(|l| l.measurements)
    }

    pub fn estimator(&self) -> PlaybackTask<Estimate> {
        self.task(|l| l.estimate)
    }

    pub fn controller(&self) -> PlaybackTask<Command> {
        self.task(|l| l.command)
    }
}

/// Whether a playback sends a loop on marked lost: the recording has no message of it, or
/// one marked lost.
fn withheld(recorded: Option<&impl Message>) -> bool {
    recorded.is_none_or(|m| m.header().lost != 0)
}

/// A stage that sends its recorded output of each loop, whatever its input (its input type is
/// only the topic it listens on).
pub struct PlaybackTask<Out> {
    outputs: Vec<Option<Out>>,
    withheld: Vec<bool>,
    /// The last recorded output sent: a loop the recording has none of sends it again.
    last: Option<Out>,
}

impl<Out: Message> PlaybackTask<Out> {
    fn output(&self, k: u64) -> Option<&Out> {
        self.outputs.get(k as usize).and_then(Option::as_ref)
    }
}

macro_rules! playback_task {
    ($in:ty, $out:ty) => {
        impl Task for PlaybackTask<$out> {
            type In = $in;
            type Out = $out;
            const PLAYS_BACK: bool = true;
            fn process(&mut self, input: &$in, out: &mut $out) -> Result<()> {
                if let Some(recorded) = self.output(input.header().k) {
                    self.last = Some(*recorded);
                }
                if let Some(last) = &self.last {
                    *out = *last;
                }
                Ok(())
            }
            fn withheld(&self, k: u64) -> bool {
                self.withheld.get(k as usize).copied().unwrap_or(true)
            }
        }
    };
}
playback_task!(PlantState, Measurements);
playback_task!(Measurements, Estimate);
playback_task!(Estimate, Command);

/// The plant of an open-loop replay: the recorded state of each tick and the input the
/// recorded actuator applied, whatever the commands; a tick the recording has no state of holds
/// the last, and goes out marked lost.
pub struct RecordedPlant {
    states: Vec<Option<PlantState>>,
    /// Per tick: whether its state goes out marked lost (the recording has none).
    withheld: Vec<bool>,
    k: usize,
    x: Vec<f64>,
    applied: Vec<f64>,
}

impl RecordedPlant {
    fn new(states: Vec<Option<PlantState>>, withheld: Vec<bool>, state_len: usize, input_len: usize) -> Self {
        let first = states.iter().flatten().next().copied().unwrap_or_else(|| unreachable!("checked at load"));
        let mut plant = Self {
            states,
            withheld,
            k: 0,
            x: first.x[..state_len].to_vec(),
            applied: first.u_applied[..input_len].to_vec(),
        };
        plant.take(0);
        plant
    }

    /// Takes the recorded state of tick k, if there is one.
    fn take(&mut self, k: usize) {
        self.k = k;
        if let Some(state) = self.states.get(k).copied().flatten() {
            let (n, m) = (self.x.len(), self.applied.len());
            self.x.copy_from_slice(&state.x[..n]);
            self.applied.copy_from_slice(&state.u_applied[..m]);
        }
    }
}

impl Plant for RecordedPlant {
    fn state(&self) -> &[f64] {
        &self.x
    }

    fn step(&mut self, _t: f64, _u: &[f64], _dt: f64) -> Result<()> {
        self.take(self.k + 1);
        Ok(())
    }

    fn restore(&mut self, state: &[f64]) {
        self.x.copy_from_slice(state);
    }

    fn applied_input(&self) -> Option<&[f64]> {
        Some(&self.applied)
    }

    fn initial_input(&self) -> Option<&[f64]> {
        Some(&self.applied)
    }

    fn withheld(&self, k: u64) -> bool {
        self.withheld.get(k as usize).copied().unwrap_or(true)
    }
}
