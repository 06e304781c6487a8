//! A scenario's vectors, declared once: the names, units and sizes of its true state, its
//! input, its estimate, and each signal its sensors can measure with how it is read from the
//! truth. Column headers, message sizes and launch-file checks all derive from this.

pub use crate::config::schema::{Component, SignalLayout};

/// How a signal is read from the truth at simulation time `t`: the true state `x` and the
/// input the actuator applied over the last interval (an accelerometer or a known force needs
/// it), into `out` (one value per component). The emulator then adds bias and noise.
pub type ReadSignal = fn(t: f64, x: &[f64], u_applied: &[f64], out: &mut [f64]);

/// How a signal is read: computed by the scenario's code, or picked component by component
/// (a declared system's sensor, `reads = ["state.theta", "input.current"]`).
#[derive(Clone, Copy)]
pub enum Read {
    Computed(ReadSignal),
    Picks(&'static [Pick]),
}

/// One component a declared sensor reads: of the state message (the state, then the plant's
/// outputs) or of the applied input, by index.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pick {
    State(usize),
    Input(usize),
}

impl Read {
    /// The signal at `t` from the true state `x` and the applied input, into `out`.
    pub fn apply(&self, t: f64, x: &[f64], u_applied: &[f64], out: &mut [f64]) {
        match self {
            Read::Computed(read) => read(t, x, u_applied, out),
            Read::Picks(picks) => {
                for (out, pick) in out.iter_mut().zip(picks.iter()) {
                    *out = match *pick {
                        Pick::State(i) => x[i],
                        Pick::Input(i) => u_applied[i],
                    };
                }
            }
        }
    }
}

/// Something a sensor can measure: named components read from the truth.
pub struct Signal {
    pub name: &'static str,
    /// One per component; a scalar signal has one.
    pub components: &'static [Component],
    pub read: Read,
}

impl Signal {
    pub fn layout(&self) -> SignalLayout {
        SignalLayout { name: self.name, components: self.components }
    }
}

/// Every vector of one scenario.
pub struct Vectors {
    pub state: &'static [Component],
    /// The input's limits depend on the launch file: [`crate::model::scenario::ScenarioParts::input_limits`].
    pub input: &'static [Component],
    pub estimate: &'static [Component],
    pub signals: &'static [Signal],
}

impl Vectors {
    pub fn signal(&self, name: &str) -> Option<&'static Signal> {
        self.signals.iter().find(|s| s.name == name)
    }
}

/// Concatenates component tables at compile time (a scenario's state and estimate share parts).
pub const fn concat<const N: usize>(parts: &[&[Component]]) -> [Component; N] {
    let mut out = [Component::new("", ""); N];
    let (mut i, mut n) = (0, 0);
    while i < parts.len() {
        let mut j = 0;
        while j < parts[i].len() {
            out[n] = parts[i][j];
            (j, n) = (j + 1, n + 1);
        }
        i += 1;
    }
    assert!(n == N, "the parts do not add up to the vector's length");
    out
}
