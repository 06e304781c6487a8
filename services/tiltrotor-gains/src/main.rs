//! The gains of paper 004's NLLS-2L by the mixed H₂/H∞ synthesis with pole-placement LMIs of
//! section 3.3, (51)–(57), with Table 2's regions and Table 3's weights; printed as the
//! `[controller]` keys of launch/tiltrotor.toml.
//!
//! For each loop ė = Ae + B_u ũ + B_π π, z = C_z e + D_uz ũ + D_πz π, ũ = Ke:
//! 1. γ* = min γ subject to the H∞ LMI and the region LMIs (55)–(57) at every vertex;
//! 2. with γ̂ = margin·γ*, min tr(N) subject to the H₂ LMIs (53), the H∞ LMI at γ̂ and the regions;
//!
//! K = YQ⁻¹, with one Q, Y for every vertex of the parameter polytope (quadratic D-stability).
//! Where the printed forms are not the standard ones we use the standard ones:
//! - H∞ (bounded real lemma, Chilali & Gahinet 1996): [[AQ+QAᵀ+BY+YᵀBᵀ, B_π, (C_zQ+D_uzY)ᵀ],
//!   [*, −I, D_πzᵀ], [*, *, −γI]] ≺ 0 gives ‖T_πz‖∞ < √γ, the bound the text states; the printed
//!   (54), −γ in both blocks, would bound it by γ.
//! - H₂ (Scherer, Gahinet & Chilali 1997): the H₂ output is z with D_πz = 0 (the text: "with
//!   D_πz = 0"), ‖T‖₂² < tr(N).
//! - Table 2's signs: Re s < α, the disk of centre c and radius |r|, the cone of half-angle φ.
//!
//! The design models (A, B_u over the polytope) are in `loops`. The defaults are the launch
//! file's: each loop on its nominal model, x and the swing apart as (51) lists them, φ, θ's α
//! at −15 rad/s and its disk's radius 60; `--polytope`, `--combined`, `--attitude-alpha -7` and
//! `--attitude-radius 110` give the alternatives
//! the scenario's README measures. The TOML goes to stdout, each loop's poles to stderr; the
//! exit status is 1 if any loop has no solution.

mod lmi;
mod loops;

use lmi::{Aff, Vars, minimise};
use loops::{Loop, Region};
use nalgebra::{DMatrix, DVector};

/// γ̂ = MARGIN·γ* ("γ̂ slightly above γ*"; the paper gives no number: a choice).
const MARGIN: f64 = 1.1;
/// Strict inequalities as ⪯ −εI.
const EPS: f64 = 1e-7;

/// MARGIN, or LMI_MARGIN from the environment (to try others).
fn margin() -> f64 {
    std::env::var("LMI_MARGIN").ok().and_then(|m| m.parse().ok()).unwrap_or(MARGIN)
}

struct Design {
    gains: Vec<f64>,
    gamma_star: f64,
    gamma_hat: f64,
    h2_bound: f64,
}

fn region_lmis(q: &Aff, m: &Aff, r: &Region, vars: usize) -> Vec<Aff> {
    let sym = m.add(&m.t());
    let n = q.shape().0;
    let eps = Aff::constant(DMatrix::identity(n, n) * EPS, vars);
    let eps2 = Aff::constant(DMatrix::identity(2 * n, 2 * n) * EPS, vars);
    // (55): AQ + QAᵀ + BY + YᵀBᵀ − 2αQ ≺ 0 (Re s < α).
    let r1 = q.scale(2.0 * r.alpha).sub(&sym).sub(&eps);
    // (56): [[−rQ, M − cQ], [*, −rQ]] ≺ 0.
    let off = m.sub(&q.scale(r.centre));
    let r2 =
        Aff::block(&[vec![q.scale(-r.radius), off.clone()], vec![off.t(), q.scale(-r.radius)]]).scale(-1.0).sub(&eps2);
    // (57): [[sφ(M + Mᵀ), cφ(M − Mᵀ)], [cφ(Mᵀ − M), sφ(M + Mᵀ)]] ≺ 0.
    let (s, c) = r.cone.sin_cos();
    let skew = m.sub(&m.t());
    let r3 =
        Aff::block(&[vec![sym.scale(s), skew.scale(c)], vec![skew.scale(-c), sym.scale(s)]]).scale(-1.0).sub(&eps2);
    vec![r1, r2, r3]
}

