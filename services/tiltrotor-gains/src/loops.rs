//! The design models (51) of each loop, Table 2's regions and Table 3's weights.
//!
//! After feedback linearisation with the nominal (Table 1) model, a loop whose plant has drawn
//! masses and inertias sees e⁽ⁿ⁾ = ρv + … with ρ = (nominal / true) mass or inertia, in
//! [1/1.3, 1/0.7] for the ±30 % draw: each chain's B_u = ρ eₙ, at the two vertices of ρ.
//! The x, y + swing loop (49)–(50) on the linearised pendulum (rod l, vehicle mass M_v, load
//! m₄; A of (48) inverts the nominal M_q2): ẍ = ρv + κd, d̈ = −ẍ − (g/l)d, with ρ = M_v/M_v′ and
//! κ = (g/l)(m₄′/M_v′ − m₄/M_v) (the load's pull the nominal b leaves over); (M_v′, m₄′) at the
//! four corners of ±30 %.

use nalgebra::{DMatrix, DVector};
use std::ops::Range;

const G: f64 = 9.81;
const ROD: f64 = 0.5;
/// Table 1: the main body and the two thruster groups; the load.
const VEHICLE_MASS: f64 = 1.402 + 2.0 * 0.1566;
const LOAD_MASS: f64 = 0.05;
const UNCERTAINTY: f64 = 0.3;

/// Table 2, read as Re s < α, |s − c| < |r|, |Im s| < tan φ |Re s|.
#[derive(Clone, Copy, Debug)]
pub struct Region {
    pub alpha: f64,
    pub centre: f64,
    pub radius: f64,
    pub cone: f64,
}

pub struct Loop {
    pub name: &'static str,
    pub n: usize,
    /// (A, B_u) at each vertex of the polytope.
    pub vertices: Vec<(DMatrix<f64>, DMatrix<f64>)>,
    pub bpi: DMatrix<f64>,
    pub cz: DMatrix<f64>,
    pub duz: DMatrix<f64>,
    pub dpiz: DMatrix<f64>,
    pub region: Region,
    /// The launch file's keys and the slice of K each takes.
    pub keys: Vec<(&'static str, Range<usize>)>,
    /// ω of the solver's state scaling (a chain's typical speed, rad/s).
    pub scale: f64,
    /// Each state's derivative order k (ẽ = e/ωᵏ); the input's is one above the highest.
    pub orders: Vec<i32>,
}

pub struct Options {
    /// One vertex: the nominal model (ρ = 1, κ = 0); `--polytope` imposes the LMIs at the ±30 %
    /// vertices with one Q, Y (infeasible with Table 2's cones for every loop, φ, θ's only at
    /// Table 2's α = −7).
    pub nominal: bool,
    /// `--combined`: x and the swing as one loop on the pendulum, in `combined_region` (default:
    /// two loops as (51) lists them, the swing on ë = −ũ).
    pub combined: bool,
    /// The combined loop's region: "x", "swing" or "hull" (the smallest of the three LMI
    /// regions holding both Table 2 rows).
    pub combined_region: String,
    /// Only the loop of this name (for debugging).
    pub only: Option<String>,
    /// φ, θ's α: −15 (a choice, see the launch file); Table 2's is −7.
    pub attitude_alpha: f64,
    /// φ, θ's disk radius about −7: 60 (a choice, see the launch file); Table 2's is 110.
    pub attitude_radius: f64,
}

impl Options {
    pub fn parse(args: &[String]) -> Options {
        let mut o = Options {
            nominal: true,
            combined: false,
            combined_region: "hull".into(),
            only: None,
            attitude_alpha: -15.0,
            attitude_radius: 60.0,
        };
        let mut it = args.iter();
        while let Some(a) = it.next() {
            match a.as_str() {
                "--polytope" => o.nominal = false,
                "--combined" => o.combined = true,
                "--attitude-alpha" => o.attitude_alpha = it.next().and_then(|a| a.parse().ok()).expect("α, rad/s"),
                "--attitude-radius" => o.attitude_radius = it.next().and_then(|a| a.parse().ok()).expect("r, rad/s"),
                "--only" => o.only = Some(it.next().expect("a loop").clone()),
                "--combined-region" => o.combined_region = it.next().expect("a region").clone(),
                other => panic!(
                    "unknown argument {other} (--polytope, --combined, --combined-region x|swing|hull, --attitude-alpha A, --attitude-radius R, --only LOOP)"
                ),
            }
        }
        o
    }

