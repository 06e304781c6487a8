//! The launch file's gains checked without the solver: each loop's closed-loop poles in its
//! region, its H∞ norm (a frequency sweep) below the √γ̂ and its H₂ norm (a Lyapunov equation)
//! below the bound the tool reported, so a mistyped gain fails.

use super::*;
use nalgebra::DVector;

const G_OVER_L: f64 = 9.81 / 0.5;

/// The launch file's `[controller]` gains, read as numbers (not through `controller`, which
/// imports this module).
struct Gains {
    xy_gains: Vec<f64>,
    swing_gains: Vec<f64>,
    z_gains: Vec<f64>,
    attitude_gains: Vec<f64>,
    yaw_gains: Vec<f64>,
}

fn section() -> Gains {
    let file: toml::Table =
        toml::from_str(include_str!("../../../../../launch/tiltrotor.toml")).expect("launch/tiltrotor.toml parses");
    let key = |k: &str| -> Vec<f64> { file["controller"][k].clone().try_into().expect("a list of numbers") };
    Gains {
        xy_gains: key("xy_gains"),
        swing_gains: key("swing_gains"),
        z_gains: key("z_gains"),
        attitude_gains: key("attitude_gains"),
        yaw_gains: key("yaw_gains"),
    }
}

/// One loop of (51): model, Table 3's weights, its region and the tool's bounds.
struct Design {
    name: &'static str,
    a: DMatrix<f64>,
    b: DMatrix<f64>,
    b_pi: DMatrix<f64>,
    cz: DMatrix<f64>,
    duz: DMatrix<f64>,
    dpiz: DMatrix<f64>,
    region: Region,
    gains: Vec<f64>,
    /// √γ̂ and the H₂ bound √tr(N) the tool printed.
    hinf_bound: f64,
    h2_bound: f64,
}

fn col(v: &[f64]) -> DMatrix<f64> {
    DMatrix::from_column_slice(v.len(), 1, v)
}

fn diag(v: &[f64]) -> DMatrix<f64> {
    DMatrix::from_diagonal(&DVector::from_column_slice(v))
}

fn designs() -> Vec<Design> {
    let s = section();
    let five_cz = diag(&[0.1, 1.0, 0.25, 25.0, 1.0 / 0.09]);
    let five_duz = col(&[0.5, 0.1, 0.1, 0.1, 0.1]);
    let five_dpiz = col(&[0.1, 0.1, 0.1, 0.1, 1.0]);
    let chain_design = |name, gains: &[f64], weights: [&DMatrix<f64>; 3], region, bounds: (f64, f64)| {
        let (a, b) = chain(gains.len());
        Design {
            name,
            a,
            b: b.clone(),
            b_pi: b,
            cz: weights[0].clone(),
            duz: weights[1].clone(),
            dpiz: weights[2].clone(),
            region,
            gains: gains.to_vec(),
            hinf_bound: bounds.0,
            h2_bound: bounds.1,
        }
    };
    let swing_b = col(&[0.0, -1.0]);
    vec![
        chain_design(
            "x, y",
            &s.xy_gains,
            [&diag(&[0.1, 1.0, 0.25]), &col(&[0.5, 0.1, 0.1]), &col(&[0.1, 0.1, 1.0])],
            X_REGION,
            BOUNDS[0],
        ),
        Design {
            name: "swing",
            a: DMatrix::from_row_slice(2, 2, &[0.0, 1.0, 0.0, 0.0]),
            b: swing_b.clone(),
            b_pi: swing_b,
            cz: diag(&[0.1, 1.0]),
            duz: col(&[0.5, 0.1]),
            dpiz: col(&[0.1, 0.1]),
            region: SWING_REGION,
            gains: s.swing_gains.to_vec(),
            hinf_bound: BOUNDS[1].0,
            h2_bound: BOUNDS[1].1,
        },
        chain_design("z", &s.z_gains, [&five_cz, &five_duz, &five_dpiz], Z_REGION, BOUNDS[2]),
        chain_design(
            "φ, θ",
            &s.attitude_gains,
            [
                &diag(&[1500.0, 1000.0, 4.0, 1.0 / 0.49, 1.0 / 0.09]),
                &col(&[0.05, 0.001, 0.1, 0.1, 1.3]),
                &col(&[0.3, 0.01, 0.01, 1.0, 1.0]),
            ],
            ATTITUDE_DESIGN_REGION,
            BOUNDS[3],
        ),
        chain_design("ψ", &s.yaw_gains, [&five_cz, &five_duz, &five_dpiz], YAW_REGION, BOUNDS[4]),
    ]
}

