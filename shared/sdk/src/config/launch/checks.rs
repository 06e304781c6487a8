//! The checks of a launch configuration: bounds of the run, its sensors, supervision, wait
//! settings and faults, each error naming the dotted key and where its value came from.

use std::fmt;

use crate::config::error::LaunchError;
use crate::config::faults::{
    FAULT_KINDS, FaultKind, FaultSpec, MAX_BACKOFF_S, MAX_RESTARTS, MAX_STOP_S, MAX_TIMEOUT_S, ON_DEATH_CONTINUE_ROLES,
    OnDeath, Supervision,
};
use crate::config::launch::types::{LaunchConfig, MAX_DURATION_S, MAX_LOOPS, MAX_RATE_HZ, Mode, Origins, PerComponent};
use crate::config::realtime::MAX_PRIORITY;
use crate::config::wait::{MAX_WAIT_US, WaitSettings};
use crate::contract::msg::MAX_SENSORS;
use crate::contract::role::Role;

pub(super) fn check_common(c: &LaunchConfig) -> Result<(), LaunchError> {
    if !(c.rate_hz.is_finite() && c.rate_hz > 0.0) {
        return Err(c.error("rate_hz", format!("must be a positive number of loops per second, got {}", c.rate_hz)));
    }
    if c.rate_hz > MAX_RATE_HZ {
        return Err(c.error("rate_hz", format!("must be at most {MAX_RATE_HZ} Hz, got {}", c.rate_hz)));
    }
    if let Some(deadline_us) = c.deadline_us {
        // Longer than a period would need the plant to keep several loops open at once.
        let period_us = 1e6 / c.rate_hz;
        if !(deadline_us >= 1.0 && deadline_us <= period_us) {
            return Err(c.error(
                "deadline_us",
                format!(
                    "must be from 1 µs to one loop period ({period_us} µs at rate_hz = {}), got {deadline_us}",
                    c.rate_hz
                ),
            ));
        }
    }
    if let Some(us) = c.explain_over_us
        && !(us.is_finite() && us > 0.0 && us <= 3.6e9)
    {
        return Err(c.error("explain_over_us", format!("must be a positive number of µs, at most an hour, got {us}")));
    }
    if c.probe && c.mode == Mode::Lockstep {
        return Err(c.error("probe", "measures timer wake-ups beside a real-time loop, and lockstep has no timer: use mode = \"realtime\" or leave it out"));
    }
    if !(c.duration_s.is_finite() && c.duration_s > 0.0 && c.duration_s <= MAX_DURATION_S) {
        return Err(c.error(
            "duration_s",
            format!("must be a positive number of seconds, at most {MAX_DURATION_S} (a week), got {}", c.duration_s),
        ));
    }
    if c.loops() == 0 {
        return Err(c.error("duration_s", format!("{} s at {} Hz is less than one loop", c.duration_s, c.rate_hz)));
    }
    if c.loops() > MAX_LOOPS {
        return Err(c.error(
            "duration_s",
            format!(
                "{} s at {} Hz is {} loops; at most {MAX_LOOPS} are allowed (shorten the run or lower rate_hz)",
                c.duration_s,
                c.rate_hz,
                c.loops()
            ),
        ));
    }
    if c.sensors.len() > MAX_SENSORS {
        return Err(c.error("sensors", format!("at most {MAX_SENSORS} sensors are supported, got {}", c.sensors.len())));
    }
    let dt = c.dt();
    for (name, s) in &c.sensors {
        let key = |field: &str| format!("sensors.{name}.{field}");
        let ticks = s.period_s * c.rate_hz;
        if !(s.period_s.is_finite() && s.period_s > 0.0) || ticks.round() < 1.0 || (ticks - ticks.round()).abs() > 1e-6
        {
            // A rate changed on the command line breaks a period the user never touched: say
            // which option did it and what to set with it.
            let rate_origin = c.origins.of("rate_hz");
            let fix = if rate_origin != c.origins.file && c.origins.of(&key("period_s")) == c.origins.file {
                format!(
                    "; rate_hz comes from {rate_origin} (--rate): set the sensor's period with it, e.g. --set {}={dt}",
                    key("period_s")
                )
            } else {
                String::new()
            };
            return Err(c.error(
                &key("period_s"),
                format!(
                    "{} s is not a whole multiple of the loop period {dt} s (rate_hz = {}); allowed: {dt}, {}, {}, ...{fix}",
                    s.period_s,
                    c.rate_hz,
                    2.0 * dt,
                    3.0 * dt
                ),
            ));
        }
        // A sensor slower than the run samples once, at loop 0; the bound keeps tick counts small.
        if s.period_s > MAX_DURATION_S {
            return Err(
                c.error(&key("period_s"), format!("must be at most {MAX_DURATION_S} s (a week), got {}", s.period_s))
            );
        }
        if u64::from(s.delay_ticks) > c.loops() {
            return Err(c.error(
                &key("delay_ticks"),
                format!("must be at most the run's {} loops, got {}", c.loops(), s.delay_ticks),
            ));
        }
        if !(s.quantum.is_finite() && s.quantum >= 0.0) {
            return Err(c.error(&key("quantum"), format!("must be 0 (none) or a positive step, got {}", s.quantum)));
        }
        for (field, value) in [("noise_std", &s.noise_std), ("bias", &s.bias)] {
            let values = match value {
                PerComponent::All(v) => vec![*v],
                PerComponent::Each(v) => v.clone(),
            };
            if values.iter().any(|v| !v.is_finite()) || (field == "noise_std" && values.iter().any(|v| *v < 0.0)) {
                return Err(c.error(&key(field), "must be finite (and not negative for noise_std)"));
            }
        }
    }
    Ok(())
}

