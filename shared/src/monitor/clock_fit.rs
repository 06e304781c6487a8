//! The offset and drift of a remote host's clock, fitted from the loops' own stamps (each loop is a free NTP exchange).

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

/// Default length of a fitting window: one minimum-round-trip sample is kept per second of local time.
pub const DEFAULT_WINDOW_NS: u64 = 1_000_000_000;

/// Most the two clocks' rates can differ: Linux slews a clock by at most 500 ppm, crystals err by ~100.
const MAX_DRIFT: f64 = 1e-3;

/// Stretches of windows the uncertainty takes its tightest upper and lower bound points from.
const BOUND_STRETCHES: usize = 32;

/// One NTP exchange: `t1` local send, `t2` remote receive, `t3` remote send, `t4` local receive.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct NtpSample {
    pub t1: u64,
    pub t2: u64,
    pub t3: u64,
    pub t4: u64,
}

impl NtpSample {
    /// Remote minus local clock, exact to within ± `round_trip_ns() / 2`.
    pub fn offset_ns(&self) -> f64 {
        self.twice_offset() as f64 / 2.0
    }

    /// The network round trip: the exchange's local span minus the time it spent on the remote host.
    pub fn round_trip_ns(&self) -> i64 {
        ((self.t4 as i128 - self.t1 as i128) - (self.t3 as i128 - self.t2 as i128)) as i64
    }

    // In integers: stamps near 1e13 ns lose nothing before the reference is subtracted.
    fn twice_offset(&self) -> i128 {
        (self.t2 as i128 - self.t1 as i128) + (self.t3 as i128 - self.t4 as i128)
    }

    /// t2 − t1: at least the offset when the remote host received (the out delay is ≥ 0).
    fn out_bound(&self) -> i128 {
        self.t2 as i128 - self.t1 as i128
    }

    /// t3 − t4: at most the offset when the remote host sent back (the back delay is ≥ 0).
    fn back_bound(&self) -> i128 {
        self.t3 as i128 - self.t4 as i128
    }

    /// Local time of the exchange's middle, relative to `reference`.
    fn midpoint_from(&self, reference: u64) -> f64 {
        ((self.t1 as i128 - reference as i128) + (self.t4 as i128 - reference as i128)) as f64 / 2.0
    }
}

/// The NTP samples of one loop's stamps (flow order, as [`crate::contract::msg::LoopTrace::stamps`]),
/// given the host of each stamp (0 = local, h > 0 = remote host h): one per maximal stretch of stamps on
/// one remote host with a local stamp right before and right after it. A stretch touching either end,
/// next to another remote host, or with any of its four stamps zero (not stamped) gives none.
pub fn ntp_samples(stamps: &[u64; 8], hosts: &[u8; 8]) -> Vec<(u8, NtpSample)> {
    let mut samples = Vec::new();
    let mut start = 0;
    while start < 8 {
        let host = hosts[start];
        let mut end = start;
        while end + 1 < 8 && hosts[end + 1] == host {
            end += 1;
        }
        if host != 0 && start > 0 && end < 7 && hosts[start - 1] == 0 && hosts[end + 1] == 0 {
            let s = NtpSample { t1: stamps[start - 1], t2: stamps[start], t3: stamps[end], t4: stamps[end + 1] };
            if [s.t1, s.t2, s.t3, s.t4].iter().all(|&t| t != 0) {
                samples.push((host, s));
            }
        }
        start = end + 1;
    }
    samples
}

/// A remote clock as seen from the local one: remote = local + `offset_ns` + `drift_ppm`·1e-6·(local − `t_ref_ns`).
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
pub struct ClockFit {
    pub offset_ns: f64,
    pub drift_ppm: f64,
    /// Local time the offset is given at: the mean of the windows' sample times.
    pub t_ref_ns: u64,
    /// Bound on |fitted − true offset| at any local time from the first sample's send to the last one's
    /// receive, for a true clock of constant drift under 1000 ppm; with one window, of no drift.
    pub uncertainty_ns: f64,
    /// Windows with a sample, each giving its smallest-round-trip sample to the fit.
    pub windows: usize,
    pub min_round_trip_ns: f64,
}