/// (√γ̂, the H₂ bound) of x y, swing, z, φ θ, ψ as `tiltrotor-gains` printed them (the launch
/// file's comments).
const BOUNDS: [(f64, f64); 5] =
    [(2.184358, 4.063625), (1.765541, 2.805185), (1.321691, 8.985782), (1.933035, 17.828620), (3.016288, 12.235121)];

/// φ, θ's region as designed: Table 2's with α = −15 and the disk's radius 60 (the launch file
/// says why).
const ATTITUDE_DESIGN_REGION: Region = Region { alpha: -15.0, radius: 60.0, ..ATTITUDE_REGION };

impl Design {
    fn closed_loop(&self) -> DMatrix<f64> {
        &self.a + &self.b * DMatrix::from_row_slice(1, self.gains.len(), &self.gains)
    }

    fn output(&self) -> DMatrix<f64> {
        &self.cz + &self.duz * DMatrix::from_row_slice(1, self.gains.len(), &self.gains)
    }

    /// sup over ω of |T(jω)| (one input: the column's norm), on a log grid refined about its peak.
    fn hinf_norm(&self) -> f64 {
        let n = self.a.nrows();
        let a = self.closed_loop().map(|v| Complex::new(v, 0.0));
        let c = self.output().map(|v| Complex::new(v, 0.0));
        let b = self.b_pi.map(|v| Complex::new(v, 0.0));
        let d = self.dpiz.map(|v| Complex::new(v, 0.0));
        let gain = |w: f64| {
            let m = DMatrix::<Complex<f64>>::identity(n, n) * Complex::new(0.0, w) - &a;
            let x = m.lu().solve(&b).expect("jω not a pole");
            (&c * x + &d).norm()
        };
        let grid = |lo: f64, hi: f64, k: usize| (0..=k).map(move |i| lo * (hi / lo).powf(i as f64 / k as f64));
        let (mut peak, mut at) = (gain(0.0), 0.0);
        for w in grid(1e-3, 1e4, 4000) {
            if gain(w) > peak {
                (peak, at) = (gain(w), w);
            }
        }
        if at > 0.0 {
            for w in grid(at * 0.99, at * 1.01, 400) {
                peak = peak.max(gain(w));
            }
        }
        peak
    }

    /// ‖(C_z + D_uz K)(sI − A_cl)⁻¹B_π‖₂ (the H₂ output has D_πz = 0): tr(C P Cᵀ) with
    /// A P + P Aᵀ + B Bᵀ = 0, by Kronecker products.
    fn h2_norm(&self) -> f64 {
        let n = self.a.nrows();
        let a = self.closed_loop();
        let eye = DMatrix::<f64>::identity(n, n);
        let lhs = eye.kronecker(&a) + a.kronecker(&eye);
        let q = -(&self.b_pi * self.b_pi.transpose());
        let p = lhs.lu().solve(&DVector::from_column_slice(q.as_slice())).expect("A_cl stable");
        let p = DMatrix::from_column_slice(n, n, p.as_slice());
        let c = self.output();
        (&c * p * c.transpose()).trace().sqrt()
    }
}