pub(super) fn check_sensors(c: &LaunchConfig) -> Result<(), LaunchError> {
    for (name, s) in &c.sensors {
        let Some(signal) = c.schema.signal(&s.signal) else {
            let names: Vec<_> = c.schema.signals.iter().map(|sig| sig.name).collect();
            if s.signal.is_empty() {
                return Err(c.error(
                    &format!("sensors.{name}"),
                    format!("has no `signal`: which one it measures; allowed: {}", names.join(", ")),
                ));
            }
            return Err(c.error(
                &format!("sensors.{name}.signal"),
                format!("unknown signal \"{}\"; allowed: {}", s.signal, names.join(", ")),
            ));
        };
        let dim = signal.components.len();
        for (field, value) in [("noise_std", &s.noise_std), ("bias", &s.bias)] {
            if let PerComponent::Each(v) = value
                && v.len() != dim
            {
                return Err(c.error(
                    &format!("sensors.{name}.{field}"),
                    format!(
                        "signal \"{}\" has {dim} components, so give one number or {dim}; got {}",
                        s.signal,
                        v.len()
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// Rejects NaN and ±inf anywhere in `value`, found at dotted `key` (list items by index).
pub(super) fn check_finite(origins: &Origins, key: &str, value: &toml::Value) -> Result<(), LaunchError> {
    let child = |part: &dyn fmt::Display| format!("{key}.{part}");
    match value {
        toml::Value::Float(v) if !v.is_finite() => {
            Err(origins.error(key, format!("must be a finite number, got {v}; nan and inf are not allowed")))
        }
        toml::Value::Table(table) => table.iter().try_for_each(|(k, v)| check_finite(origins, &child(k), v)),
        toml::Value::Array(items) => {
            items.iter().enumerate().try_for_each(|(i, v)| check_finite(origins, &child(&i), v))
        }
        _ => Ok(()),
    }
}

/// Checks the fault against the run; `key` is its dotted key (`faults.2`).
pub(super) fn check_fault(f: &FaultSpec, c: &LaunchConfig, key: &str) -> Result<(), LaunchError> {
    let field = |f: &str| format!("{key}.{f}");
    if f.kind == FaultKind::Cut && c.hosts.remote().is_none() {
        let without: Vec<&str> = FAULT_KINDS.iter().filter(|k| **k != FaultKind::Cut).map(|k| k.name()).collect();
        return Err(c.error(
            &field("kind"),
            format!(
                "a cut needs a link, and no stage is placed on another host (hosts.<stage> = \"<host>\"); allowed \
                 without one: {}",
                without.join(", ")
            ),
        ));
    }
    let targets = f.kind.targets();
    if !f.process.parse::<Role>().is_ok_and(|role| targets.contains(&role)) {
        let allowed: Vec<&str> = targets.iter().map(|r| r.name()).collect();
        return Err(c.error(
            &field("process"),
            format!("a {} fault cannot target \"{}\"; allowed: {}", f.kind.name(), f.process, allowed.join(", ")),
        ));
    }
    if Role::BRIDGES.iter().any(|r| r.name() == f.process) && c.hosts.remote().is_none() {
        return Err(c.error(
            &field("process"),
            format!("no {} runs: no stage is placed on another host (hosts.<stage> = \"<host>\")", f.process),
        ));
    }
    if !(f.at_s.is_finite() && f.at_s >= 0.0 && f.at_s < c.duration_s) {
        return Err(c.error(
            &field("at_s"),
            format!("must be a time within the run, 0 ≤ at_s < {} s, got {}", c.duration_s, f.at_s),
        ));
    }
    if let Some(d) = f.duration_s {
        // A stop lasts wall-clock seconds; the others simulation time, where anything past
        // the run's end means "to the end".
        let (most, what) = if f.kind == FaultKind::Stop {
            (MAX_STOP_S, "wall-clock seconds, at most 3600 (an hour)")
        } else {
            (MAX_DURATION_S, "seconds, at most 604800 (a week; leave it out for \"to the end of the run\")")
        };
        if !(d.is_finite() && d > 0.0 && d <= most) {
            return Err(c.error(&field("duration_s"), format!("must be a positive number of {what}, got {d}")));
        }
    }
    let only = |name: &str, present: bool, kind: FaultKind| -> Result<(), LaunchError> {
        if present && f.kind != kind {
            return Err(c.error(&field(name), format!("applies to {} faults only", kind.name())));
        }
        Ok(())
    };
    only("delay_s", f.delay_s.is_some(), FaultKind::Delay)?;
    only("delay_ticks", f.delay_ticks.is_some(), FaultKind::Delay)?;
    only("probability", f.probability.is_some(), FaultKind::Drop)?;
    only("value", f.value.is_some(), FaultKind::Corrupt)?;
    match f.kind {
        FaultKind::Kill if f.duration_s.is_some() => {
            Err(c.error(&field("duration_s"), "a kill has no duration (the process is restarted, or not)"))
        }
        FaultKind::Stop if f.duration_s.is_none() => {
            Err(c.error(&field("duration_s"), "a stop needs the seconds it lasts before SIGCONT"))
        }
        FaultKind::Delay => match (f.delay_s, f.delay_ticks) {
            (Some(_), Some(_)) | (None, None) => {
                Err(c.error(&field("delay_s"), "give exactly one of delay_s (seconds) and delay_ticks (loops)"))
            }
            (Some(d), None) if !(d.is_finite() && d >= 0.0 && d < c.duration_s) => Err(c.error(
                &field("delay_s"),
                format!("must be 0 or more seconds, less than the run's duration_s = {} s, got {d}", c.duration_s),
            )),
            (None, Some(t)) if u64::from(t) > c.loops() => {
                Err(c.error(&field("delay_ticks"), format!("must be at most the run's {} loops, got {t}", c.loops())))
            }
            _ => Ok(()),
        },
        FaultKind::Drop => match f.probability {
            Some(p) if (0.0..=1.0).contains(&p) => Ok(()),
            Some(p) => Err(c.error(&field("probability"), format!("must be between 0 and 1, got {p}"))),
            None => Err(c.error(&field("probability"), "a drop needs the chance, 0 to 1, that each output is lost")),
        },
        _ => Ok(()),
    }
}

pub(super) fn check_supervision(s: &Supervision, c: &LaunchConfig) -> Result<(), LaunchError> {
    let timeout = |key: &str, v: f64| {
        if v.is_finite() && v > 0.0 && v <= MAX_TIMEOUT_S {
            Ok(())
        } else {
            Err(c.error(
                &format!("supervision.{key}"),
                format!("must be a positive number of seconds, at most {MAX_TIMEOUT_S} (an hour), got {v}"),
            ))
        }
    };
    timeout("stall_timeout_s", s.stall_timeout_s)?;
    timeout("hang_timeout_s", s.hang_timeout_s)?;
    if s.hang_timeout_s <= s.stall_timeout_s {
        return Err(c.error(
            "supervision.hang_timeout_s",
            format!(
                "must be longer than supervision.stall_timeout_s ({} s): a process is stalled before it hangs, got {}",
                s.stall_timeout_s, s.hang_timeout_s
            ),
        ));
    }
    timeout("command_timeout_s", s.command_timeout_s)?;
    timeout("lockstep_stall_s", s.lockstep_stall_s)?;
    timeout("ready_timeout_s", s.ready_timeout_s)?;
    timeout("backoff_reset_s", s.backoff_reset_s)?;
    for role in Role::ALL {
        // The key to blame: the process's own, or the default it took.
        let key = |field: &str| {
            let own = match field {
                "backoff_s" => s.policy_of(role).backoff_s.is_some(),
                _ => s.policy_of(role).max_restarts.is_some(),
            };
            if own { format!("supervision.{role}.{field}") } else { format!("supervision.{field}") }
        };
        let policy = s.policy(role);
        if !(policy.backoff_s.is_finite() && policy.backoff_s >= 0.0 && policy.backoff_s <= MAX_BACKOFF_S) {
            return Err(
                c.error(&key("backoff_s"), format!("must be 0 to {MAX_BACKOFF_S} seconds, got {}", policy.backoff_s))
            );
        }
        let continues = s.policy_of(role).on_death == Some(OnDeath::Continue);
        if continues && role != Role::Monitor && !ON_DEATH_CONTINUE_ROLES.contains(&role) {
            return Err(c.error(
                &format!("supervision.{role}.on_death"),
                format!(
                    "must be \"end\" for the {role}: the loop cannot go on without it (on_death = \"continue\" is \
                     for sensors, estimator and controller)"
                ),
            ));
        }
        if policy.max_restarts > MAX_RESTARTS {
            return Err(c.error(
                &key("max_restarts"),
                format!("must be 0 to {MAX_RESTARTS} restarts per process and run, got {}", policy.max_restarts),
            ));
        }
    }
    Ok(())
}

pub(super) fn check_wait(w: &WaitSettings, config: &LaunchConfig) -> Result<(), LaunchError> {
    for (key, value) in [("wait.lead_us", Some(w.lead_us)), ("wait.spin_cap_us", w.spin_cap_us)] {
        let Some(value) = value else { continue };
        if !(value.is_finite() && (0.0..=MAX_WAIT_US).contains(&value)) {
            return Err(config.error(key, format!("must be 0 to {MAX_WAIT_US} µs (a second), got {value}")));
        }
    }
    Ok(())
}

pub(super) fn check_realtime(config: &LaunchConfig) -> Result<(), LaunchError> {
    match config.realtime.priority {
        Some(p) if !(1..=MAX_PRIORITY).contains(&p) => {
            Err(config
                .error("realtime.priority", format!("must be a SCHED_FIFO priority, 1 to {MAX_PRIORITY}, got {p}")))
        }
        _ => Ok(()),
    }
}