impl ClockFit {
    /// Remote minus local at local time `local_ns`.
    pub fn offset_at(&self, local_ns: f64) -> f64 {
        self.offset_ns + self.drift_ppm * 1e-6 * (local_ns - self.t_ref_ns as f64)
    }

    /// A remote stamp on the local clock: solves remote = local + offset_at(local).
    pub fn to_local_ns(&self, remote_ns: u64) -> f64 {
        let remote_from_ref = (remote_ns as i128 - self.t_ref_ns as i128) as f64;
        self.t_ref_ns as f64 + (remote_from_ref - self.offset_ns) / (1.0 + self.drift_ppm * 1e-6)
    }
}

/// Fits one remote host's clock, fed sample by sample. Each window of local time keeps three samples:
/// the smallest round trip (the offset the network blurred least, for the fit) and the smallest
/// `t2 − t1` and largest `t3 − t4` (the tightest one-way bounds, for the uncertainty).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ClockFitter {
    window_ns: u64,
    windows: BTreeMap<u64, Window>,
    first_send: u64,
    last_receive: u64,
}

#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
struct Window {
    best: NtpSample,
    min_out: NtpSample,
    max_back: NtpSample,
}

impl Default for ClockFitter {
    fn default() -> Self {
        Self::new(DEFAULT_WINDOW_NS)
    }
}

impl ClockFitter {
    pub fn new(window_ns: u64) -> Self {
        ClockFitter { window_ns: window_ns.max(1), windows: BTreeMap::new(), first_send: u64::MAX, last_receive: 0 }
    }

    pub fn push(&mut self, s: NtpSample) {
        if s.t4 < s.t1 || s.t3 < s.t2 || s.round_trip_ns() < 0 {
            return; // no real exchange runs backwards: corrupt stamps
        }
        self.first_send = self.first_send.min(s.t1);
        self.last_receive = self.last_receive.max(s.t4);
        let key = (s.t1 + (s.t4 - s.t1) / 2) / self.window_ns;
        let w = self.windows.entry(key).or_insert(Window { best: s, min_out: s, max_back: s });
        if s.round_trip_ns() < w.best.round_trip_ns() {
            w.best = s;
        }
        if s.out_bound() < w.min_out.out_bound() {
            w.min_out = s;
        }
        if s.back_bound() > w.max_back.back_bound() {
            w.max_back = s;
        }
    }