#[test]
fn every_loop_meets_its_region_and_the_tools_norm_bounds() {
    for d in designs() {
        let poles = closed_loop_poles(&d.a, &d.b, &d.gains);
        for p in &poles {
            assert!(d.region.holds(*p), "{}: pole {p} outside {:?}: {poles:?}", d.name, d.region);
        }
        let hinf = d.hinf_norm();
        assert!(hinf < d.hinf_bound, "{}: ‖T‖∞ = {hinf} ≥ √γ̂ = {}", d.name, d.hinf_bound);
        let h2 = d.h2_norm();
        assert!(h2 < d.h2_bound, "{}: ‖T‖₂ = {h2} ≥ {}", d.name, d.h2_bound);
    }
}

/// The norms by frequency sweep and by Lyapunov against closed forms on a first-order loop:
/// ė = −e + π, z = [e; π]: |T(jω)|² = 1/(1 + ω²) + 1 peaks at √2 (ω = 0); ‖e‖₂² = 1/2.
#[test]
fn the_norms_match_a_closed_form() {
    let d = Design {
        name: "first order",
        a: DMatrix::from_element(1, 1, -1.0),
        b: DMatrix::zeros(1, 1),
        b_pi: DMatrix::from_element(1, 1, 1.0),
        cz: col(&[1.0, 0.0]),
        duz: col(&[0.0, 0.0]),
        dpiz: col(&[0.0, 1.0]),
        region: X_REGION,
        gains: vec![0.0],
        hinf_bound: 0.0,
        h2_bound: 0.0,
    };
    assert!((d.hinf_norm() - 2f64.sqrt()).abs() < 1e-12, "{}", d.hinf_norm());
    assert!((d.h2_norm() - 0.5f64.sqrt()).abs() < 1e-12, "{}", d.h2_norm());
    let _ = (d.name, d.region, d.hinf_bound, d.h2_bound);
}

/// The x and swing loops designed apart (as (51) lists them) act together on the pendulum:
/// (∫e_x, e_x, ė_x, ∫ḋ, ḋ) with ẍ = ρv + κd, d̈ = −ẍ − (g/l)d. At every vertex of the ±30 %
/// polytope (vehicle and load mass: (ρ, κ) of `x_and_pendulum`) the slowest mode, the
/// pendulum's, decays at Re s ≤ −0.141 (measured; −0.31 ± 3.36j nominal, where the
/// pole-placement stand-ins left −0.18 ± 3.39j). A 10 % slower mode fails.
#[test]
fn the_x_and_swing_loops_together_damp_the_pendulum_over_the_polytope() {
    let s = section();
    let k: Vec<f64> = s.xy_gains.iter().chain(&s.swing_gains).copied().collect();
    let load_ratio = 0.05 / (1.402 + 2.0 * 0.1566);
    let (a, b) = x_and_pendulum(G_OVER_L, 1.0, 0.0);
    let nominal = closed_loop_poles(&a, &b, &k).iter().map(|p| p.re).fold(f64::MIN, f64::max);
    assert!(nominal < -0.30, "nominal slowest mode {nominal}");
    for vehicle in [0.7, 1.3] {
        for load in [0.7, 1.3] {
            let kappa = G_OVER_L * load_ratio * (load / vehicle - 1.0);
            let (a, b) = x_and_pendulum(G_OVER_L, 1.0 / vehicle, kappa);
            let poles = closed_loop_poles(&a, &b, &k);
            let slowest = poles.iter().map(|p| p.re).fold(f64::MIN, f64::max);
            assert!(slowest < -0.127, "vertex ({vehicle}, {load}): {poles:?}");
        }
    }
    // Without the swing terms (NLPT-2L) the pendulum pair sits on the imaginary axis.
    let without = closed_loop_poles(&a, &b, &[k[0], k[1], k[2], 0.0, 0.0]);
    let undamped = without.iter().map(|p| p.re).fold(f64::MIN, f64::max);
    assert!(undamped.abs() < 1e-9, "{without:?}");
}