fn hinf_lmi(l: &Loop, q: &Aff, y: &Aff, a: &DMatrix<f64>, bu: &DMatrix<f64>, gamma: &Aff) -> Aff {
    let vars = q.coef.len();
    let m = q.left(a).add(&y.left(bu));
    let sym = m.add(&m.t());
    let z = q.left(&l.cz).add(&y.left(&l.duz));
    let nz = l.cz.nrows();
    let c = |x: &DMatrix<f64>| Aff::constant(x.clone(), vars);
    let eye_z = DMatrix::identity(nz, nz);
    let gamma_block = {
        // γI as an expression: γ · I.
        let mut g = Aff::zeros(nz, nz, vars);
        for (k, coef) in gamma.coef.iter().enumerate() {
            g.coef[k] = &eye_z * coef[(0, 0)];
        }
        g.constant = &eye_z * gamma.constant[(0, 0)];
        g
    };
    let lmi = Aff::block(&[
        vec![sym, c(&l.bpi), z.t()],
        vec![c(&l.bpi.transpose()), c(&-DMatrix::identity(1, 1)), c(&l.dpiz.transpose())],
        vec![z, c(&l.dpiz), gamma_block.scale(-1.0)],
    ]);
    let n = lmi.shape().0;
    lmi.scale(-1.0).sub(&c(&(DMatrix::identity(n, n) * EPS)))
}

/// The same loop in ẽ = T⁻¹e, T = diag(1, ω, ω², …), û = u/ωⁿ, π̂ = π/σ and ẑ = z/σ
/// (σ = ωⁿ⁻¹): a chain's states, gains and Q then have like magnitudes (the solver's
/// conditioning); the regions and both norms are unchanged.
fn scaled(l: &Loop, omega: f64) -> (Loop, DMatrix<f64>, f64) {
    let n = l.n;
    let t = DMatrix::from_diagonal(&DVector::from_iterator(n, l.orders.iter().map(|&i| omega.powi(i))));
    let t_inv = t.clone().try_inverse().expect("diagonal");
    let input_order = l.orders.iter().max().expect("states") + 1;
    let un = omega.powi(input_order);
    let sigma = omega.powi(input_order - 1);
    let s = Loop {
        name: l.name,
        n,
        vertices: l.vertices.iter().map(|(a, b)| (&t_inv * a * &t, &t_inv * b * un)).collect(),
        bpi: &t_inv * &l.bpi * sigma,
        cz: &l.cz * &t / sigma,
        duz: &l.duz * (un / sigma),
        dpiz: l.dpiz.clone(),
        region: l.region,
        keys: l.keys.clone(),
        scale: 1.0,
        orders: l.orders.clone(),
    };
    (s, t_inv, un)
}

fn design(l: &Loop) -> Result<Design, String> {
    let (scaled_loop, t_inv, un) = scaled(l, l.scale);
    let mut d = design_unscaled(&scaled_loop)?;
    let k = DMatrix::from_row_slice(1, l.n, &d.gains) * &t_inv * un;
    d.gains = k.iter().copied().collect();
    Ok(d)
}

fn design_unscaled(l: &Loop) -> Result<Design, String> {
    let n = l.n;
    // Stage 1: min γ.
    let mut v = Vars::default();
    let (qv, yv) = (v.sym(n), v.full(1, n));
    let gv = v.full(1, 1);
    let vars = v.count;
    let (q, y, g) = (qv.expr(vars), yv.expr(vars), gv.expr(vars));
    let eye = Aff::constant(DMatrix::identity(n, n) * EPS, vars);
    let mut psd = vec![q.sub(&eye)];
    for (a, bu) in &l.vertices {
        psd.extend(region_lmis(&q, &q.left(a).add(&y.left(bu)), &l.region, vars));
        psd.push(hinf_lmi(l, &q, &y, a, bu, &g));
    }
    let mut c = vec![0.0; vars];
    let gamma_at = match gv {
        lmi::VarMatrix::Full { at, .. } => at,
        lmi::VarMatrix::Sym { at, .. } => at,
    };
    c[gamma_at] = 1.0;
    let x = minimise(&c, &psd).map_err(|e| format!("{}: H∞ stage: {e}", l.name))?;
    let gamma_star = x[gamma_at];
    let gamma_hat = margin() * gamma_star;

    // Stage 2: min tr(N) at γ̂.
    let mut v = Vars::default();
    let (qv, yv) = (v.sym(n), v.full(1, n));
    let nz = l.cz.nrows();
    let nv = v.sym(nz);
    let vars = v.count;
    let (q, y, nn) = (qv.expr(vars), yv.expr(vars), nv.expr(vars));
    let g = Aff::constant(DMatrix::from_element(1, 1, gamma_hat), vars);
    let eye = Aff::constant(DMatrix::identity(n, n) * EPS, vars);
    let mut psd = vec![q.sub(&eye)];
    let z = q.left(&l.cz).add(&y.left(&l.duz));
    let h2 = Aff::block(&[vec![nn.clone(), z.clone()], vec![z.t(), q.clone()]]);
    let k = h2.shape().0;
    psd.push(h2.sub(&Aff::constant(DMatrix::identity(k, k) * EPS, vars)));
    for (a, bu) in &l.vertices {
        let m = q.left(a).add(&y.left(bu));
        psd.extend(region_lmis(&q, &m, &l.region, vars));
        psd.push(hinf_lmi(l, &q, &y, a, bu, &g));
        let lyap = m.add(&m.t()).add(&Aff::constant(&l.bpi * l.bpi.transpose(), vars));
        psd.push(lyap.scale(-1.0).sub(&eye));
    }
    let mut c = vec![0.0; vars];
    if let lmi::VarMatrix::Sym { n, at } = nv {
        let mut k = at;
        for j in 0..n {
            for i in 0..=j {
                if i == j {
                    c[k] = 1.0;
                }
                k += 1;
            }
        }
    }
    let x = minimise(&c, &psd).map_err(|e| format!("{}: H₂ stage: {e}", l.name))?;
    let qm = qv.value(&x);
    let ym = yv.value(&x);
    let kk = ym * qm.try_inverse().ok_or("Q singular")?;
    Ok(Design { gains: kk.iter().copied().collect(), gamma_star, gamma_hat, h2_bound: nv.value(&x).trace().sqrt() })
}

