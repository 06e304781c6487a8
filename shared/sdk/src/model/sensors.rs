//! The multi-rate sensor emulator.
//!
//! Each sensor samples the truth at its own instants (every `period_s`, a whole number of loop
//! ticks, from tick 0), adds its bias and Gaussian noise, quantises, and delivers the value
//! `delay_ticks` later. (In real-time mode the sensors process can miss a tick; a sensor whose
//! instant fell on it samples at the next tick it sees, with that tick's time as sample time.) Between deliveries it holds the last value (zero-order hold). Every
//! tick, every sensor's held value is published with its sample time, sequence number and a
//! fresh flag. Noise comes from one ChaCha8 generator per sensor, seeded from the run's seed
//! and the sensor's name, so a run is reproducible and adding a sensor does not change the
//! others' noise.

use std::collections::VecDeque;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use crate::config::launch::LaunchConfig;
use crate::config::seed::fnv1a;
use crate::contract::msg::{MAX_SENSOR_DIM, SensorReading};
use crate::model::vectors::{Read, Signal};

struct EmulatedSensor {
    read: Read,
    dim: usize,
    period_ticks: u64,
    delay_ticks: u64,
    bias: Vec<f64>,
    noise_std: Vec<f64>,
    quantum: f64,
    rng: ChaCha8Rng,
    /// Samples taken but not yet delivered: (delivery tick, value, sample time).
    in_flight: VecDeque<(u64, [f64; MAX_SENSOR_DIM], f64)>,
    /// The first tick at or after which the next sample is due.
    next_sample: u64,
    held: SensorReading,
    delivered: u64,
}

pub struct SensorEmulator {
    sensors: Vec<EmulatedSensor>,
}

impl SensorEmulator {
    /// One emulated sensor per sensor of `config`, reading the scenario's `signals` (the
    /// launch file was checked to name only these).
    pub fn new(config: &LaunchConfig, signals: &[Signal]) -> Self {
        let sensors = config
            .sensors
            .iter()
            .map(|(name, spec)| {
                let signal =
                    signals.iter().find(|s| s.name == spec.signal).expect("sensor signals are checked at load");
                let dim = signal.components.len();
                EmulatedSensor {
                    read: signal.read,
                    dim,
                    period_ticks: config.period_ticks(spec),
                    delay_ticks: u64::from(spec.delay_ticks),
                    bias: spec.bias.expand(dim),
                    noise_std: spec.noise_std.expand(dim),
                    quantum: spec.quantum,
                    rng: ChaCha8Rng::seed_from_u64(config.seed ^ fnv1a(name)),
                    in_flight: VecDeque::new(),
                    next_sample: 0,
                    held: SensorReading::default(),
                    delivered: 0,
                }
            })
            .collect();
        Self { sensors }
    }

