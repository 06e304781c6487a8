//! The restart policy: whether a process that died starts again, and after what backoff. A pure
//! function of what the supervisor knows at the death; no clock is read here.

use std::time::Duration;

use crate::config::faults::{Policy, Restart};
use crate::contract::role::Role;

/// The backoff doubles with each quick restart up to this.
pub const MAX_BACKOFF: Duration = Duration::from_secs(1);

/// Quick deaths in a row with the same last words after which a process is not restarted: a
/// crash loop (a deterministic error in its first steps), which another restart would repeat.
pub const CRASH_LOOP_DEATHS: u32 = 3;

/// What the supervisor knows of a process whose output just ended.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Death {
    /// It exited with status 0.
    pub clean: bool,
    /// Its restarts so far in this run.
    pub restarts: u32,
    /// Its restarts since it last ran healthy: each doubles the backoff.
    pub quick_restarts: u32,
    /// Wall-clock seconds it ran since it was last ready (None: it never was).
    pub ran_s: Option<f64>,
    /// It stopped because its disk is full (`contract::protocol::EXIT_DISK_FULL`).
    pub disk_full: bool,
    /// Its deaths in a row, this one included, that came before it ran healthy and ended with
    /// the same last line on stderr, numbers aside (0: it said nothing, or something new).
    pub same_failure_in_a_row: u32,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Decision {
    /// Start it again once `backoff` has passed; it then has `quick_restarts` quick restarts.
    Restart { backoff: Duration, quick_restarts: u32 },
    /// Its policy does not restart it after this death.
    NotWanted(Restart),
    /// It would be restarted, but has had its `max_restarts` already.
    TooMany { max_restarts: u32 },
    /// Its disk is full: a restart would only fill it again.
    DiskFull,
    /// It failed the same way on its last `deaths` starts, each before it ran healthy.
    CrashLoop { deaths: u32 },
}

impl Decision {
    /// Why it is not restarted, after the text of how it died.
    pub fn refusal(&self) -> Option<String> {
        match self {
            Decision::Restart { .. } => None,
            Decision::NotWanted(restart) => Some(format!("not restarted (restart = {})", restart_text(*restart))),
            Decision::TooMany { max_restarts } => {
                Some(format!("not restarted: it reached supervision max_restarts = {max_restarts}"))
            }
            Decision::DiskFull => Some("not restarted: its disk is full".into()),
            Decision::CrashLoop { deaths } => Some(format!(
                "not restarted: a crash loop, the same error on each of its last {deaths} starts before it ran \
                 healthy (supervision.backoff_reset_s); another restart would repeat it"
            )),
        }
    }
}

/// Whether and when a process starts again. A process that ran `backoff_reset_s` since it was
/// last ready counts as healthy: its backoff starts again from `policy.backoff_s`.
pub fn decide(policy: &Policy, backoff_reset_s: f64, death: Death) -> Decision {
    let wanted = match policy.restart {
        Restart::Never => false,
        Restart::OnFailure => !death.clean,
        Restart::Always => true,
    };
    if !wanted {
        return Decision::NotWanted(policy.restart);
    }
    if death.disk_full {
        return Decision::DiskFull;
    }
    if death.same_failure_in_a_row >= CRASH_LOOP_DEATHS {
        return Decision::CrashLoop { deaths: death.same_failure_in_a_row };
    }
    if death.restarts >= policy.max_restarts {
        return Decision::TooMany { max_restarts: policy.max_restarts };
    }
    let healthy = death.ran_s.is_some_and(|s| s >= backoff_reset_s);
    let quick = if healthy { 0 } else { death.quick_restarts };
    // backoff_s is checked at load to be a small number of seconds.
    let backoff = Duration::try_from_secs_f64(policy.backoff_s)
        .unwrap_or(MAX_BACKOFF)
        .saturating_mul(1 << quick.min(20))
        .min(MAX_BACKOFF);
    Decision::Restart { backoff, quick_restarts: quick + 1 }
}

/// The policy's name as the launch file spells it.
fn restart_text(restart: Restart) -> String {
    serde_json::to_value(restart).ok().and_then(|v| v.as_str().map(String::from)).unwrap_or_default()
}

/// The steps of one restart (CLOCK_MONOTONIC, ns), for the report.
#[derive(Debug, Clone, PartialEq)]
pub struct RestartRecord {
    pub process: Role,
    /// The incarnation it starts.
    pub incarnation: u32,
    pub backoff: Duration,
    pub died_ns: u64,
    pub cleaned_ns: Option<u64>,
    pub spawned_ns: Option<u64>,
    pub ready_ns: Option<u64>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::faults::OnDeath;

    const ON_FAILURE: Policy =
        Policy { restart: Restart::OnFailure, on_death: OnDeath::End, max_restarts: 10, backoff_s: 0.01 };

    fn killed(restarts: u32, quick_restarts: u32, ran_s: Option<f64>) -> Death {
        Death { clean: false, restarts, quick_restarts, ran_s, disk_full: false, same_failure_in_a_row: 0 }
    }