fn poles(a: &DMatrix<f64>, bu: &DMatrix<f64>, k: &[f64]) -> Vec<nalgebra::Complex<f64>> {
    let kk = DMatrix::from_row_slice(1, k.len(), k);
    (a + bu * kk).complex_eigenvalues().iter().copied().collect()
}

fn fmt_poles(p: &[nalgebra::Complex<f64>]) -> String {
    let mut p = p.to_vec();
    p.sort_by(|a, b| b.re.partial_cmp(&a.re).unwrap().then(b.im.partial_cmp(&a.im).unwrap()));
    p.iter()
        .map(|c| if c.im.abs() < 1e-9 { format!("{:.3}", c.re) } else { format!("{:.3}{:+.3}j", c.re, c.im) })
        .collect::<Vec<_>>()
        .join(", ")
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let opts = loops::Options::parse(&args);
    let mut out = format!(
        "# By `cargo run --release --manifest-path services/tiltrotor-gains/Cargo.toml{}`\n",
        if args.is_empty() { String::new() } else { format!(" -- {}", args.join(" ")) }
    );
    let margin = margin();
    let mut xy_and_swing: (Vec<f64>, Vec<f64>) = (vec![], vec![]);
    let mut failed = false;
    for l in loops::all(&opts) {
        if opts.only.as_ref().is_some_and(|o| o != l.name) {
            continue;
        }
        match design(&l) {
            Ok(d) => {
                eprintln!(
                    "{:>9}: γ* {:.6}, γ̂ {:.6}, ‖T‖∞ < √γ̂ = {:.6}, ‖T‖₂ < {:.6}; K = {:?}",
                    l.name,
                    d.gamma_star,
                    d.gamma_hat,
                    d.gamma_hat.sqrt(),
                    d.h2_bound,
                    d.gains
                );
                for (i, (a, bu)) in l.vertices.iter().enumerate() {
                    eprintln!("           vertex {i}: poles {}", fmt_poles(&poles(a, bu, &d.gains)));
                }
                let shown: Vec<String> = d.gains.iter().map(|g| format!("{g:.6e}")).collect();
                out += &format!(
                    "# {}: ‖T_πz‖∞ < √γ̂ = {:.6} (γ* = {:.6}, γ̂ = {margin}·γ*), ‖T_πz₂‖₂ < {:.6}\n",
                    l.name,
                    d.gamma_hat.sqrt(),
                    d.gamma_star,
                    d.h2_bound,
                );
                for (key, range) in &l.keys {
                    let part: Vec<String> = shown[range.clone()].to_vec();
                    out += &format!("{key} = [{}]\n", part.join(", "));
                    if *key == "xy_gains" {
                        xy_and_swing.0 = d.gains[range.clone()].to_vec();
                    }
                    if *key == "swing_gains" {
                        xy_and_swing.1 = d.gains[range.clone()].to_vec();
                    }
                }
            }
            Err(e) => {
                eprintln!("{e}");
                failed = true;
            }
        }
    }
    // The combined x + pendulum loop the separate designs leave out, at each polytope vertex.
    if xy_and_swing.0.len() == 3 && xy_and_swing.1.len() == 2 {
        let k: Vec<f64> = xy_and_swing.0.iter().chain(&xy_and_swing.1).copied().collect();
        let polytope = loops::Options { nominal: false, ..opts };
        for (i, (a, bu)) in loops::x_and_pendulum(&polytope).iter().enumerate() {
            eprintln!("x + pendulum, vertex {i}: {}", fmt_poles(&poles(a, bu, &k)));
        }
    }
    print!("{out}");
    if failed {
        std::process::exit(1);
    }
}