    /// Least squares line through the windows' smallest-round-trip offsets (offset given at their mean
    /// time; drift 0 with one window).
    ///
    /// Uncertainty: the delays are ≥ 0, so the true offset θ is ≤ t2 − t1 when the remote host received
    /// and ≥ t3 − t4 when it sent back. Moved to the local stamps t1 and t4 these widen by
    /// [`MAX_DRIFT`]·(t4 − t1), and by 1 ns for whole-ns stamps. The true line lies below all such
    /// upper points and above all lower ones: a linear programme in two unknowns, so by LP duality its
    /// extreme at a time x0 is set by two points: x0 = w·x_a + (1 − w)·x_b gives θ(x0) ≤ w·v_a + (1 − w)·v_b
    /// when each positive weight is on an upper point and each negative one on a lower point (mirrored
    /// for ≥). Those bounds at both ends of the sampled span, against the fitted line there, bound its
    /// error across the span, the error being linear in time. With one window a line of no drift is
    /// assumed, bounded by the smallest upper and the largest lower point.
    pub fn fit(&self) -> Option<ClockFit> {
        let first = self.windows.values().next()?.best;
        let n = self.windows.len();
        let mean_mid = self.windows.values().map(|w| w.best.midpoint_from(first.t1)).sum::<f64>() / n as f64;
        let t_ref = first.t1 + mean_mid.round() as u64;
        let from_ref = |t: u64| (t as i128 - t_ref as i128) as f64;
        // Offsets relative to the first window's: 1e12-sized values would blur in the sums of squares.
        let from_first = |twice: i128| (twice - first.twice_offset()) as f64 / 2.0;
        let points: Vec<(f64, f64)> =
            self.windows.values().map(|w| (w.best.midpoint_from(t_ref), from_first(w.best.twice_offset()))).collect();
        let mean_x = points.iter().map(|p| p.0).sum::<f64>() / n as f64;
        let mean_y = points.iter().map(|p| p.1).sum::<f64>() / n as f64;
        let sxx: f64 = points.iter().map(|p| (p.0 - mean_x).powi(2)).sum();
        let sxy: f64 = points.iter().map(|p| (p.0 - mean_x) * (p.1 - mean_y)).sum();
        let slope = if n > 1 && sxx > 0.0 { sxy / sxx } else { 0.0 };
        let fitted = |x: f64| mean_y + slope * (x - mean_x);

        let slack = |s: &NtpSample| MAX_DRIFT * (s.t4 - s.t1) as f64 + 1.0;
        let uppers: Vec<(f64, f64)> = self
            .windows
            .values()
            .map(|w| (from_ref(w.min_out.t1), from_first(2 * w.min_out.out_bound()) + slack(&w.min_out)))
            .collect();
        let lowers: Vec<(f64, f64)> = self
            .windows
            .values()
            .map(|w| (from_ref(w.max_back.t4), from_first(2 * w.max_back.back_bound()) - slack(&w.max_back)))
            .collect();
        // Any subset of points gives a valid bound; the tightest of each stretch of windows keeps the work
        // constant however long the run, and still has points across the whole span.
        let chunk = n.div_ceil(BOUND_STRETCHES);
        let tightest = |side: &[(f64, f64)], slack: &dyn Fn(&(f64, f64)) -> f64| -> Vec<(f64, f64)> {
            side.chunks(chunk).filter_map(|c| c.iter().copied().min_by(|a, b| slack(a).total_cmp(&slack(b)))).collect()
        };
        let uppers = tightest(&uppers, &|p| p.1 - fitted(p.0));
        let lowers = tightest(&lowers, &|p| fitted(p.0) - p.1);
        let points: Vec<(f64, f64, bool)> =
            uppers.iter().map(|&(x, v)| (x, v, true)).chain(lowers.iter().map(|&(x, v)| (x, v, false))).collect();

        let error_at = |x0: f64| {
            let (mut lower, mut upper) = (f64::NEG_INFINITY, f64::INFINITY);
            if n == 1 {
                upper = uppers.iter().map(|p| p.1).fold(upper, f64::min);
                lower = lowers.iter().map(|p| p.1).fold(lower, f64::max);
            } else {
                for (i, a) in points.iter().enumerate() {
                    for b in points[i + 1..].iter().filter(|b| b.0 != a.0) {
                        let w = (b.0 - x0) / (b.0 - a.0);
                        let terms = [(w, a), (1.0 - w, b)];
                        let value = w * a.1 + (1.0 - w) * b.1;
                        if terms.iter().all(|(c, p)| *c == 0.0 || (*c > 0.0) == p.2) {
                            upper = upper.min(value);
                        }
                        if terms.iter().all(|(c, p)| *c == 0.0 || (*c > 0.0) != p.2) {
                            lower = lower.max(value);
                        }
                    }
                }
            }
            (upper - fitted(x0)).max(fitted(x0) - lower)
        };
        let uncertainty = error_at(from_ref(self.first_send)).max(error_at(from_ref(self.last_receive)));

        Some(ClockFit {
            offset_ns: first.offset_ns() + fitted(0.0),
            drift_ppm: slope * 1e6,
            t_ref_ns: t_ref,
            uncertainty_ns: uncertainty,
            windows: n,
            min_round_trip_ns: self.windows.values().map(|w| w.best.round_trip_ns()).min().unwrap_or(0) as f64,
        })
    }
}

#[cfg(test)]
mod tests {
    use rand::SeedableRng;
    use rand::distr::{Distribution, Uniform};
    use rand_chacha::ChaCha8Rng;

    use super::*;

    const OFFSET_NS: i64 = 1_000_000_000_000; // a time namespace shifted by 1000 s
    const START_NS: u64 = 5_000_000_000_000; // local monotonic clock after ~1.4 h of uptime