    /// (ρ, κ) at each vertex.
    fn vertices(&self) -> Vec<(f64, f64)> {
        if self.nominal {
            return vec![(1.0, 0.0)];
        }
        let (lo, hi) = (1.0 - UNCERTAINTY, 1.0 + UNCERTAINTY);
        let mut v = vec![];
        for mv in [lo, hi] {
            for m4 in [lo, hi] {
                let rho = 1.0 / mv;
                let kappa = G / ROD * (LOAD_MASS * m4 / (VEHICLE_MASS * mv) - LOAD_MASS / VEHICLE_MASS);
                v.push((rho, kappa));
            }
        }
        v
    }

    fn gains(&self) -> Vec<f64> {
        if self.nominal { vec![1.0] } else { vec![1.0 / (1.0 + UNCERTAINTY), 1.0 / (1.0 - UNCERTAINTY)] }
    }
}

fn col(v: &[f64]) -> DMatrix<f64> {
    DMatrix::from_column_slice(v.len(), 1, v)
}

fn diag(v: &[f64]) -> DMatrix<f64> {
    DMatrix::from_diagonal(&DVector::from_column_slice(v))
}

/// ė = shift·e + B_u ũ: e = (∫e, e, ė, …).
fn chain(n: usize, rhos: &[f64]) -> Vec<(DMatrix<f64>, DMatrix<f64>)> {
    let mut a = DMatrix::zeros(n, n);
    for i in 0..n - 1 {
        a[(i, i + 1)] = 1.0;
    }
    rhos.iter()
        .map(|rho| {
            let mut b = DMatrix::zeros(n, 1);
            b[(n - 1, 0)] = *rho;
            (a.clone(), b)
        })
        .collect()
}

fn unit(n: usize) -> DMatrix<f64> {
    let mut b = DMatrix::zeros(n, 1);
    b[(n - 1, 0)] = 1.0;
    b
}

const X_REGION: Region = Region { alpha: -1.0, centre: 0.0, radius: 3.0, cone: std::f64::consts::PI / 36.0 };
const SWING_REGION: Region = Region { alpha: -1.5, centre: 0.0, radius: 2.0, cone: std::f64::consts::PI / 20.0 };

/// The combined loop (∫e_x, e_x, ė_x, ∫ḋ, ḋ) at each vertex; ∫ḋ stands for d (a hanging start).
pub fn x_and_pendulum(o: &Options) -> Vec<(DMatrix<f64>, DMatrix<f64>)> {
    let w2 = G / ROD;
    o.vertices()
        .into_iter()
        .map(|(rho, kappa)| {
            let mut a = DMatrix::zeros(5, 5);
            a[(0, 1)] = 1.0;
            a[(1, 2)] = 1.0;
            a[(2, 3)] = kappa;
            a[(3, 4)] = 1.0;
            a[(4, 3)] = -(w2 + kappa);
            (a, col(&[0.0, 0.0, rho, 0.0, -rho]))
        })
        .collect()
}

pub fn all(o: &Options) -> Vec<Loop> {
    let rhos = o.gains();
    let x_weights = (diag(&[0.1, 1.0, 0.25]), col(&[0.5, 0.1, 0.1]), col(&[0.1, 0.1, 1.0]));
    let swing_weights = (diag(&[0.1, 1.0]), col(&[0.5, 0.1]), col(&[0.1, 0.1]));
    // z shares ψ's 5-state row (Table 3's merged cells).
    let five = (
        diag(&[0.1, 1.0, 1.0 / 4.0, 1.0 / 0.04, 1.0 / 0.09]),
        col(&[0.5, 0.1, 0.1, 0.1, 0.1]),
        col(&[0.1, 0.1, 0.1, 0.1, 1.0]),
    );
    let attitude = (
        diag(&[1500.0, 1000.0, 1.0 / 0.25, 1.0 / 0.49, 1.0 / 0.09]),
        col(&[0.05, 0.001, 0.1, 0.1, 1.3]),
        col(&[0.3, 0.01, 0.01, 1.0, 1.0]),
    );
    let mut loops = vec![];
    if o.combined {
        let region = match o.combined_region.as_str() {
            "x" => X_REGION,
            "swing" => SWING_REGION,
            _ => Region { alpha: -1.0, centre: 0.0, radius: 3.0, cone: std::f64::consts::PI / 20.0 },
        };
        let mut cz = DMatrix::zeros(5, 5);
        cz.view_mut((0, 0), (3, 3)).copy_from(&x_weights.0);
        cz.view_mut((3, 3), (2, 2)).copy_from(&swing_weights.0);
        loops.push(Loop {
            name: "x + swing",
            n: 5,
            vertices: x_and_pendulum(o),
            bpi: col(&[0.0, 0.0, 1.0, 0.0, -1.0]),
            cz,
            duz: col(&[0.5, 0.1, 0.1, 0.5, 0.1]),
            dpiz: col(&[0.1, 0.1, 1.0, 0.1, 0.1]),
            region,
            keys: vec![("xy_gains", 0..3), ("swing_gains", 3..5)],
            scale: (-region.alpha * region.radius).sqrt(),
            orders: vec![0, 1, 2, 1, 2],
        });
    } else {
        loops.push(Loop {
            name: "x, y",
            n: 3,
            vertices: chain(3, &rhos),
            bpi: unit(3),
            cz: x_weights.0,
            duz: x_weights.1,
            dpiz: x_weights.2,
            region: X_REGION,
            keys: vec![("xy_gains", 0..3)],
            scale: 1.0,
            orders: vec![0, 1, 2],
        });
        let swing =
            rhos.iter().map(|rho| (DMatrix::from_row_slice(2, 2, &[0.0, 1.0, 0.0, 0.0]), col(&[0.0, -rho]))).collect();
        loops.push(Loop {
            name: "swing",
            n: 2,
            vertices: swing,
            bpi: col(&[0.0, -1.0]),
            cz: swing_weights.0,
            duz: swing_weights.1,
            dpiz: swing_weights.2,
            region: SWING_REGION,
            keys: vec![("swing_gains", 0..2)],
            scale: 1.0,
            orders: vec![0, 1],
        });
    }
    let pi = std::f64::consts::PI;
    let mut five_loop = |name, weights: &(DMatrix<f64>, DMatrix<f64>, DMatrix<f64>), region: Region, key| {
        loops.push(Loop {
            name,
            n: 5,
            vertices: chain(5, &rhos),
            bpi: unit(5),
            cz: weights.0.clone(),
            duz: weights.1.clone(),
            dpiz: weights.2.clone(),
            region,
            keys: vec![(key, 0..5)],
            // The geometric mean of the region's slowest and fastest real pole.
            scale: (-region.alpha * (region.radius - region.centre)).sqrt(),
            orders: vec![0, 1, 2, 3, 4],
        })
    };
    five_loop("z", &five, Region { alpha: -1.1, centre: 0.0, radius: 80.0, cone: pi / 36.0 }, "z_gains");
    five_loop(
        "φ, θ",
        &attitude,
        Region { alpha: o.attitude_alpha, centre: -7.0, radius: o.attitude_radius, cone: pi / 4.0 },
        "attitude_gains",
    );
    five_loop("ψ", &five, Region { alpha: -3.0, centre: -3.0, radius: 20.0, cone: pi / 10.0 }, "yaw_gains");
    loops
}