    fn ms(ms: u64) -> Duration {
        Duration::from_millis(ms)
    }

    /// The backoffs of a process killed again and again without ever running `backoff_reset_s`.
    fn backoffs(policy: &Policy, deaths: u32) -> Vec<Duration> {
        let mut quick = 0;
        (0..deaths)
            .map(|restarts| match decide(policy, 1.0, killed(restarts, quick, Some(0.1))) {
                Decision::Restart { backoff, quick_restarts } => {
                    quick = quick_restarts;
                    backoff
                }
                other => panic!("restart {restarts}: {other:?}"),
            })
            .collect()
    }

    /// The third quick death in a row with the same words is a crash loop, whatever the
    /// restarts left; fewer are restarted.
    #[test]
    fn the_same_failure_three_times_in_a_row_is_not_restarted() {
        let death = |same| Death { same_failure_in_a_row: same, ..killed(2, 2, Some(0.01)) };
        assert!(matches!(decide(&ON_FAILURE, 1.0, death(2)), Decision::Restart { .. }));
        assert_eq!(decide(&ON_FAILURE, 1.0, death(3)), Decision::CrashLoop { deaths: 3 });
        assert!(Decision::CrashLoop { deaths: 3 }.refusal().unwrap().starts_with("not restarted: a crash loop"));
    }

    #[test]
    fn the_backoff_doubles_up_to_one_second() {
        assert_eq!(
            backoffs(&ON_FAILURE, 9),
            [ms(10), ms(20), ms(40), ms(80), ms(160), ms(320), ms(640), ms(1000), ms(1000)]
        );
        let big = Policy { backoff_s: 60.0, ..ON_FAILURE };
        assert_eq!(backoffs(&big, 2), [MAX_BACKOFF, MAX_BACKOFF]);
        let none = Policy { backoff_s: 0.0, ..ON_FAILURE };
        assert_eq!(backoffs(&none, 2), [Duration::ZERO, Duration::ZERO]);
    }

    #[test]
    fn a_process_that_ran_backoff_reset_s_starts_again_from_the_first_backoff() {
        assert_eq!(
            decide(&ON_FAILURE, 1.0, killed(4, 4, Some(1.0))),
            Decision::Restart { backoff: ms(10), quick_restarts: 1 }
        );
        assert_eq!(
            decide(&ON_FAILURE, 1.0, killed(4, 4, Some(0.999))),
            Decision::Restart { backoff: ms(160), quick_restarts: 5 }
        );
        // Never ready since its last start: not healthy.
        assert_eq!(
            decide(&ON_FAILURE, 1.0, killed(4, 4, None)),
            Decision::Restart { backoff: ms(160), quick_restarts: 5 }
        );
    }

    #[test]
    fn max_restarts_is_the_last_one() {
        let two = Policy { max_restarts: 2, ..ON_FAILURE };
        assert!(matches!(decide(&two, 1.0, killed(1, 1, None)), Decision::Restart { .. }));
        let refused = decide(&two, 1.0, killed(2, 2, None));
        assert_eq!(refused, Decision::TooMany { max_restarts: 2 });
        assert_eq!(refused.refusal().unwrap(), "not restarted: it reached supervision max_restarts = 2");
        let zero = Policy { max_restarts: 0, ..ON_FAILURE };
        assert_eq!(decide(&zero, 1.0, killed(0, 0, None)), Decision::TooMany { max_restarts: 0 });
    }

    #[test]
    fn each_policy_restarts_what_it_says() {
        let clean = Death { clean: true, ..killed(0, 0, Some(5.0)) };
        let never = Policy { restart: Restart::Never, ..ON_FAILURE };
        let always = Policy { restart: Restart::Always, ..ON_FAILURE };
        assert_eq!(decide(&never, 1.0, killed(0, 0, None)), Decision::NotWanted(Restart::Never));
        assert_eq!(decide(&never, 1.0, killed(0, 0, None)).refusal().unwrap(), "not restarted (restart = never)");
        assert_eq!(decide(&ON_FAILURE, 1.0, clean), Decision::NotWanted(Restart::OnFailure));
        assert_eq!(decide(&ON_FAILURE, 1.0, clean).refusal().unwrap(), "not restarted (restart = on-failure)");
        assert_eq!(decide(&always, 1.0, clean), Decision::Restart { backoff: ms(10), quick_restarts: 1 });
        assert_eq!(decide(&always, 1.0, clean).refusal(), None);
    }

    #[test]
    fn a_process_whose_disk_is_full_is_not_restarted_into_it() {
        let full = Death { disk_full: true, ..killed(0, 0, Some(5.0)) };
        let always = Policy { restart: Restart::Always, ..ON_FAILURE };
        assert_eq!(decide(&always, 1.0, full), Decision::DiskFull);
        assert_eq!(decide(&always, 1.0, full).refusal().unwrap(), "not restarted: its disk is full");
    }
}