    /// The remote clock at local time `local`: offset plus `ppm` of drift since START_NS, whole ns.
    fn remote(local: u64, ppm: i64) -> u64 {
        (local as i64 + OFFSET_NS + (local - START_NS) as i64 * ppm / 1_000_000) as u64
    }

    /// A remote controller at 1 kHz for `seconds`; returns the fitter and every (sample, true delays out and back).
    fn simulate(seconds: u64, ppm: i64, seed: u64) -> (ClockFitter, Vec<(NtpSample, u64, u64)>) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let out = Uniform::new_inclusive(30_000u64, 400_000).unwrap();
        let back = Uniform::new_inclusive(30_000u64, 900_000).unwrap();
        let compute = Uniform::new_inclusive(5_000u64, 20_000).unwrap();
        let mut fitter = ClockFitter::default();
        let mut exchanges = Vec::new();
        for k in 0..seconds * 1000 {
            let t1 = START_NS + k * 1_000_000;
            let (d_out, c, d_back) = (out.sample(&mut rng), compute.sample(&mut rng), back.sample(&mut rng));
            let t4 = t1 + d_out + c + d_back;
            let s = NtpSample { t1, t2: remote(t1 + d_out, ppm), t3: remote(t1 + d_out + c, ppm), t4 };
            fitter.push(s);
            exchanges.push((s, d_out, d_back));
        }
        (fitter, exchanges)
    }

    fn check_against_truth(seconds: u64, ppm: i64) -> ClockFit {
        let (fitter, exchanges) = simulate(seconds, ppm, 17);
        let fit = fitter.fit().unwrap();
        assert_eq!(fit.windows, seconds as usize);
        let true_offset = |local: f64| OFFSET_NS as f64 + (local - START_NS as f64) * ppm as f64 * 1e-6;
        let (first, last) = (exchanges[0].0.t1 as f64, exchanges.last().unwrap().0.t4 as f64);
        for t in [first, fit.t_ref_ns as f64, last] {
            assert!((fit.offset_at(t) - true_offset(t)).abs() <= fit.uncertainty_ns, "at {t}: {fit:?}");
        }
        assert!((fit.drift_ppm - ppm as f64).abs() * 1e-6 * (last - first) <= 2.0 * fit.uncertainty_ns);
        // Honest, and not much looser than the best exchange allows.
        assert!(fit.uncertainty_ns <= fit.min_round_trip_ns / 2.0 + 5_000.0, "{fit:?}");
        // Corrected crossing hops are the true one-way delays, to within the uncertainty.
        for &(s, d_out, d_back) in &exchanges {
            let (out, back) = (fit.to_local_ns(s.t2) - s.t1 as f64, s.t4 as f64 - fit.to_local_ns(s.t3));
            assert!((out - d_out as f64).abs() <= fit.uncertainty_ns * (1.0 + 1e-3), "{out} vs {d_out}");
            assert!((back - d_back as f64).abs() <= fit.uncertainty_ns * (1.0 + 1e-3), "{back} vs {d_back}");
        }
        fit
    }

    #[test]
    fn offset_and_drift_are_recovered_within_the_stated_uncertainty() {
        let fit = check_against_truth(60, 20);
        assert!((fit.drift_ppm - 20.0).abs() < 1.0, "{fit:?}");
    }

    #[test]
    fn a_shifted_namespace_gives_its_offset_and_no_drift() {
        let fit = check_against_truth(60, 0);
        assert!((fit.offset_ns - OFFSET_NS as f64).abs() <= fit.uncertainty_ns);
    }

    #[test]
    fn one_window_gives_drift_zero_and_its_one_way_bounds() {
        let (fitter, exchanges) = simulate(1, 0, 3);
        let fit = fitter.fit().unwrap();
        assert_eq!((fit.windows, fit.drift_ppm), (1, 0.0));
        let best = exchanges.iter().map(|e| e.0).min_by_key(|s| s.round_trip_ns()).unwrap();
        assert_eq!(fit.offset_ns, best.offset_ns());
        assert_eq!(fit.min_round_trip_ns, best.round_trip_ns() as f64);
        let slack = |s: &NtpSample| MAX_DRIFT * (s.t4 - s.t1) as f64 + 1.0;
        let out = exchanges.iter().map(|e| e.0).min_by_key(|s| s.t2 - s.t1).unwrap();
        let back = exchanges.iter().map(|e| e.0).min_by_key(|s| s.t4 as i64 - s.t3 as i64).unwrap();
        let upper = (out.t2 - out.t1) as f64 + slack(&out) - best.offset_ns();
        let lower = best.offset_ns() - (back.t3 as f64 - back.t4 as f64 - slack(&back));
        assert!((fit.uncertainty_ns - upper.max(lower)).abs() < 1e-3, "{fit:?} {upper} {lower}");
        assert!((fit.offset_ns - OFFSET_NS as f64).abs() <= fit.uncertainty_ns);
        assert!(ClockFitter::default().fit().is_none());
    }

    #[test]
    fn huge_stamps_keep_nanosecond_precision() {
        // Offsets are exact half-integers: 1e13-sized stamps squared in f64 would lose them.
        let base = 9_000_000_000_000u64;
        let s = NtpSample { t1: base, t2: base + 3_000_000_000_101, t3: base + 3_000_000_000_202, t4: base + 300 };
        assert_eq!((s.offset_ns(), s.round_trip_ns()), (3_000_000_000_001.5, 199));
        let mut fitter = ClockFitter::default();
        for k in 0..5u64 {
            let shift = k * DEFAULT_WINDOW_NS + 7;
            fitter.push(NtpSample { t1: s.t1 + shift, t2: s.t2 + shift, t3: s.t3 + shift, t4: s.t4 + shift });
        }
        let fit = fitter.fit().unwrap();
        assert_eq!((fit.offset_ns, fit.drift_ppm, fit.windows), (3_000_000_000_001.5, 0.0, 5));
        assert_eq!(fit.t_ref_ns, base + 2 * DEFAULT_WINDOW_NS + 7 + 150);
        assert_eq!(fit.to_local_ns(s.t2 + 7), (base + 7) as f64 + 99.5);
    }

    #[test]
    fn samples_bracket_each_remote_stretch() {
        let stamps = [10, 20, 30, 40, 50, 1060, 1070, 80];
        let remote_controller = ntp_samples(&stamps, &[0, 0, 0, 0, 0, 1, 1, 0]);
        assert_eq!(remote_controller, vec![(1, NtpSample { t1: 50, t2: 1060, t3: 1070, t4: 80 })]);
        let stamps = [10, 20, 30, 1040, 1050, 1060, 1070, 80];
        let remote_pair = ntp_samples(&stamps, &[0, 0, 0, 2, 2, 2, 2, 0]);
        assert_eq!(remote_pair, vec![(2, NtpSample { t1: 30, t2: 1040, t3: 1070, t4: 80 })]);
        let stamps = [10, 1020, 1030, 40, 50, 1060, 1070, 80];
        let two = ntp_samples(&stamps, &[0, 1, 1, 0, 0, 1, 1, 0]);
        assert_eq!(two.iter().map(|(h, s)| (*h, s.t1, s.t4)).collect::<Vec<_>>(), vec![(1, 10, 40), (1, 50, 80)]);
    }

    #[test]
    fn unstamped_or_unbracketed_stretches_give_none() {
        let partial = [10, 20, 30, 40, 50, 1060, 1070, 0];
        assert!(ntp_samples(&partial, &[0, 0, 0, 0, 0, 1, 1, 0]).is_empty());
        let full = [10, 20, 30, 40, 50, 1060, 1070, 80];
        assert!(ntp_samples(&full, &[0, 0, 0, 0, 0, 0, 1, 1]).is_empty()); // touches the end
        assert!(ntp_samples(&full, &[1, 0, 0, 0, 0, 0, 0, 0]).is_empty()); // touches the start
        assert!(ntp_samples(&full, &[0, 0, 0, 0, 0, 1, 2, 0]).is_empty()); // two hosts back to back
        assert!(ntp_samples(&full, &[0; 8]).is_empty());
    }
}