    /// Advances to tick `k` (simulation time `t`, true state `x`, the input the actuator
    /// applied over the last interval `u_applied`) and writes every sensor's held reading into
    /// `out`.
    pub fn tick(&mut self, k: u64, t: f64, x: &[f64], u_applied: &[f64], out: &mut [SensorReading]) {
        for (sensor, out) in self.sensors.iter_mut().zip(out.iter_mut()) {
            if k >= sensor.next_sample {
                sensor.next_sample = (k / sensor.period_ticks + 1) * sensor.period_ticks;
                let mut value = [0.0; MAX_SENSOR_DIM];
                sensor.read.apply(t, x, u_applied, &mut value[..sensor.dim]);
                for ((v, bias), std) in value.iter_mut().zip(&sensor.bias).zip(&sensor.noise_std) {
                    let noise: f64 = StandardNormal.sample(&mut sensor.rng);
                    let measured = *v + bias + std * noise;
                    *v = if sensor.quantum > 0.0 {
                        (measured / sensor.quantum).round() * sensor.quantum
                    } else {
                        measured
                    };
                }
                sensor.in_flight.push_back((k + sensor.delay_ticks, value, t));
            }
            sensor.held.fresh = 0;
            while let Some(&(due, value, sample_time)) = sensor.in_flight.front() {
                if due > k {
                    break;
                }
                sensor.in_flight.pop_front();
                sensor.held = SensorReading { value, sample_time, seq: sensor.delivered, fresh: 1, valid: 1 };
                sensor.delivered += 1;
            }
            *out = sensor.held;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::launch::{Override, resolve_config};
    use crate::config::schema::{Component, ScenarioSchema};

    const RAD: &[Component] = &[Component::new("theta", "rad")];
    const RAD_S: &[Component] = &[Component::new("wheel_speed", "rad/s")];
    /// The pendulum's two signals, and one that reads time and the applied input.
    const SIGNALS: &[Signal] = &[
        Signal { name: "theta", components: RAD, read: Read::Computed(|_, x, _, out| out[0] = x[0]) },
        Signal { name: "wheel_speed", components: RAD_S, read: Read::Computed(|_, x, _, out| out[0] = x[2]) },
        Signal {
            name: "known_input",
            components: &[Component::new("t", "s"), Component::new("u", "A")],
            read: Read::Computed(|t, _, u, out| out[..2].copy_from_slice(&[t, u[0]])),
        },
    ];

    /// The pendulum's default launch file, resolved against [`SIGNALS`] (no scenario is built).
    fn emulator(sets: &[&str]) -> (SensorEmulator, LaunchConfig) {
        let schema = ScenarioSchema {
            name: "pendulum",
            file: "launch/pendulum.toml",
            text: include_str!("../../../../launch/pendulum.toml"),
            state: &[],
            input: &[],
            estimate: &[],
            signals: SIGNALS.iter().map(Signal::layout).collect(),
        };
        let overrides: Vec<_> = sets.iter().map(|s| Override::parse(s).unwrap()).collect();
        let config = resolve_config("pendulum", &overrides, &[schema]).unwrap();
        (SensorEmulator::new(&config, SIGNALS), config)
    }

    /// A made-up truth whose θ and wheel speed change every tick.
    fn truth(k: u64) -> [f64; 3] {
        let t = k as f64 * 1e-3;
        [0.3 * (7.0 * t).sin(), 0.0, 10.0 * t]
    }

    #[test]
    fn held_values_change_only_at_sample_instants_and_equal_quantised_truth_plus_bias() {
        let (mut emu, config) = emulator(&[
            "sensors.wheel_speed.noise_std=0.0",
            "sensors.wheel_speed.bias=0.5",
            "sensors.wheel_speed.quantum=0.25",
            "sensors.wheel_speed.period_s=0.005",
        ]);
        let q = config.sensors["encoder"].quantum;
        let mut out = [SensorReading::default(); 2];
        let mut previous = out;
        for k in 0..200 {
            let x = truth(k);
            emu.tick(k, k as f64 * 1e-3, &x, &[], &mut out);
            // Encoder: every tick, q(θ + 0.1).
            assert_eq!(out[0].fresh, 1);
            assert_eq!(out[0].value[0], ((x[0] + 0.1) / q).round() * q);
            assert_eq!(out[0].seq, k);
            // Wheel speed: every 5 ticks, q(φ̇ + 0.5); held in between.
            if k % 5 == 0 {
                assert_eq!(out[1].fresh, 1, "tick {k}");
                assert_eq!(out[1].value[0], ((x[2] + 0.5) / 0.25).round() * 0.25);
                assert_eq!(out[1].sample_time, k as f64 * 1e-3);
                assert_eq!(out[1].seq, k / 5);
            } else {
                assert_eq!(out[1].fresh, 0, "tick {k}");
                assert_eq!(out[1], SensorReading { fresh: 0, ..previous[1] });
            }
            previous = out;
        }
    }

    #[test]
    fn transport_delay_shifts_delivery_and_keeps_the_sample_time() {
        let (mut emu, _) = emulator(&["sensors.wheel_speed.noise_std=0.0", "sensors.wheel_speed.delay_ticks=3"]);
        let mut out = [SensorReading::default(); 2];
        for k in 0..40 {
            emu.tick(k, k as f64 * 1e-3, &truth(k), &[], &mut out);
            let speed = out[1];
            if k < 3 {
                assert_eq!(speed.valid, 0, "nothing has arrived yet at tick {k}");
                continue;
            }
            let sampled_at = (k - 3) / 10 * 10;
            assert_eq!(speed.fresh, u32::from((k - 3) % 10 == 0), "tick {k}");
            assert_eq!(speed.value[0], truth(sampled_at)[2], "tick {k}");
            assert_eq!(speed.sample_time, sampled_at as f64 * 1e-3);
        }
    }

    #[test]
    fn a_sample_instant_the_process_never_saw_is_taken_at_the_next_tick() {
        let (mut emu, _) = emulator(&["sensors.wheel_speed.noise_std=0.0"]);
        let mut out = [SensorReading::default(); 2];
        for k in (0..30).filter(|k| *k != 10) {
            emu.tick(k, k as f64 * 1e-3, &truth(k), &[], &mut out);
            let speed = out[1];
            let sampled_at = match k {
                0..=9 => 0,
                11..=19 => 11,
                _ => 20,
            };
            assert_eq!(speed.fresh, u32::from(k == sampled_at), "tick {k}");
            assert_eq!(speed.value[0], truth(sampled_at)[2], "tick {k}");
            assert_eq!(speed.sample_time, sampled_at as f64 * 1e-3);
        }
    }

    #[test]
    fn noise_is_seeded_per_sensor() {
        let run = |seed: &str| {
            let (mut emu, _) = emulator(&["sensors.encoder.noise_std=0.01", "sensors.encoder.quantum=0.0", seed]);
            let mut out = [SensorReading::default(); 2];
            (0..50)
                .map(|k| {
                    emu.tick(k, 0.0, &[0.0; 3], &[], &mut out);
                    out[0].value[0]
                })
                .collect::<Vec<_>>()
        };
        let a = run("seed=7");
        assert_eq!(a, run("seed=7"));
        assert_ne!(a, run("seed=8"));
        let mean = a.iter().sum::<f64>() / 50.0;
        let std = (a.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / 49.0).sqrt();
        assert!((mean - 0.1).abs() < 0.005 && (std - 0.01).abs() < 0.004, "mean {mean}, std {std}");
    }

    #[test]
    fn a_signal_may_read_time_and_the_applied_input() {
        let (mut emu, _) = emulator(&[
            "sensors.wheel_speed.signal=known_input",
            "sensors.wheel_speed.noise_std=0.0",
            "sensors.wheel_speed.period_s=0.002",
            "sensors.wheel_speed.delay_ticks=1",
        ]);
        let mut out = [SensorReading::default(); 2];
        for k in 0..10 {
            let (t, u) = (k as f64 * 1e-3, [0.5 * k as f64]);
            emu.tick(k, t, &truth(k), &u, &mut out);
            // Sampled at even ticks, delivered one tick later: (t, u) of the sample instant.
            let sampled_at = (k.max(1) - 1) / 2 * 2;
            assert_eq!(out[1].value[..2], [sampled_at as f64 * 1e-3, 0.5 * sampled_at as f64], "tick {k}");
            assert_eq!(out[1].fresh, u32::from(k % 2 == 1), "tick {k}");
        }
    }
}
